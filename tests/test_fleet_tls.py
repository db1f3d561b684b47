"""ROS 2 mutual TLS: the [ros] security setting, the fleet CA and certificates, the text pairing
path (the real CLI), the router and session configs, and a real Zenoh router with mTLS on
loopback refusing a session without a certificate and one from a foreign CA."""

from __future__ import annotations

import datetime as dt
import os
import socket
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest
import zenoh  # noqa: F401  a hard dependency: a broken install fails here, never skips

from rosnet_tui.core.config.settings_model import RosSettings, Settings
from rosnet_tui.core.ros import fleet_tls, ros2
from rosnet_tui.core.ros.fleet_tls import TlsError
from rosnet_tui.core.saved.settings import parse_settings, render_settings
from tests.builders import ros2_master
from tests.builders import ros2_member as member

REPO = Path(__file__).resolve().parents[1]


def master(**ros) -> Settings:
    return ros2_master(public_ip="203.0.113.2", **ros)


# --------------------------------------------------------------------------- the setting
def test_security_defaults_follow_the_ros_version_and_files_that_do_not_say():
    assert RosSettings(version=2).security == "mtls"
    assert RosSettings(version=1).security == "firewall"
    ros1 = "[this]\nname='a'\nrole='master'\n[ros]\nversion=1\n"
    ros2_old = "[this]\nname='a'\nrole='master'\n[ros]\nversion=2\n"
    assert parse_settings(ros1).ros.security == "firewall"
    assert parse_settings(ros2_old).ros.security == "mtls"
    assert parse_settings(ros2_old + "security='none'\n").ros.security == "none"
    # a version changed later (the set-up screen) changes a default, never an explicit choice
    from dataclasses import replace
    assert replace(RosSettings(version=1), version=2).security == "mtls"
    assert replace(RosSettings(version=1, security="none"), version=2).security == "none"
    # saved: ROS 2 files say it; a ROS 1 file only when chosen
    assert 'security = "mtls"' in render_settings(master())
    assert "security" not in render_settings(replace(master(), ros=RosSettings(master="turtlebot")))
    back = parse_settings(render_settings(master(security="none")))
    assert back.ros.security == "none"


def test_security_refusals():
    probs = dict(master(security="bogus").problems())
    assert "ros.security" in probs
    s = master()
    s.ros.version = 1
    s.ros.security = "mtls"
    assert "ROS 1" in dict(s.problems())["ros.security"]


# --------------------------------------------------------------------------- material
def test_master_ca_and_certificate(tmp_path):
    p = fleet_tls.tls_paths(tmp_path)
    from rosnet_tui.core.ros import pairing

    made = pairing.prepare_master(master(), p)
    assert len(made) == 2 and pairing.prepare_master(master(), p) == []
    assert stat.S_IMODE(p.ca_key.stat().st_mode) == 0o600
    assert stat.S_IMODE(p.node_key.stat().st_mode) == 0o600
    s = fleet_tls.cert_summary(p.node_crt)
    assert s["cn"] == "turtlebot" and s["sans"] == ["turtlebot", "203.0.113.2"]
    assert s["issuer_key_id"] == fleet_tls.ca_key_id(p.ca_crt) and s["days_left"] > 300
    from cryptography import x509
    from cryptography.x509.oid import ExtendedKeyUsageOID as Eku
    cert = fleet_tls.load_cert(p.node_crt)
    eku = cert.extensions.get_extension_for_class(x509.ExtendedKeyUsage).value
    assert Eku.SERVER_AUTH in eku and Eku.CLIENT_AUTH in eku


