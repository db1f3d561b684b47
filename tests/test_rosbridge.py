"""Web clients (issue 24) without the lab: [rosbridge] settings, the forwards it adds, the step
texts, ros.rosbridge's hops against real servers on loopback, and the advisor's rule per hop.
The lab tests (tests/test_rosbridge_lab.py) run the whole path through a modem."""

from __future__ import annotations

import asyncio
import json
import subprocess
import sys
from dataclasses import replace

import pytest

from rosnet_tui.core.advisor import advise
from rosnet_tui.core.checks import REGISTRY, CheckContext, data, load_builtin_checks, run_check
from rosnet_tui.core.config.settings_model import (
    Peer,
    RosbridgeSettings,
    RosSettings,
    Settings,
    SettingsError,
    ThisComponent,
)
from rosnet_tui.core.exposure.forwarding import ports_to_forward, required_ports
from rosnet_tui.core.results import CheckResult, Status
from rosnet_tui.core.ros import rosbridge
from rosnet_tui.core.saved.settings import parse_settings, render_settings
from rosnet_tui.core.upnp.forwards import description, needs
from rosnet_tui.core.wizard.steps import STEP_BY_ID, step_for
from tests.builders import free_port


def member(version: int = 1, **bridge) -> Settings:
    """sami, a member; 'localhost' is the master (and so, by default, the bridge's host)."""
    return Settings(this=ThisComponent(name="sami", role="member", local_ip="192.168.1.10"),
                    peers=[Peer(name="localhost", local_ip="127.0.0.1", public_ip="127.0.0.1")],
                    ros=RosSettings(master="localhost", version=version),
                    rosbridge=RosbridgeSettings(**{"enabled": True, **bridge}))


def master(version: int = 2, **bridge) -> Settings:
    return Settings(this=ThisComponent(name="turtlebot", role="master", local_ip="10.10.10.1"),
                    peers=[Peer(name="sami", public_ip="198.51.100.2")],
                    ros=RosSettings(master="turtlebot", version=version),
                    rosbridge=RosbridgeSettings(**{"enabled": True, **bridge}))


# --------------------------------------------------------------------------- settings
def test_settings_default_off_on_9090_on_the_master_and_round_trip():
    s = parse_settings("[this]\nname = \"sami\"\n")
    assert s.rosbridge == RosbridgeSettings(enabled=False, port=9090, host="")
    assert "[rosbridge]" not in render_settings(s)        # not written unless asked for
    on = master(port=9091, host="sami")
    text = render_settings(on)
    assert "[rosbridge]" in text and "enabled = true" in text
    assert parse_settings(text).rosbridge == on.rosbridge
    assert member().rosbridge_host == "localhost"         # default: the master
    assert master().hosts_rosbridge and not member().hosts_rosbridge
    # switched off again: the table stays and says so (never a stale `enabled = true`)
    off = replace(on, rosbridge=RosbridgeSettings())
    assert parse_settings(render_settings(off, text)).rosbridge.enabled is False


@pytest.mark.parametrize("text, key", [
    ("[rosbridge]\nenabled = 1\n", "rosbridge.enabled"),
    ("[rosbridge]\nenabled = \"yes\"\n", "rosbridge.enabled"),
    ("[rosbridge]\nport = 70000\n", "rosbridge.port"),
    ("[rosbridge]\nport = true\n", "rosbridge.port"),
    ("[rosbridge]\nhost = \"nobody\"\n", "rosbridge.host"),
    ("[rosbridge]\nbridge = 1\n", "rosbridge.bridge"),
])
def test_bad_rosbridge_settings_are_refused_with_their_key(text, key):
    with pytest.raises(SettingsError) as exc:
        parse_settings("[this]\nname = \"sami\"\n" + text)
    assert exc.value.key == key


