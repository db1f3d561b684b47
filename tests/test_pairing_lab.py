"""ROS 2 mutual TLS on the network lab (default settings: [ros] security = "mtls").

- A member without a certificate pairs with `rosnet-tui ros pair` over the SSH the checks use
  (host key verified from its known_hosts; the master's side runs with the rosnet-tui installed
  there, as the README installs it), within 5 s; its router then links and every ros2.* check
  passes from both seats.
- A member certificate from a foreign CA, and an expired one, are named by ros2.router.
- ``security = "none"``: `ros apply` writes plain tcp/ configs and says security is off.
"""

from __future__ import annotations

import datetime as dt
import time

import pytest

from rosnet_tui.core.ros import fleet_tls, pairing
from tests.lab.ros2 import ROS2_IDS
from tests.lab.verdicts import explain

pytestmark = pytest.mark.lab


@pytest.fixture
def ros2(ros2):
    """The lab plugin's healthy ROS 2 world; after the test, the laptop without a certificate
    and the master with its own again (the plugin then makes it healthy)."""
    yield ros2
    ros2.remove_tls("laptop")
    from rosnet_tui.core.ros import pairing  # the master's own certificate back to its name
    pairing.prepare_master(ros2.settings("robot"), ros2.tls_paths("robot"), renew=True)
    for h in ("robot", "laptop"):     # certificates may have changed: routers read them at start
        ros2.stop_router(h)


def test_a_member_pairs_over_ssh_and_then_every_check_passes(ros2):
    lab = ros2.lab
    ros2.stop_router("laptop")
    ros2.remove_tls("laptop")
    cfg = ros2.config_path("laptop")
    t0 = time.monotonic()
    r = lab.rosnet("laptop", "ros", "pair", "--config", str(cfg), env=ros2.env("laptop"))
    took = time.monotonic() - t0
    assert r.returncode == 0, r.stdout + r.stderr
    assert "Paired with turtlebot's fleet CA" in r.stdout, r.stdout
    # a figure, not a verdict: no bound assumes a quiet machine (no goal says how fast)
    print(f"pairing took {took:.2f} s (whole CLI process)")
    paths = ros2.tls_paths("laptop")
    assert not paths.ca_key.exists()     # the CA key stays on the master
    summ = fleet_tls.cert_summary(paths.node_crt)
    assert summ["cn"] == "sami"
    assert summ["issuer_key_id"] == fleet_tls.ca_key_id(ros2.tls_paths("robot").ca_crt)
    again = lab.rosnet("laptop", "ros", "pair", "--config", str(cfg), env=ros2.env("laptop"))
    assert again.returncode == 0 and "Already paired" in again.stdout
    renew = lab.rosnet("laptop", "ros", "pair", "--renew", "--config", str(cfg),
                       env=ros2.env("laptop"))
    assert renew.returncode == 0, renew.stderr
    assert fleet_tls.cert_summary(paths.node_crt)["fingerprint"] != summ["fingerprint"]
    ros2.start_router("laptop")
    talker = ros2.node("robot", "talker")
    listener = ros2.node("laptop", "listener")
    assert lab.wait_output(listener, r"heard: hello from turtlebot \d+", timeout=15), \
        lab.output(listener)
    for host in ("laptop", "robot"):
        results = ros2.check(host)
        assert list(results) == ROS2_IDS, explain(results)
        assert all(c["status"] == "pass" for c in results.values()), explain(results)
        assert results["ros2.router"]["data"]["tls"]["problem"] is None
    lab.kill(talker)


@pytest.mark.parametrize("variant", ["foreign", "expired"])
def test_a_foreign_or_expired_member_certificate_is_named(ros2, tmp_path, variant):
    paths = ros2.tls_paths("laptop")
    if variant == "foreign":
        foreign = fleet_tls.make_test_ca(tmp_path, "another fleet")
        fleet_tls.issue_test_cert(foreign, paths, "sami")
        paths.ca_crt.write_bytes(ros2.tls_paths("robot").ca_crt.read_bytes())
    else:
        old = dt.datetime.now(dt.timezone.utc) - dt.timedelta(days=30)
        fleet_tls.issue_test_cert(ros2.tls_paths("robot"), paths, "sami", days=10, not_before=old)
    t0 = time.monotonic()
    router = ros2.check("laptop")["ros2.router"]
    print(f"{variant}: {router['status']} in {router.get('duration_s', 0):.2f} s "
          f"(whole check run {time.monotonic() - t0:.1f} s): {router['summary']}")
    assert router["status"] == "fail", router
    tls = router["data"]["tls"]
    if variant == "foreign":
        assert tls["problem"] == "foreign_ca" and tls["handshake"] == "rejected_foreign", tls
        assert "another CA" in router["summary"] or "other CA" in router["summary"]
    else:
        assert tls["problem"] == "expired" and tls["handshake"] == "rejected_expired", tls
        assert "expired" in router["summary"]