def test_sign_and_install_and_their_refusals(tmp_path):
    from rosnet_tui.core.ros import pairing

    mp, sp = fleet_tls.tls_paths(tmp_path / "m"), fleet_tls.tls_paths(tmp_path / "s")
    pairing.prepare_master(master(), mp)
    csr = fleet_tls.make_request(sp, "sami")
    assert stat.S_IMODE(sp.node_key.stat().st_mode) == 0o600
    ca, cert = fleet_tls.sign_request(mp, csr, master="turtlebot", members=["sami"])
    with pytest.raises(TlsError, match="names the master"):
        fleet_tls.sign_request(mp, fleet_tls.make_request(fleet_tls.tls_paths(tmp_path / "x"),
                                                          "turtlebot"), master="turtlebot",
                               members=["sami", "turtlebot"])
    with pytest.raises(TlsError, match="not a certificate request"):
        fleet_tls.sign_request(mp, "hello", master="turtlebot", members=["sami"])
    foreign = fleet_tls.make_test_ca(tmp_path / "f", "someone else")
    with pytest.raises(TlsError, match="not signed by"):
        fleet_tls.install(sp, foreign.ca_crt.read_text(), cert)
    other = fleet_tls.tls_paths(tmp_path / "o")
    with pytest.raises(TlsError, match="not for this component's key"):
        fleet_tls.install(other if fleet_tls.ensure_node_key(other) else other, ca, cert)
    summ = fleet_tls.install(sp, ca, cert)
    assert summ["cn"] == "sami" and pairing.needs_pairing(member(), sp) is None
    # an expired or soon-expiring certificate, and one from another CA, need pairing again
    old = dt.datetime.now(dt.timezone.utc) - dt.timedelta(days=400)
    fleet_tls.issue_test_cert(mp, sp, "sami", days=380, not_before=old)
    assert "expires" in pairing.needs_pairing(member(), sp)
    fleet_tls.issue_test_cert(foreign, fleet_tls.tls_paths(tmp_path / "s2"), "sami")
    sp.node_crt.write_bytes((tmp_path / "s2" / "tls" / "node.crt").read_bytes())
    assert "not from the fleet CA" in pairing.needs_pairing(member(), sp)


def _cli(home: Path, *args: str, stdin: str = "") -> subprocess.CompletedProcess:
    env = {**os.environ, "XDG_CONFIG_HOME": str(home), "PYTHONPATH": str(REPO)}
    return subprocess.run([sys.executable, "-m", "rosnet_tui", *args], input=stdin, env=env,
                          capture_output=True, text=True, timeout=60, cwd=REPO)


def test_text_pairing_path_through_the_cli(tmp_path):
    mh, sh = tmp_path / "m", tmp_path / "s"
    for home, s in ((mh, master()), (sh, member())):
        (home / "rosnet-tui").mkdir(parents=True)
        (home / "rosnet-tui" / "config.toml").write_text(render_settings(s))
    req = _cli(sh, "ros", "pair", "--print-request")
    assert req.returncode == 0 and fleet_tls.PEM_CSR in req.stdout, req.stderr
    fp = fleet_tls.key_fingerprint(fleet_tls.load_request_key(req.stdout))
    assert fp in req.stderr
    signed = _cli(mh, "ros", "pair", "--sign", "--yes",
                  stdin="some words around it\n" + req.stdout)
    assert signed.returncode == 0 and signed.stdout.count(fleet_tls.PEM_CERT) == 2, signed.stderr
    assert fp in signed.stderr and "names sami" in signed.stderr
    assert (mh / "rosnet-tui" / "tls" / "ca.key").exists()
    inst = _cli(sh, "ros", "pair", "--install", stdin=signed.stdout)
    assert inst.returncode == 0 and "Installed" in inst.stdout, inst.stderr
    assert not (sh / "rosnet-tui" / "tls" / "ca.key").exists()   # the CA key stays on the master
    assert fleet_tls.cert_summary(sh / "rosnet-tui" / "tls" / "node.crt")["cn"] == "sami"
    bad = _cli(sh, "ros", "pair", "--install", stdin="nothing here")
    assert bad.returncode == 2 and "Traceback" not in bad.stderr
    bad = _cli(mh, "ros", "pair", "--sign", "--yes", stdin="nothing here")
    assert bad.returncode == 2 and "not a certificate request" in bad.stderr