# --------------------------------------------------------------------------- forwards and texts
def test_the_hosts_modem_forwards_the_bridge_port_besides_the_zenoh_port():
    assert [(p.ports, p.required) for p in ports_to_forward(master())][:2] == [("7447", True),
                                                                            ("9090", True)]
    assert [p.ports for p in required_ports(replace(master(), rosbridge=RosbridgeSettings()))] \
        == ["7447"]
    assert [p.ports for p in required_ports(member(2))] == []           # not the host
    hosting = member(2, host="sami")
    assert [p.ports for p in required_ports(hosting)] == ["9090"]        # a member hosting it
    assert [p.ports for p in required_ports(master(1))] == ["1024-65000"]  # the range covers it
    assert [p.ports for p in required_ports(master(1, port=443))] == ["1024-65000", "443"]
    got = needs(master())
    assert [w.port for w in got.forwards] == [7447, 9090, 12345]
    assert description(master(), got.forwards[1]) == "rosnet-tui turtlebot rosbridge"


def test_step_texts_and_the_ros_step_checks():
    for s, launch in ((member(1), "roslaunch rosbridge_server rosbridge_websocket.launch"),
                      (member(2), "ros2 launch rosbridge_server rosbridge_websocket_launch.xml")):
        text = STEP_BY_ID["ros"].configure(s)
        assert launch in text and "ws://localhost:9090/" in text and "rosauth" in text
        assert step_for("ros", s).check_ids[-1] == "ros.rosbridge"
        off = replace(s, rosbridge=RosbridgeSettings())
        assert "ros.rosbridge" not in step_for("ros", off).check_ids
        assert "rosbridge" not in STEP_BY_ID["ros"].configure(off)
    router = STEP_BY_ID["router"].configure(master())
    assert "TCP 9090" in router and "besides the Zenoh port 7447" in router
    assert "9090" not in STEP_BY_ID["router"].configure(member(2))
    assert "port:=9091" in STEP_BY_ID["ros"].configure(member(1, port=9091))


# --------------------------------------------------------------------------- the check
async def run(settings: Settings, timeout: float = 1.0) -> CheckResult:
    load_builtin_checks()
    return await run_check(REGISTRY["ros.rosbridge"],
                           CheckContext(settings=settings, timeout_s=timeout, upnp=False))


async def test_skipped_when_off_and_on_the_host():
    r = await run(replace(member(), rosbridge=RosbridgeSettings()))
    assert r.status is Status.SKIP and "[rosbridge] enabled = false" in r.summary
    r = await run(master())
    assert r.status is Status.SKIP and "turtlebot runs rosbridge" in r.summary
    assert "sami" in r.summary


async def test_nothing_listening_is_the_bridge_hop_with_declared_data():
    r = await run(member(port=free_port()))
    assert r.status is Status.FAIL and r.data["failed_hop"] == "bridge", r.summary
    assert r.data["tcp"] == "refused" and r.data["address"] == "127.0.0.1"
    assert data.undeclared("ros.rosbridge", r.data) == []


async def _serve(handler):
    server = await asyncio.start_server(handler, "127.0.0.1", 0)
    return server, server.sockets[0].getsockname()[1]


async def test_a_plain_web_server_is_the_upgrade_hop():
    async def http(reader, writer):
        await reader.readuntil(b"\r\n\r\n")
        writer.write(b"HTTP/1.1 404 Not Found\r\nContent-Length: 0\r\nConnection: close\r\n\r\n")
        await writer.drain()
        writer.close()

    server, port = await _serve(http)
    async with server:
        r = await run(member(port=port))
    assert r.data["failed_hop"] == "upgrade" and "HTTP 404" in r.summary, r.summary
    assert r.data["tcp"] == "connected" and r.data["upgraded"] is False


async def _ws_server(on_message):
    from websockets.asyncio.server import serve

    async def handler(ws):
        async for raw in ws:
            for out in on_message(json.loads(raw)):
                await ws.send(json.dumps(out))

    return await serve(handler, "127.0.0.1", 0)


