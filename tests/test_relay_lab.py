"""ROS 2 through the relay on the network lab (issue 30): neither modem forwards the Zenoh port;
both sites' routers (real Zenoh routers, from the config `ros apply` writes under [relay]) dial
the relay, which runs `rosnet-tui relay serve` with the router config the product wrote for it
and its certificate from the master's fleet CA. From both seats relay.router and ros2.router pass
(the path to the relay), a stand-in node's messages cross the relay, and an outsider on the
internet gets no Zenoh session at the relay (plain TCP, or a certificate of another CA)."""

from __future__ import annotations

import pytest

from tests.lab import outsider
from tests.lab.relay import RelayWorld
from tests.lab.topology import ADDR
from tests.lab.verdicts import explain

pytestmark = pytest.mark.lab


@pytest.fixture(scope="module")
def relay_world(lab):
    with RelayWorld(lab) as world:
        yield world


def test_both_sites_meet_at_the_relay_and_strangers_do_not(relay_world):
    w = relay_world
    talker = w.node("robot", "talker")
    listener = w.node("laptop", "listener")
    assert w.lab.wait_output(listener, r"heard: hello from turtlebot \d+ \(attachment ok\)",
                             timeout=20), w.lab.output(listener)
    w.lab.kill(talker)
    for host in ("robot", "laptop"):
        results = w.check(host)
        relay = results["relay.router"]
        assert relay["status"] == "pass", explain(results)
        assert relay["data"]["endpoint"] == f"tls/{ADDR.RELAY_NAME}:7447"
        assert relay["data"]["address"] == ADDR.RELAY_IP
        router = results["ros2.router"]
        assert router["status"] == "pass", explain(results)
        assert router["data"]["endpoint"] == f"tls/{ADDR.RELAY_NAME}:7447"
        assert router["data"]["local_router"]["routers"], explain(results)   # linked to the relay
        stranger = results["security.outsider"]       # what a stranger gets at the relay
        assert stranger["status"] == "pass", explain(results)
        assert stranger["data"]["target"] == f"{ADDR.RELAY_NAME}:7447"
    for tls in (False, True):
        got = outsider.zenoh_session(w.lab, ADDR.RELAY_IP, 7447, tls=tls)
        assert got["session"] is False, got
    port = w.check("robot", step="router")["router.port_open"]   # the master forwards nothing:
    assert port["status"] == "pass" and "the relay's TCP 7447" in port["summary"], port  # the
    assert port["data"]["public_ip"] == ADDR.RELAY_IP, port       # relay's port is the one open
    for host in ("robot", "laptop"):   # every step: nothing fails, `check` exits 0
        r = w.lab.rosnet(host, "check", "--config", str(w.config_path(host)), env=w.env(host),
                         timeout=90)
        assert r.returncode == 0, r.stdout + r.stderr


def test_the_robot_behind_carrier_nat_still_meets_the_laptop_at_the_relay(relay_world):
    """The robot's modem moved behind the carrier's NAT (a new, shared public address): its
    router dials the relay again through it, and messages cross again, bounded."""
    w = relay_world
    w.lab._set_cgnat(True)
    try:
        results = w.check("robot")
        assert results["relay.router"]["status"] == "pass", explain(results)
        nat = w.check("robot", step="isp")["isp.cgnat"]     # seen, and no problem here:
        assert nat["status"] == "pass" and nat["data"]["cgnat"], nat   # the relay carries it
        assert "carrier-grade NAT" in nat["summary"] and "relay" in nat["summary"], nat
        listener = w.node("laptop", "listener", name="relay_listener")
        talker = w.node("robot", "talker", name="relay_talker")
        assert w.lab.wait_output(listener, r"heard: hello from turtlebot \d+", timeout=40), \
            w.lab.output(listener)
        w.lab.kill(talker)
        w.lab.kill(listener)
    finally:
        w.lab._set_cgnat(False)
        w.start_router("robot")        # a fresh link from the robot's own address again


def test_a_stopped_relay_fails_within_the_timeout_and_is_named_first(relay_world):
    w = relay_world
    w.stop_relay()
    try:
        results = w.check("laptop")
        relay = results["relay.router"]
        assert relay["status"] == "fail", explain(results)
        assert relay["duration_s"] <= 3.0 + 0.5, explain(results)
        advice = relay.get("advice") or []
        assert advice and advice[0]["rule"] == "relay.router.down", explain(results)
    finally:
        w.start_relay()