# --------------------------------------------------------------------------- configs
def test_router_and_session_configs_under_mtls(tmp_path):
    p = fleet_tls.tls_paths(tmp_path)
    m, s = ros2.router_config(master(), p), ros2.router_config(member(), p)
    assert m["listen"]["endpoints"] == ["tls/10.10.10.1:7447", "tcp/127.0.0.1:7447"]
    other = ros2.router_config(master(zenoh_port=17447), p)["listen"]["endpoints"]
    assert other == ["tls/0.0.0.0:17447", "tcp/127.0.0.1:7447"]
    mt = m["transport"]["link"]["tls"]
    assert mt == {"root_ca_certificate": str(p.ca_crt), "listen_private_key": str(p.node_key),
                  "listen_certificate": str(p.node_crt), "enable_mtls": True,
                  "verify_name_on_connect": True}
    assert s["connect"]["endpoints"] == ["tls/turtlebot:7447"]
    assert s["listen"]["endpoints"] == ["tcp/0.0.0.0:7447"]
    st = s["transport"]["link"]["tls"]
    assert st["connect_certificate"] == str(p.node_crt) and st["verify_name_on_connect"] is True
    assert ros2.router_config_problems(member(), [], ["tls/turtlebot:7447"], True) == []
    sess = ros2.session_config(member(), p)
    assert sess["connect"]["endpoints"] == ["tls/turtlebot:7447"]
    assert sess["transport"]["link"]["tls"]["connect_private_key"] == str(p.node_key)
    values, bad = ros2.parse_override(ros2.client_override(member(), p))
    assert bad == [] and values["transport/link/tls/connect_certificate"] == str(p.node_crt)
    from rosnet_tui.core.peer import zenohproto  # a peer's lone client node dials with these keys
    env = {"ZENOH_CONFIG_OVERRIDE": ros2.client_override(member(), p)}
    assert zenohproto.peer_endpoint(env, "x") == ("tls/turtlebot:7447", "client")
    assert zenohproto.override_tls(env) == ros2.tls_settings(member(), p, listen=False)
    plain = ros2.router_config(member(security="none"), p)
    assert plain["connect"]["endpoints"] == ["tcp/turtlebot:7447"]
    assert "tls" not in plain["transport"]["link"]


# --------------------------------------------------------------------------- a real router
def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait_port(port: int, proc: subprocess.Popen, timeout: float = 15.0) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end and proc.poll() is None:
        with socket.socket() as s:
            s.settimeout(0.2)
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.05)
    raise AssertionError("router did not start")