async def test_a_websocket_that_never_answers_is_the_bridge_hop_within_the_timeout():
    server = await _ws_server(lambda msg: [])
    async with server:
        port = server.sockets[0].getsockname()[1]
        r = await run(member(port=port), timeout=1.0)
    assert r.data["failed_hop"] == "bridge" and r.data["upgraded"] is True, r.summary
    assert r.duration_s < 2 * 1.0  # one wait, never two (bench row 3 times it)


async def test_topics_but_no_message_back_is_the_round_trip_hop():
    def answer(msg):
        if msg.get("op") == "call_service":
            return [{"op": "service_response", "id": msg["id"], "service": msg["service"],
                     "values": {"topics": ["/rosout", "/rosnet_probe/x"], "types": ["", ""]},
                     "result": True}]
        return []
    server = await _ws_server(answer)
    async with server:
        port = server.sockets[0].getsockname()[1]
        r = await run(member(port=port), timeout=1.0)
    assert r.data["failed_hop"] == "round_trip", r.summary
    assert r.data["rosapi"] is True and r.data["topics"] == ["/rosout"]
    assert r.duration_s < 2 * 1.0  # one wait, never two (bench row 3 times it)


async def test_the_whole_path_passes_against_a_loopback_bridge():
    """A minimal bridge in this process (the lab runs the real-roscore stand-in): subscribe, then
    publish from another connection, comes back as a publish op."""
    from websockets.asyncio.server import serve

    subscribers: dict[str, list] = {}

    async def handler(ws):
        async for raw in ws:
            msg = json.loads(raw)
            op = msg.get("op")
            if op == "call_service":
                await ws.send(json.dumps({"op": "service_response", "id": msg["id"],
                                          "service": msg["service"], "result": True,
                                          "values": {"topics": ["/rosout"], "types": ["x"]}}))
            elif op == "subscribe":
                subscribers.setdefault(msg["topic"], []).append(ws)
            elif op == "publish":
                for sub in subscribers.get(msg["topic"], []):
                    await sub.send(json.dumps({"op": "publish", "topic": msg["topic"],
                                               "msg": msg["msg"]}))

    async with await serve(handler, "127.0.0.1", 0) as server:
        port = server.sockets[0].getsockname()[1]
        r = await run(member(2, port=port), timeout=2.0)
    assert r.status is Status.PASS, (r.summary, r.evidence)
    assert r.data["round_trip"] is True and r.data["round_trip_ms"] is not None
    assert any("std_msgs/msg/String" in e for e in r.evidence)


def test_websockets_stays_off_the_start_up_path():
    code = ("import sys; import rosnet_tui.ui.app; from rosnet_tui.core.checks import "
            "load_builtin_checks; load_builtin_checks(); import rosnet_tui.core.advisor; "
            "sys.exit(1 if 'websockets' in sys.modules else 0)")
    assert subprocess.run([sys.executable, "-c", code], timeout=60).returncode == 0


# --------------------------------------------------------------------------- the advisor
def result(s: Settings, status: str, **d) -> CheckResult:
    base = {"host": s.rosbridge_host, "url": rosbridge.url(s), "address": "203.0.113.2",
            "tcp": "connected", "upgraded": False, "rosapi": False, "topics": [],
            "round_trip": False, "round_trip_ms": None, "failed_hop": None, "detail": "seen"}
    return CheckResult("ros.rosbridge", "ros", Status(status), "summary", [], 0.1, 3.0,
                       {**base, **d})