def test_security_none_writes_plain_tcp(ros2):
    lab = ros2.lab
    rc = ros2.router_config_path("laptop")
    rc.unlink()
    cfg = ros2.config_path("laptop", security="none")
    r = lab.rosnet("laptop", "ros", "apply", "--yes", "--no-checks", "--config", str(cfg),
                   "--router-config", str(rc), env=ros2.env("laptop"))
    assert r.returncode == 0, r.stderr
    assert '"tcp/turtlebot:7447"' in rc.read_text() and "tls" not in rc.read_text()
    assert "Security is off" in r.stdout
    r = lab.rosnet("laptop", "undo", "--yes", env=ros2.env("laptop"))
    assert r.returncode == 0 and not rc.exists(), r.stderr


def _full(ros2, host: str) -> tuple[dict, float]:
    import json

    t0 = time.monotonic()
    r = ros2.lab.rosnet(host, "check", "--json", "--config", str(ros2.config_path(host)),
                        env=ros2.env(host), timeout=90)
    took = time.monotonic() - t0
    assert r.stdout.strip(), r.stderr
    return {c["id"]: c for c in json.loads(r.stdout)["checks"]}, took


def _rules(entry: dict) -> list[str]:
    return [a["rule"] for a in entry.get("advice") or []]


def test_security_none_brings_back_plain_tcp_and_the_exposure_finding(ros2):
    """Full verification on the master: under mTLS the open port is no finding (only the fleet
    gets in); with security "none" the routers run plain tcp/ and security.zenoh_exposed is
    back. Also the cost of TLS to full verification from the member's seat (printed)."""
    times: dict[str, list[float]] = {"mtls": [], "none": []}
    for mode in ("mtls", "none"):
        if mode == "none":
            ros2.set_security("none")
        robot, _ = _full(ros2, "robot")
        exposed = "security.zenoh_exposed" in _rules(robot["router.port_open"])
        assert exposed == (mode == "none"), explain(robot)
        assert robot["ros2.router"]["data"]["endpoint"] == (
            "tls/turtlebot:7447" if mode == "mtls" else "tcp/turtlebot:7447")
        for _ in range(3):
            laptop, took = _full(ros2, "laptop")
            out = laptop.pop("security.outsider")     # the outsider gets in only with "none"
            assert out["status"] == ("fail" if mode == "none" else "pass"), explain(laptop)
            assert mode == "mtls" or out["data"]["cause"] == "security_off", out
            assert all(c["status"] in ("pass", "skip") for c in laptop.values()), explain(laptop)
            times[mode].append(took)
    med = {m: sorted(v)[1] for m, v in times.items()}
    print(f"full verification from the laptop, median of 3: mtls {med['mtls']:.2f} s, none "
          f"{med['none']:.2f} s, TLS adds {med['mtls'] - med['none']:+.2f} s; all {times}")


def test_removing_a_member_shuts_it_out_at_once(ros2):
    """`ros pair --remove sami` on the master: a new CA (the others would be re-paired over SSH;
    here sami is the only member); after the master's router restarts, sami's certificate from
    the old CA is refused and ros2.router names it."""
    lab = ros2.lab
    old_ca = fleet_tls.ca_key_id(ros2.tls_paths("robot").ca_crt)
    r = lab.rosnet("robot", "ros", "pair", "--remove", "sami", "--yes", "--config",
                   str(ros2.config_path("robot")), env=ros2.env("robot"))
    assert r.returncode == 0, r.stdout + r.stderr
    assert "sami is out of the fleet" in r.stdout
    assert fleet_tls.ca_key_id(ros2.tls_paths("robot").ca_crt) != old_ca
    ros2.start_router("robot")
    router = ros2.check("laptop")["ros2.router"]
    assert router["status"] == "fail", router
    assert router["data"]["tls"]["handshake"] in ("master_foreign_ca", "rejected_foreign"), router
    assert "ros2.tls.foreign_ca" in [a["rule"] for a in router.get("advice") or []], router


