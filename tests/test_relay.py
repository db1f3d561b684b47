"""The relay (issue 30, ROS 2 across carrier NAT): every component's router config under
[relay], the relay's own router config, the fleet CA signing the relay, and `rosnet-tui relay
serve` running the real Zenoh router (eclipse-zenoh) on loopback: routers that only dial it carry
data between them; no session without a fleet certificate, with a foreign one, or in plain TCP."""

from __future__ import annotations

import queue
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
import zenoh  # noqa: F401  a hard dependency: a broken install fails here, never skips

from rosnet_tui.core.config.settings_model import RelaySettings, Settings
from rosnet_tui.core.ros import fleet_tls, pairing, relay, ros2
from rosnet_tui.core.ros.fleet_tls import TlsError
from tests.builders import ros2_master, ros2_member

REPO = Path(__file__).resolve().parents[1]
ZROUTER = REPO / "tests" / "lab" / "ros2_scripts" / "zrouter.py"


def relayed(s: Settings, host: str = "relay", port: int = 7447) -> Settings:
    s.relay = RelaySettings(host=host, ssh_user="root", zenoh_port=port)
    return s


# --------------------------------------------------------------------------- configs
def test_every_router_dials_the_relay_and_listens_on_loopback_only(tmp_path):
    p = fleet_tls.tls_paths(tmp_path)
    for s in (relayed(ros2_master()), relayed(ros2_member())):
        cfg = ros2.router_config(s, p)
        assert cfg["connect"]["endpoints"] == ["tls/relay:7447"]
        assert cfg["listen"]["endpoints"] == ["tcp/127.0.0.1:7447"]
        tls = cfg["transport"]["link"]["tls"]
        assert tls["connect_certificate"] == str(p.node_crt) and tls["enable_mtls"]
        assert tls["verify_name_on_connect"] and "listen_certificate" not in tls
        assert ros2.router_config_problems(s, cfg["listen"]["endpoints"],
                                           cfg["connect"]["endpoints"], False) == []
        assert "relay" in ros2.render_router_config(s, p).split("\n{")[0]
    m = relayed(ros2_master())
    assert ros2.router_config_problems(m, ["tls/0.0.0.0:7447"], [], False)   # the old master's
    lone = ros2.client_override(relayed(ros2_member(), port=7448), p)
    assert 'connect/endpoints=["tls/relay:7448"]' in lone
    assert ros2.session_config(relayed(ros2_member()), p)["connect"]["endpoints"] == \
        ["tls/relay:7447"]


def test_under_a_relay_no_modem_forwards_anything():
    from rosnet_tui.core.exposure.forwarding import required_ports

    assert [p.ports for p in required_ports(ros2_master())] == ["7447"]
    assert required_ports(relayed(ros2_master())) == []
    assert required_ports(relayed(ros2_member())) == []


def test_the_relays_router_config_takes_fleet_certificates_only(tmp_path):
    p = fleet_tls.tls_paths(tmp_path)
    cfg = relay.relay_router_config("relay", 7448, p)
    assert cfg["mode"] == "router" and cfg["connect"]["endpoints"] == []
    assert cfg["listen"]["endpoints"] == ["tls/0.0.0.0:7448"]
    link = cfg["transport"]["link"]
    assert link["protocols"] == ["tls"]
    assert link["tls"] == {"root_ca_certificate": str(p.ca_crt),
                           "listen_private_key": str(p.node_key),
                           "listen_certificate": str(p.node_crt), "enable_mtls": True,
                           "verify_name_on_connect": True}
    text = relay.render_relay_config("relay", 7448, p)
    assert ros2.loads_json5(text) == cfg and ros2.is_managed(text)


def test_the_fleet_ca_signs_the_relay_named_in_the_settings(tmp_path):
    mp = fleet_tls.tls_paths(tmp_path / "m")
    pairing.prepare_master(ros2_master(), mp)
    csr = fleet_tls.make_request(fleet_tls.tls_paths(tmp_path / "r"), "Relay")
    with pytest.raises(TlsError, match="not a member"):
        fleet_tls.read_request(csr, master="turtlebot", members=["sami"])
    req = fleet_tls.read_request(csr, master="turtlebot", members=["sami"], relay="relay")
    assert (req.name, req.role) == ("relay", "relay")
    _ca, cert = fleet_tls.sign_request(mp, csr, master="turtlebot", members=["sami"],
                                       relay="relay")
    assert fleet_tls.cert_summary(cert.encode())["sans"] == ["relay"]
    member = fleet_tls.make_request(fleet_tls.tls_paths(tmp_path / "s"), "sami")
    assert fleet_tls.read_request(member, master="turtlebot", members=["sami"],
                                  relay="relay").role == "member"
    # the master's own `ros pair --serve relay` signs it with the master's settings
    s = relayed(ros2_master())
    rep = pairing.serve(s, mp, "relay", csr)
    assert "cert" in rep, rep
    assert "error" in pairing.serve(ros2_master(), mp, "relay", csr)   # no [relay]: refused


# --------------------------------------------------------------------------- relay serve
def serve(path: Path, *extra: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "rosnet_tui", "relay", "serve",
                             "--router-config", str(path), *extra], cwd=REPO,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            stdin=subprocess.DEVNULL)