@pytest.mark.parametrize("hop, tcp, rule, goto, words", [
    ("name", None, "rosbridge.name", "linux", "hosts apply"),
    ("forward", "timeout", "rosbridge.forward", "router", "forward TCP 9090"),
    ("bridge", "refused", "rosbridge.not_running", "ros", "rosbridge_websocket.launch"),
    ("bridge", "connected", "rosbridge.not_running", "ros", "rosbridge_websocket.launch"),
    ("upgrade", "connected", "rosbridge.upgrade", "ros", "ss -ltnp"),
    ("rosapi", "connected", "rosbridge.rosapi", "ros", "rosapi_node"),
    ("round_trip", "connected", "rosbridge.round_trip", "ros", "ROS environment"),
])
def test_one_rule_per_hop(hop, tcp, rule, goto, words):
    s = replace(member(), peers=[Peer(name="localhost", public_ip="203.0.113.2")])
    found = advise({"ros.rosbridge": result(s, "fail", failed_hop=hop, tcp=tcp)}, s, strict=True)
    mine = [f for f in found if f.rule.startswith("rosbridge.")]
    assert [f.rule for f in mine] == [rule]
    assert mine[0].goto_step == goto and mine[0].severity == "fail"
    assert words in " ".join(mine[0].actions), mine[0].actions
    assert not [f for f in found if f.rule == "check.unexplained"]


def test_security_the_bridge_is_exposed_like_the_master():
    s = member()
    ok = result(s, "pass", upgraded=True, rosapi=True, round_trip=True, detail=None)
    sec = [f for f in advise({"ros.rosbridge": ok}, s, strict=True)
           if f.rule == "security.rosbridge_exposed"]
    assert sec and sec[0].severity == "security"
    text = sec[0].meaning + " ".join(sec[0].actions)
    assert "like the ROS master" in text and "rosauth" in text and "TCP 9090" in text
    assert "ssh -L 9090:localhost:9090" in text
    skip = CheckResult("ros.rosbridge", "ros", Status.SKIP, "skipped", [], 0, 3, {})
    assert not any(f.rule == "security.rosbridge_exposed"    # a skipped check says nothing
                   for f in advise({"ros.rosbridge": skip}, master(), strict=True))
    off = replace(s, rosbridge=RosbridgeSettings())
    assert not any(f.rule.startswith(("rosbridge.", "security.rosbridge"))
                   for f in advise({"ros.rosbridge": ok}, off, strict=True))


def _case(status: str, **d):
    def build():
        s = replace(member(), peers=[Peer(name="localhost", public_ip="203.0.113.2")])
        return {"ros.rosbridge": result(s, status, **d)}, s
    return build


# The advisor's rule cases (tests/test_advisor_rules.py runs every rule on its case).
ROSBRIDGE_CASES = {
    "rosbridge.name": _case("fail", failed_hop="name", tcp=None, address=None),
    "rosbridge.forward": _case("fail", failed_hop="forward", tcp="timeout"),
    "rosbridge.not_running": _case("fail", failed_hop="bridge", tcp="refused"),
    "rosbridge.upgrade": _case("fail", failed_hop="upgrade"),
    "rosbridge.rosapi": _case("fail", failed_hop="rosapi", upgraded=True),
    "rosbridge.round_trip": _case("fail", failed_hop="round_trip", upgraded=True, rosapi=True),
    "security.rosbridge_exposed": _case("pass", upgraded=True, rosapi=True, round_trip=True,
                                        detail=None),
}


def test_a_reports_settings_keep_rosbridge():
    """`rosnet-tui report --from-json` reads the settings back: the rosbridge rules need them."""
    from rosnet_tui.core.wizard.report import ReportError, public_settings, settings_from_dict

    s = master(port=9091, host="sami")
    assert settings_from_dict(public_settings(s)).rosbridge == s.rosbridge
    bad = public_settings(s)
    bad["rosbridge"]["enabled"] = "yes"
    with pytest.raises(ReportError, match="rosbridge.enabled"):
        settings_from_dict(bad)


def test_a_member_running_rosbridge_under_ros2_forwards_only_its_port():
    text = STEP_BY_ID["router"].configure(member(2, host="sami"))
    assert "Only rosbridge needs a forward" in text and "TCP 9090" in text
    assert "Zenoh port" not in text.split("**rosbridge")[1]
