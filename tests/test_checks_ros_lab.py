"""The ros.* checks on the network lab: `rosnet-tui check --step ros` run on a component, the peer's
side over the lab's SSH, the master on the robot behind its modem's port forwarding."""

from __future__ import annotations

import time

import pytest

from tests.lab.firewall import secured
from tests.lab.verdicts import explain, lab_check

pytestmark = pytest.mark.lab

ROS_IDS = ["ros.env", "ros.master", "ros.node_uris", "ros.pubsub_out", "ros.pubsub_in",
           "ros.link", "security.outsider"]


def ros_check(lab, host: str) -> dict[str, dict]:
    """`rosnet-tui check --json --step ros` on *host*, in its ROS environment."""
    results = lab_check(lab, host, step="ros", timeout=60)
    assert list(results) == ROS_IDS, explain(results)
    return results


def test_healthy_lab_passes_both_directions_from_each_seat(ros1_lab):
    lab = ros1_lab
    lab.reset()
    with secured(lab):                     # ROS 1 as the product sets it up: the firewall on
        both = {h: ros_check(lab, h) for h in ("laptop", "robot")}
    for host, peer in (("laptop", "turtlebot"), ("robot", "sami")):
        results = both[host]
        assert all(c["status"] == "pass" for c in results.values()), explain(results)
        assert results["ros.pubsub_out"]["data"]["peer"] == peer
        assert results["ros.pubsub_in"]["data"]["ok"] is True
        assert results["ros.node_uris"]["data"]["from"] == ["here", peer]
        assert "/rosout" in results["ros.master"]["data"]["nodes"]
        out = results["security.outsider"]["data"]     # the outsider is shut out, the peer not
        assert not any(out["outsider_reachable"].values()), explain(results)
        assert all(out["insider_reachable"].values()), explain(results)


def test_ros_ip_on_the_laptop_names_its_node_and_breaks_one_direction(ros1_lab):
    lab = ros1_lab
    with lab.variant("ros_ip_laptop"):
        talker = lab.talker("laptop", "/rnl_chatter_ros_ip")
        try:
            line = lab.wait_output(talker, r"talker on \S+ as (\S+) at (\S+)", timeout=15)
            assert line, lab.output(talker)
            results = ros_check(lab, "laptop")
        finally:
            lab.kill(talker)
    text = explain(results)
    assert results["ros.env"]["status"] == "warn" and results["ros.env"]["data"]["ros_ip"] == \
        lab.addr.LAPTOP_LOCAL, text

    uris = results["ros.node_uris"]
    assert uris["status"] == "fail", text
    bad = {u["node"]: u for u in uris["data"]["unreachable"]}
    assert bad and all(u["from"] == "turtlebot" for u in bad.values()), text
    assert all(u["host"] == lab.addr.LAPTOP_LOCAL for u in bad.values()), text
    assert any(n.startswith("/rnl_talker") for n in bad), text        # the user's node
    assert any(n.startswith("/rosnet_probe_sami") for n in bad), text  # and ours, started alike
    assert lab.addr.LAPTOP_LOCAL in uris["summary"]

    out, back = results["ros.pubsub_out"], results["ros.pubsub_in"]
    assert out["status"] == "fail", text
    assert out["data"]["failed_hop"] == "xmlrpc_callback", text
    assert out["data"]["node"].startswith("/rosnet_probe_sami"), text
    assert f"http://{lab.addr.LAPTOP_LOCAL}:" in out["data"]["uri"], text
    assert "ROS_IP" in out["summary"], text
    assert back["status"] == "pass", text  # the laptop can still subscribe to the robot


def test_master_down_fails_within_its_timeout(ros1_lab):
    lab = ros1_lab
    lab.reset()
    lab.stop_roscore()
    try:
        start = time.monotonic()
        results = ros_check(lab, "laptop")
        took = time.monotonic() - start
    finally:
        lab.start_roscore()
    master = results["ros.master"]
    assert master["status"] == "fail", explain(results)
    assert master["duration_s"] <= master["timeout_s"] + 0.5
    assert "did not answer" in master["summary"] or "no answer" in master["summary"]
    assert master["data"]["reachable"] is False
    for cid in ("ros.node_uris", "ros.pubsub_out", "ros.pubsub_in"):
        assert results[cid]["status"] == "fail", explain(results)
    assert results["ros.pubsub_out"]["data"]["failed_hop"] == "registration"
    assert took < 30
