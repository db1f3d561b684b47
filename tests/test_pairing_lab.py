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

from rosnet_tui.core import fleet_tls
from tests.lab.ros2 import ROS2_IDS, Ros2World, explain

pytestmark = pytest.mark.lab


@pytest.fixture(scope="module")
def world(lab):
    with Ros2World(lab) as w:
        yield w


@pytest.fixture
def ros2(world):
    world.healthy()
    yield world
    world.remove_tls("laptop")
    world.healthy()


def test_a_member_pairs_over_ssh_within_5_s_and_then_every_check_passes(ros2):
    lab = ros2.lab
    ros2.stop_router("laptop")
    ros2.remove_tls("laptop")
    cfg = ros2.config_path("laptop")
    t0 = time.monotonic()
    r = lab.rosnet("laptop", "ros", "pair", "--config", str(cfg), env=ros2.env("laptop"))
    took = time.monotonic() - t0
    assert r.returncode == 0, r.stdout + r.stderr
    assert "Paired with turtlebot's fleet CA" in r.stdout, r.stdout
    print(f"pairing took {took:.2f} s (whole CLI process)")
    assert took <= 5.0
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