def test_a_real_router_with_the_masters_config_admits_only_the_fleet(tmp_path):
    from rosnet_tui.core.peer import zenohproto
    from rosnet_tui.core.ros import pairing

    port = _free_port()
    mp = fleet_tls.tls_paths(tmp_path / "m")
    # the master's name as members dial it here: localhost
    ms = master(zenoh_port=port)
    ms.this.name = ms.ros.master = "localhost"
    ms.peers[0].name = "sami"
    pairing.prepare_master(ms, mp)
    cfg = ros2.router_config(ms, mp)
    assert cfg["listen"]["endpoints"][0] == f"tls/0.0.0.0:{port}"
    cfg["listen"]["endpoints"] = [f"tls/127.0.0.1:{port}"]   # loopback only in tests
    path = tmp_path / "router.json5"
    path.write_text(ros2.render_json5(cfg, []))
    zr = REPO / "tests" / "lab" / "ros2_scripts" / "zrouter.py"
    proc = subprocess.Popen([sys.executable, str(zr), str(path), "60"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    try:
        _wait_port(port, proc)
        sp = fleet_tls.tls_paths(tmp_path / "s")
        ca, cert = fleet_tls.sign_request(mp, fleet_tls.make_request(sp, "sami"),
                                          master="localhost", members=["sami"])
        fleet_tls.install(sp, ca, cert)
        ep = f"tls/localhost:{port}"

        def tls_of(p):
            return {"root_ca_certificate": str(p.ca_crt), "connect_private_key": str(p.node_key),
                    "connect_certificate": str(p.node_crt), "enable_mtls": True,
                    "verify_name_on_connect": True}

        t0 = time.monotonic()
        sess = zenohproto.open_client(ep, 10.0, "client", tls_of(sp))
        took = time.monotonic() - t0
        sess.close()
        assert took < 5.0       # admitted at once, not after the (long) timeout
        foreign = fleet_tls.make_test_ca(tmp_path / "f", "someone else")
        fp = fleet_tls.tls_paths(tmp_path / "fm")
        fleet_tls.issue_test_cert(foreign, fp, "sami")
        fp.ca_crt.write_bytes(sp.ca_crt.read_bytes())   # trusts the fleet, but its cert is foreign
        for tls in (tls_of(fp), {"root_ca_certificate": str(sp.ca_crt)}, None):
            e = ep if tls else f"tcp/127.0.0.1:{port}"
            with pytest.raises(zenohproto.OpenFailed):
                zenohproto.open_client(e, 1.0, "client", tls).close()
    finally:
        proc.kill()
        proc.wait(5)


def test_the_sync_service_renews_the_masters_certificate_before_expiry(tmp_path):
    from rosnet_tui.core.ros import pairing

    p = fleet_tls.tls_paths(tmp_path)
    assert pairing.renew_due(master(), p) == ([], 6 * 3600.0)   # no CA: the service makes none
    assert not p.ca_key.exists()
    pairing.prepare_master(master(), p)
    old = dt.datetime.now(dt.timezone.utc) - dt.timedelta(days=380)
    fleet_tls.issue_test_cert(p, p, "turtlebot", days=400, not_before=old)   # 20 days left
    said, _ = pairing.renew_due(master(), p)
    assert said and fleet_tls.cert_summary(p.node_crt)["days_left"] > 300
    assert pairing.renew_due(master(security="none"), p) == ([], 6 * 3600.0)


def test_the_program_s_own_config_folder_is_the_product_s(tmp_path, monkeypatch):
    """fleet_tls, fed to a peer's interpreter, restates the config folder's rule instead of
    importing it (the installed rosnet-tui there may be of another version): held equal here."""
    from rosnet_tui.core.config.paths import default_config_dir

    for xdg in (str(tmp_path / "xdg"), ""):
        monkeypatch.setenv("HOME", str(tmp_path / "home"))
        monkeypatch.setenv("XDG_CONFIG_HOME", xdg)
        assert fleet_tls.tls_paths().dir == default_config_dir() / "tls"
    monkeypatch.delenv("XDG_CONFIG_HOME")
    assert fleet_tls.tls_paths().dir == tmp_path / "home" / ".config" / "rosnet-tui" / "tls"


def test_ros_apply_on_the_master_makes_the_ca_and_writes_the_tls_config(tmp_path):
    home = tmp_path / "m"
    (home / "rosnet-tui").mkdir(parents=True)
    (home / "rosnet-tui" / "config.toml").write_text(render_settings(master()))
    rc, bashrc = tmp_path / "router.json5", tmp_path / "bashrc"
    r = _cli(home, "ros", "apply", "--yes", "--no-checks", "--file", str(bashrc),
             "--router-config", str(rc), "--state-dir", str(tmp_path / "state"))
    assert r.returncode == 0, r.stdout + r.stderr
    p = fleet_tls.tls_paths(home / "rosnet-tui")
    assert "Made the fleet CA" in r.stdout and stat.S_IMODE(p.ca_key.stat().st_mode) == 0o600
    cfg = ros2.loads_json5(rc.read_text())
    assert cfg["listen"]["endpoints"][0] == "tls/10.10.10.1:7447"
    assert cfg["transport"]["link"]["tls"]["listen_certificate"] == str(p.node_crt)
    again = _cli(home, "ros", "apply", "--yes", "--no-checks", "--file", str(bashrc),
                 "--router-config", str(rc), "--state-dir", str(tmp_path / "state"))
    assert again.returncode == 0 and "Made" not in again.stdout     # made once
    # a member that cannot reach its master over SSH is told the text path, exit 1
    mem = tmp_path / "s"
    (mem / "rosnet-tui").mkdir(parents=True)
    s = member()
    s.peers[0].ssh_user = ""
    (mem / "rosnet-tui" / "config.toml").write_text(render_settings(s))
    r = _cli(mem, "ros", "apply", "--yes", "--no-checks", "--file", str(tmp_path / "b2"),
             "--router-config", str(tmp_path / "r2.json5"), "--state-dir", str(tmp_path / "s2"))
    assert r.returncode == 1 and "--print-request" in r.stderr and "Traceback" not in r.stderr


def test_undo_after_turning_mtls_on_restores_the_plain_configs(tmp_path):
    home = tmp_path / "m"
    (home / "rosnet-tui").mkdir(parents=True)
    cfg = home / "rosnet-tui" / "config.toml"
    rc, bashrc, state = tmp_path / "router.json5", tmp_path / "bashrc", tmp_path / "state"
    args = ("--yes", "--no-checks", "--file", str(bashrc), "--router-config", str(rc),
            "--state-dir", str(state))
    cfg.write_text(render_settings(master(security="none")))
    r = _cli(home, "ros", "apply", *args)
    assert r.returncode == 0 and "Security is off" in r.stdout, r.stderr
    plain = rc.read_text()
    assert '"tcp/0.0.0.0:7447"' in plain and "tls" not in plain
    cfg.write_text(render_settings(master()))
    assert _cli(home, "ros", "apply", *args).returncode == 0
    assert '"enable_mtls": true' in rc.read_text()
    u = _cli(home, "undo", "--yes", "--state-dir", str(state))
    assert u.returncode == 0, u.stderr
    assert rc.read_text() == plain
