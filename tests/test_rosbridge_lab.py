"""ros.rosbridge on the network lab (issue 24): from the laptop (sami), a browser's path to the
robot's rosbridge (turtlebot) through the robot's modem, against the lab's rosbridge stand-in
bridging to the real roscore (tests/lab/rosbridge.py). It passes when the bridge works, and fails
naming the hop, within timeout_s + 0.5 s, when the bridge is stopped, the port is not forwarded,
or rosapi is missing."""

from __future__ import annotations

import json

import pytest

from tests.lab import rosbridge as lab_bridge
from tests.lab.firewall import secured

pytestmark = pytest.mark.lab

# One check, run on a lab computer (its names, its hosts file), with the advisor's reading.
_ONE = """
import json, sys
from pathlib import Path
from rosnet_tui.core.advisor import advise
from rosnet_tui.core.checks.runner import RunOptions, run_now, select
from rosnet_tui.core.saved.settings import load_settings
s = load_settings(Path(sys.argv[1]))
r = run_now(s, select(ids=["ros.rosbridge"]), RunOptions(upnp=False))[0]
print(json.dumps({"status": r.status.value, "summary": r.summary, "evidence": r.evidence,
                  "data": r.data, "duration_s": r.duration_s, "timeout_s": r.timeout_s,
                  "rules": [f.rule for f in advise({r.id: r}, s)]}))
"""


def rosbridge_check(lab, host: str = "laptop", version: int = 1) -> dict:
    path = lab_bridge.config_path(lab, host, version)
    r = lab.run(host, [__import__("sys").executable, "-c", _ONE, str(path)], timeout=30)
    assert r.stdout.strip(), r.stderr
    return json.loads(r.stdout)


def check_through(lab, forwarding: str, bridge: dict | None, version: int = 1) -> dict:
    """ros.rosbridge from the laptop, the robot's modem forwarding as *forwarding* ("bridge": TCP
    22 and 9090; "ssh": 22 only) to the lab's bridge started with the options *bridge* (None: no
    bridge); the lab healthy again after."""
    lab.reset()
    lab._set_forwarding("robot", forwarding)
    proc = None if bridge is None else lab_bridge.start_bridge(lab, **bridge)
    try:
        return rosbridge_check(lab, "laptop", version)
    finally:
        if proc is not None:
            lab.kill(proc)
        lab.reset()


def explain(res: dict) -> str:
    return f"{res['status']} - {res['summary']}\n  " + "\n  ".join(res["evidence"])


def assert_fails_at(res: dict, hop: str, rule: str) -> None:
    assert res["status"] == "fail", explain(res)
    assert res["data"]["failed_hop"] == hop, explain(res)
    assert f"{hop.replace('_', ' ')} hop" in res["summary"]
    assert res["duration_s"] <= res["timeout_s"] + 0.5, res["duration_s"]
    assert rule in res["rules"], res["rules"]


@pytest.mark.parametrize("version", [1, 2])
def test_passes_from_the_laptop_through_the_robots_modem(ros1_lab, version):
    """Only TCP 22 and 9090 are forwarded to the robot: the browser's path needs nothing else."""
    lab = ros1_lab
    res = check_through(lab, "bridge", {}, version)
    d = res["data"]
    assert res["status"] == "pass", explain(res)
    assert d["url"] == "ws://turtlebot:9090/" and d["address"] == lab.addr.ROBOT_PUBLIC
    assert d["tcp"] == "connected" and d["upgraded"] and d["rosapi"] and d["round_trip"]
    assert "/rosout" in d["topics"]
    assert not any(t.startswith("/rosnet_probe") for t in d["topics"])
    assert "security.rosbridge_exposed" in res["rules"]  # reachable from outside: said so
    kind = "std_msgs/msg/String" if version == 2 else "std_msgs/String"
    assert any(kind in e for e in res["evidence"]), explain(res)


def test_in_the_ros_step_from_the_laptop_and_skipped_on_the_robot(ros1_lab):
    """`rosnet-tui check --step ros` on the healthy lab: the laptop's ros.rosbridge passes with
    the ROS 1 checks; on the robot, which runs the bridge, it is skipped, saying why."""
    lab = ros1_lab
    lab.reset()
    proc = lab_bridge.start_bridge(lab)
    got = {}
    try:
        with secured(lab, config=lambda h: lab_bridge.config_path(lab, h)):  # the firewall on
            for host in ("laptop", "robot"):
                r = lab.rosnet(host, "check", "--json", "--step", "ros", "--config",
                               str(lab_bridge.config_path(lab, host)), timeout=60)
                got[host] = {c["id"]: c for c in json.loads(r.stdout)["checks"]}
    finally:
        lab.kill(proc)
    laptop, robot = got["laptop"], got["robot"]
    assert list(laptop)[-2:] == ["ros.rosbridge", "security.outsider"]
    assert all(c["status"] == "pass" for c in laptop.values()), \
        {k: c["summary"] for k, c in laptop.items()}
    assert robot["ros.rosbridge"]["status"] == "skip"
    assert "turtlebot runs rosbridge" in robot["ros.rosbridge"]["summary"]
    assert "sami" in robot["ros.rosbridge"]["summary"]


def test_bridge_stopped_fails_at_the_bridge_hop(ros1_lab):
    res = check_through(ros1_lab, "bridge", None)
    assert_fails_at(res, "bridge", "rosbridge.not_running")
    assert res["data"]["tcp"] == "refused"
    assert "rosbridge_websocket.launch" in res["summary"]


def test_port_not_forwarded_fails_at_the_forward_hop_within_the_timeout(ros1_lab):
    """The robot's modem forwards SSH only: 9090 is dropped, bad news within timeout_s + 0.5."""
    res = check_through(ros1_lab, "ssh", {})
    assert_fails_at(res, "forward", "rosbridge.forward")
    assert res["data"]["tcp"] == "timeout"
    assert "forwarded to turtlebot" in res["summary"]


def test_rosapi_missing_fails_at_the_rosapi_hop(ros1_lab):
    res = check_through(ros1_lab, "bridge", {"rosapi": False})
    assert_fails_at(res, "rosapi", "rosbridge.rosapi")
    d = res["data"]
    assert d["upgraded"] is True and d["rosapi"] is False
    assert "/rosapi/topics does not exist" in d["detail"]


def test_a_name_the_laptop_cannot_resolve_fails_at_the_name_hop(ros1_lab):
    """turtlebot missing from the laptop's hosts file (the lab's DNS does not know it either)."""
    lab = ros1_lab
    lab.reset()
    lab.write_hosts("laptop", "127.0.0.1\tlocalhost\n192.168.1.10\tsami\n")
    try:
        res = rosbridge_check(lab)
    finally:
        lab.reset()
    assert_fails_at(res, "name", "rosbridge.name")
    assert res["data"]["address"] is None and res["data"]["tcp"] is None
