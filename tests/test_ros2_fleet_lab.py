"""ROS 2 over rmw_zenoh with three components (a master and two members, each behind its own
modem) on the fleet lab (tests/lab/fleet.py, tests/lab/fleet_ros2.py): real Zenoh routers, the
members' routers dialling the master's by name through its modem's forwarded port 7447, stand-in
rmw_zenoh nodes, and `rosnet-tui check --json --step ros` from every seat.

Issue 21: from a member, ros2.graph failed about 3 runs in 5 with "<peer>'s nodes are not seen from
here: (the probe node ...): the routers are not linked" while the other checks passed. The checker
acknowledged each peer's probe node as soon as it saw it, the peer then dropped it, and the verdict
was taken from the checker's *last* look at the graph, in which the first peer's probe was already
gone while it waited for the second's (one router hop further away).
"""

from __future__ import annotations

import time

import pytest

from tests.lab.fleet_ros2 import ROS2_IDS
from tests.lab.verdicts import explain

pytestmark = pytest.mark.lab
FLEET_SITES = 3
RUNS = 20


@pytest.fixture(scope="module")
def ros2_world(fleet_ros2_world):
    """This module's ROS 2 world is the fleet's (the lab plugin's ``ros2`` keeps it healthy)."""
    return fleet_ros2_world


def test_every_members_router_is_linked_to_the_masters(ros2):
    print(f"fleet of {len(ros2.lab.sites)} built in {ros2.lab.build_s['total']:.2f} s, "
          f"ROS 2 routers up and linked in {ros2.start_s:.2f} s")
    assert ros2.linked() == {"sami": True, "member2": True}


def test_from_the_master_ros2_router_lists_both_members_routers_with_their_public_addresses(ros2):
    """Issue 31: the master's ros2.router reads its own router's admin space (no SSH) and lists
    the members' routers linked right now, each with its Zenoh version and the address it came
    from: that member's modem, its public side."""
    fleet = ros2.lab
    results = ros2.check(fleet.master)
    router = results["ros2.router"]
    assert router["status"] == "pass", explain(results)
    members = {m["name"]: m for m in router["data"]["member_routers"]}
    assert sorted(members) == sorted(fleet.members), explain(results)
    for name, m in members.items():
        assert m["address"].rsplit(":", 1)[0] == fleet.public_ip(name), explain(results)
        assert m["version"] == router["data"]["router_version"], explain(results)
    assert router["data"]["version_skew"] == []
    line = next(e for e in router["evidence"] if e.startswith("member routers linked now: 2"))
    assert all(f"{n} ({fleet.public_ip(n)}:" in line for n in fleet.members), line


def test_from_the_master_a_member_whose_router_is_down_is_named_as_not_linked(ros2):
    ros2.stop_router("member2")
    results = ros2.check(ros2.lab.master)
    router = results["ros2.router"]
    assert [m["name"] for m in router["data"]["member_routers"]] == ["sami"], explain(results)
    assert "not linked now: member2" in router["evidence"], explain(results)


def test_a_healthy_three_site_network_passes_every_ros2_check_20_runs_from_each_seat(ros2):
    fleet = ros2.lab
    ros2.node(fleet.master, "talker")
    listener = ros2.node("sami", "listener")
    assert fleet.wait_output(listener, r"heard: hello from turtlebot \d+ \(attachment ok\)",
                             timeout=15), fleet.output(listener)
    expected = {"/talker": "turtlebot", "/listener": "sami"}
    timings: dict[str, list[float]] = {}
    for host in ("sami", "member2", "turtlebot"):
        peers = sorted(n for n in fleet.COMPUTERS if n != host)
        for run in range(RUNS):
            t0 = time.monotonic()
            results = ros2.check(host)
            timings.setdefault(host, []).append(time.monotonic() - t0)
            where = f"run {run + 1} of {RUNS} from {host}:\n{explain(results)}"
            assert list(results) == ROS2_IDS, where
            assert all(c["status"] == "pass" for c in results.values()), where
            graph = results["ros2.graph"]["data"]
            assert graph["probe_seen"] == dict.fromkeys(peers, True), where
            assert graph["ours_seen"] == dict.fromkeys(peers, True), where
            assert {n["name"]: n["component"] for n in graph["nodes"]} == expected, where
            for cid in ("ros2.pubsub_out", "ros2.pubsub_in"):
                assert sorted(results[cid]["data"]["peers"]) == peers, where
    print({h: f"{min(t):.2f}-{max(t):.2f} s, mean {sum(t) / len(t):.2f} s"
           for h, t in timings.items()})


def test_a_far_member_does_not_hide_the_nearer_peers_probe_node(ros2):
    """The race made certain: member2 is on a slow line (400 kbit/s), so the peer programs (fed
    over SSH, about 20 kB each) start there most of a second after the master's, and from sami the
    master's probe node shows up, is acknowledged and dropped well before member2's shows up.
    The verdict must still count both as seen, from the other member and from the master."""
    ros2.node("turtlebot", "talker")
    ros2.lab.set_rate("member2", "400kbit")
    for host in ("sami", "turtlebot"):
        peers = sorted(n for n in ros2.lab.COMPUTERS if n != host)
        results = ros2.check(host, step="ros")
        graph = results["ros2.graph"]
        assert graph["status"] == "pass", explain(results)
        assert graph["data"]["probe_seen"] == dict.fromkeys(peers, True), explain(results)
        assert all(c["status"] == "pass" for c in results.values()), explain(results)