def test_a_member_pairs_from_the_wizard_in_one_flow(ros2, tmp_path):
    """The wizard on the laptop (Pilot, headless, in the laptop's namespace): ROS step, `w`, `y`:
    the ROS 2 files are written and the master signs the laptop's certificate over SSH, within
    5 s; the router started from the written config then passes every ros2.* check."""
    import json
    import sys

    from tests.lab.lab import REPO

    lab = ros2.lab
    ros2.stop_router("laptop")
    ros2.remove_tls("laptop")
    env = ros2.env("laptop")
    env["PYTHONPATH"] = str(REPO)
    r = lab.run("laptop", [sys.executable, "-m", "tests.ui_support.drive_pair",
                           str(ros2.config_path("laptop")), str(tmp_path / "state"),
                           str(lab.bashrc_path("laptop"))], timeout=120, env=env)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-4000:]
    out = json.loads(r.stdout.strip().splitlines()[-1])
    print(f"wizard: y to certificate installed {out['paired_s']} s")
    assert out["screen"] == "WriteScreen" and out["paired_s"] is not None, out
    assert out["paired_s"] <= 5.0
    assert out["after"]["ros2.env"] == "pass", out   # re-run after the write, as in the wizard
    assert '"tls/turtlebot:7447"' in ros2.router_config_path("laptop").read_text()
    ros2.start_router("laptop")
    results = ros2.check("laptop")
    assert all(c["status"] == "pass" for c in results.values()), explain(results)


def test_a_master_certificate_with_the_wrong_name_is_named(ros2):
    """The master's router certificate names another host than the one members dial: the
    member's TLS handshake says so, and the advisor's rule points at the master."""
    robot = ros2.tls_paths("robot")
    fleet_tls.issue_test_cert(robot, robot, "robot-old-name")
    ros2.start_router("robot")
    router = ros2.check("laptop")["ros2.router"]
    assert router["status"] == "fail", router
    assert router["data"]["tls"]["handshake"] == "wrong_name", router
    assert "ros2.tls.wrong_name" in [a["rule"] for a in router.get("advice") or []], router
    robot_view = ros2.check("robot")["ros2.router"]
    assert robot_view["data"]["tls"]["problem"] == "wrong_name", robot_view


def test_a_pairing_key_can_only_sign_its_member_and_remove_ends_it(ros2):
    """Issue 35: a member's pairing key in the master's authorized_keys runs only the forced
    `ros pair --serve NAME` (no shell: ca.key is not readable through it), signs only NAME, and
    `ros pair --remove NAME` deletes it (the next login with it is refused)."""
    from rosnet_tui.core.ros import pair_access
    from tests.lab.lab import keypair
    from tests.lab.readme_install import VENV
    from tests.test_fleet_ca import csr

    lab = ros2.lab
    robot_home, laptop_home = lab.home("robot"), lab.home("laptop")
    private, public = keypair("sami pairing key")
    key = laptop_home / ".ssh" / "pair_key"
    key.write_bytes(private)
    key.chmod(0o600)
    keys = robot_home / ".ssh" / "authorized_keys"
    before = keys.read_text()
    pair_access.admit("sami", public.decode(), path=keys,
                      python=str(robot_home / VENV / "bin" / "python"))
    ssh = ["ssh", "-F", "/dev/null", "-i", str(key), "-o", "IdentitiesOnly=yes",
           "-o", "BatchMode=yes", "-o", "ConnectTimeout=5",
           "-o", f"UserKnownHostsFile={laptop_home / '.ssh' / 'known_hosts'}",
           f"root@{lab.hostname('robot')}"]
    try:
        r = lab.run("laptop", [*ssh, "cat ~/.config/rosnet-tui/tls/ca.key"],
                    input=csr("sami"), timeout=30)
        rep = pairing.report_of(r.stdout)
        assert rep and "cert" in rep, r.stdout + r.stderr
        assert "PRIVATE KEY" not in r.stdout                      # the shell never ran
        assert fleet_tls.cert_summary(rep["cert"].encode())["cn"] == "sami"
        for name, why in (("Turtlebot", "names the master"), ("SAMI", None)):
            r = lab.run("laptop", [*ssh, "anything"], input=csr(name), timeout=30)
            rep = pairing.report_of(r.stdout)
            assert rep is not None, r.stdout + r.stderr
            assert (why in rep.get("error", "")) if why else "cert" in rep, rep
        r = lab.rosnet("robot", "ros", "pair", "--remove", "sami", "--yes", "--config",
                       str(ros2.config_path("robot")), env=ros2.env("robot"))
        assert r.returncode == 0 and "Removed 1 pairing key(s) of sami" in r.stdout, \
            r.stdout + r.stderr
        assert "holds other keys too" in r.stdout
        r = lab.run("laptop", [*ssh, "anything"], input=csr("sami"), timeout=30)
        assert r.returncode == 255 and pairing.report_of(r.stdout) is None, r.stdout + r.stderr
    finally:
        keys.write_text(before)