def test_serve_refuses_a_missing_config_or_certificate_with_exit_2(tmp_path):
    out = serve(tmp_path / "none.json5").communicate(timeout=60)
    assert "no relay router config" in out[1] and "Traceback" not in out[1]
    p = fleet_tls.tls_paths(tmp_path)
    path = tmp_path / "relay.json5"
    path.write_text(relay.render_relay_config("relay", 7448, p))
    proc = serve(path)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 2 and "missing" in err and "fleet CA" in err, err
    path.write_text("{mode: 'router', listen: {endpoints: [")
    proc = serve(path)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 2 and "not valid JSON5" in err, err
    proc = serve(tmp_path / "none.json5")
    proc.communicate(timeout=60)
    assert proc.returncode == 2


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait_line(proc: subprocess.Popen, word: str, timeout: float = 20.0) -> str:
    """The first line of *proc*'s stdout holding *word* (bounded: the reader thread ends with it)."""
    import threading

    got: queue.Queue[str] = queue.Queue()
    reader = threading.Thread(target=lambda: [got.put(ln) for ln in proc.stdout], daemon=True)
    reader.start()
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        ended = not reader.is_alive()           # before the look: its last line is in the queue
        try:
            line = got.get(timeout=0.2)
        except queue.Empty:
            if ended:
                break
            continue
        if word in line:
            return line
    raise AssertionError(f"no '{word}' from the process: {proc.stderr.read() if proc.poll() is not None else ''}")


def test_relay_serve_joins_two_dialling_routers_and_admits_only_the_fleet(tmp_path):
    from rosnet_tui.core.peer import zenohproto

    port = _free_port()
    # the master: its CA, its certificate; the relay named "localhost" here (loopback only)
    master = relayed(ros2_master(), "localhost", port)
    mp = fleet_tls.tls_paths(tmp_path / "m")
    pairing.prepare_master(master, mp)
    rp = fleet_tls.tls_paths(tmp_path / "relay")
    ca, cert = fleet_tls.sign_request(mp, fleet_tls.make_request(rp, "localhost"),
                                      master="turtlebot", members=["sami"], relay="localhost")
    fleet_tls.install(rp, ca, cert)
    member = relayed(ros2_member(), "localhost", port)
    sp = fleet_tls.tls_paths(tmp_path / "s")
    ca, cert = fleet_tls.sign_request(mp, fleet_tls.make_request(sp, "sami"),
                                      master="turtlebot", members=["sami"], relay="localhost")
    fleet_tls.install(sp, ca, cert)

    cfg = relay.relay_router_config("localhost", port, rp)
    cfg["listen"]["endpoints"] = [f"tls/127.0.0.1:{port}"]          # loopback only in tests
    rpath = tmp_path / "relay.json5"
    rpath.write_text(ros2.render_json5(cfg, []))
    procs = [serve(rpath)]
    try:
        assert "mutual TLS" in _wait_line(procs[0], "Relay router")
        local = {}
        for who, s, p in (("master", master, mp), ("member", member, sp)):
            c = ros2.router_config(s, p)
            assert c["connect"]["endpoints"] == [f"tls/localhost:{port}"]
            local[who] = _free_port()
            c["listen"]["endpoints"] = [f"tcp/127.0.0.1:{local[who]}"]
            path = tmp_path / f"{who}.json5"
            path.write_text(ros2.render_json5(c, []))
            procs.append(subprocess.Popen([sys.executable, str(ZROUTER), str(path), "60"],
                                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                          text=True))
            _wait_line(procs[-1], "ZROUTER")
        # a node on the master's router publishes; one on the member's router receives
        sub = zenohproto.open_client(f"tcp/127.0.0.1:{local['member']}", 5.0)
        pub = zenohproto.open_client(f"tcp/127.0.0.1:{local['master']}", 5.0)
        got: queue.Queue[str] = queue.Queue()
        sub.declare_subscriber("0/relay_test", lambda smp: got.put(smp.payload.to_string()))
        publisher = pub.declare_publisher("0/relay_test")
        seen, end = None, time.monotonic() + 15
        while seen is None and time.monotonic() < end:
            publisher.put("across the relay")
            try:
                seen = got.get(timeout=0.3)
            except queue.Empty:
                pass
        pub.close()
        sub.close()
        assert seen == "across the relay"

        # outsiders at the relay: no certificate, a foreign CA's, plain TCP: no session
        foreign = fleet_tls.make_test_ca(tmp_path / "f", "someone else")
        fp = fleet_tls.tls_paths(tmp_path / "fm")
        fleet_tls.issue_test_cert(foreign, fp, "sami")
        fp.ca_crt.write_bytes(sp.ca_crt.read_bytes())
        ep = f"tls/localhost:{port}"
        for tls in ({"root_ca_certificate": str(sp.ca_crt), "connect_private_key": str(fp.node_key),
                     "connect_certificate": str(fp.node_crt), "enable_mtls": True},
                    {"root_ca_certificate": str(sp.ca_crt)}, None):
            with pytest.raises(zenohproto.OpenFailed):
                zenohproto.open_client(ep if tls else f"tcp/127.0.0.1:{port}", 1.0, "client",
                                       tls).close()
        own = {"root_ca_certificate": str(sp.ca_crt), "connect_private_key": str(sp.node_key),
               "connect_certificate": str(sp.node_crt), "enable_mtls": True,
               "verify_name_on_connect": True}
        zenohproto.open_client(ep, 3.0, "client", own).close()

        # SIGTERM: the relay stops at once and says so
        procs[0].send_signal(signal.SIGTERM)
        procs[0].wait(10)
        assert procs[0].returncode == 0
    finally:
        for proc in procs:
            if proc.poll() is None:
                proc.kill()
            proc.wait(5)


def test_the_steps_say_what_the_relay_needs():
    from rosnet_tui.core.wizard import steps

    for s in (relayed(ros2_master()), relayed(ros2_member())):
        text = steps.configure_router_ros2(s)
        assert "Nothing to forward" in text and "TCP 7447 open" in text, text
        assert "tls/relay:7447" in steps.configure_ros2(s)
        assert "relay" in steps.step_for("router", s).expected
