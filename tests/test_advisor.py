"""The advisor's rules, one by one: results that trigger each rule and results that must not.

Results are built by hand following the checks contract (check ids and their ``data`` keys): these
test the pure logic of the rules, no network involved.
"""

from __future__ import annotations

import copy
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from rosnet_tui.core import advisor
from rosnet_tui.core.advisor import Finding, advice_by_check, advise, all_rules, first_failure
from rosnet_tui.core.results import CheckResult, Status
from rosnet_tui.core.settings import Peer, RosSettings, Settings, ThisComponent

ROOT = Path(__file__).resolve().parents[1]
STEP_OF = {"isp": "isp", "router": "router", "linux": "linux", "ros": "ros"}

from tests.test_advisor_ros2 import ROS2_CASES  # noqa: E402
from tests.test_advisor_upnp import UPNP_CASES  # noqa: E402
from tests.test_firewall import FIREWALL_CASES  # noqa: E402
from tests.test_rosbridge import ROSBRIDGE_CASES  # noqa: E402


# --------------------------------------------------------------------------- builders
def laptop_settings(**this) -> Settings:
    """sami, a member behind its home modem; the robot turtlebot runs the master."""
    t = dict(name="sami", role="member", connection="home", profile="remote",
             local_ip="192.168.1.10", public_ip="198.51.100.2")
    t.update(this)
    return Settings(this=ThisComponent(**t),
                    peers=[Peer("turtlebot", local_ip="10.10.10.1", public_ip="203.0.113.2",
                                ssh_user="root")],
                    ros=RosSettings(master="turtlebot"))


def robot_settings(**this) -> Settings:
    t = dict(name="turtlebot", role="master", connection="telecom", profile="remote",
             local_ip="10.10.10.1", public_ip="203.0.113.2")
    t.update(this)
    return Settings(this=ThisComponent(**t),
                    peers=[Peer("sami", local_ip="192.168.1.10", public_ip="198.51.100.2",
                                ssh_user="root")],
                    ros=RosSettings(master="turtlebot"))


def res(cid: str, status: str = "pass", summary: str = "", **data) -> CheckResult:
    return CheckResult(cid, cid.split(".")[0], Status(status), summary or f"{cid} {status}",
                       [f"evidence of {cid}"], 0.1, 3.0, data)


def healthy_laptop() -> dict[str, CheckResult]:
    """Every check passing, from sami's seat (what the healthy lab should give)."""
    peer = "turtlebot"
    rs = [
        res("isp.internet", dns_ok=True, http_ok=True, failed_part=None,
            url="http://probe.lab.test/"),
        res("isp.public_ip", public_ip="198.51.100.2",
            sources={"http://probe.lab.test/ip": "198.51.100.2"}, agree=True,
            settings_ip="198.51.100.2", matches_settings=True, previous_ip="198.51.100.2",
            changed=False, history=[{"ip": "198.51.100.2", "first_seen": "2024-01-01T00:00:00",
                                     "last_seen": "2024-01-02T00:00:00"}]),
        res("isp.cgnat", wan_ip=None, method="traceroute", cgnat=False, double_nat=False,
            hop=None),
        res("router.local_ip", local_ip="192.168.1.10", interface="eth0",
            gateway="192.168.1.254", expected_ip="192.168.1.10", differs=False),
        res("router.port_free", port=12345, in_use=False, process=None, pid=None),
        res("router.listener", port=12345, listening=True),
        res("router.port_open", ports=[
            {"port": 12345, "reachable": True, "listener": True, "via": "peer:turtlebot"},
            {"port": 23456, "reachable": True, "listener": True, "via": "peer:turtlebot"},
            {"port": 22, "reachable": True, "listener": True, "via": "peer:turtlebot"}],
            test_port=12345, test_port_open=True, public_ip="198.51.100.2"),
        res("linux.hosts", missing=[], wrong=[], duplicates=[], loopback=[]),
        res("linux.resolve", names={"sami": {"resolved": "192.168.1.10",
                                             "expected": "192.168.1.10"},
                                    peer: {"resolved": "203.0.113.2", "expected": "203.0.113.2"}},
            wrong=[], loopback=[]),
        res("linux.ping", peers={peer: {"icmp": True, "tcp22": True}}),
        res("linux.ssh", peers={peer: {"ok": True, "failure": None, "fingerprint": "SHA256:abc"}}),
        res("linux.chat_out", peers={peer: {"ok": True, "failure": None}}),
        res("linux.chat_in", peers={peer: {"ok": True, "failure": None}}),
        res("ros.env", env_uri="http://turtlebot:11311", bashrc_uri="http://turtlebot:11311",
            expected_uri="http://turtlebot:11311", uri_ok=True, ros_ip=None, ros_hostname=None),
        res("ros.master", uri="http://turtlebot:11311", reachable=True,
            topics=[["/rosout", "rosgraph_msgs/Log"]], nodes=["/rosout"]),
        res("ros.node_uris", unreachable=[], checked=2),
        res("ros.pubsub_out", peer=peer, ok=True, failed_hop=None, node=None, uri=None),
        res("ros.pubsub_in", peer=peer, ok=True, failed_hop=None, node=None, uri=None),
    ]
    return {r.id: r for r in rs}


def healthy_robot() -> dict[str, CheckResult]:
    """Every check passing, from turtlebot's seat (the master)."""
    r = healthy_laptop()
    r["isp.public_ip"].data.update(public_ip="203.0.113.2", settings_ip="203.0.113.2",
                                   previous_ip="203.0.113.2",
                                   sources={"http://probe.lab.test/ip": "203.0.113.2"})
    r["router.local_ip"].data.update(local_ip="10.10.10.1", gateway="10.10.10.254",
                                     expected_ip="10.10.10.1")
    r["router.port_open"].data["ports"].append(
        {"port": 11311, "reachable": True, "listener": True, "via": "peer:sami"})
    r["router.port_open"].data["public_ip"] = "203.0.113.2"
    r["linux.resolve"].data["names"] = {
        "turtlebot": {"resolved": "10.10.10.1", "expected": "10.10.10.1"},
        "sami": {"resolved": "198.51.100.2", "expected": "198.51.100.2"}}
    for cid in ("linux.ping", "linux.ssh", "linux.chat_out", "linux.chat_in"):
        r[cid].data["peers"] = {"sami": r[cid].data["peers"]["turtlebot"]}
    for cid in ("ros.pubsub_out", "ros.pubsub_in"):
        r[cid].data["peer"] = "sami"
    return r


def put(results: dict[str, CheckResult], cid: str, status: str, **data) -> None:
    """Change one result: its status and some data keys."""
    r = results[cid]
    r.status = Status(status)
    r.data.update(data)


def run(results, settings=None) -> list[Finding]:
    return advise(results, settings or laptop_settings(), strict=True)


def ids(findings: list[Finding]) -> list[str]:
    return [f.rule for f in findings]


def text(f: Finding) -> str:
    return f.meaning + "\n" + "\n".join(f.actions)


def only(findings: list[Finding], rule: str) -> Finding:
    got = [f for f in findings if f.rule == rule]
    assert len(got) == 1, (rule, ids(findings))
    return got[0]


# --------------------------------------------------------------------------- healthy
def test_healthy_network_has_no_failures_or_warnings():
    for results, s in ((healthy_laptop(), laptop_settings()), (healthy_robot(), robot_settings())):
        fs = run(results, s)
        assert [f.severity for f in fs if f.severity in ("fail", "warn")] == []
        assert "table1.open" in ids(fs)
        # Forwarding is in use, so the exposure warning is always there.
        assert "security.exposed" in ids(fs)


def test_empty_results_give_no_findings():
    assert run({}) == []


# --------------------------------------------------------------------------- Table 1
def t1(listening: bool, open_: bool, base=None) -> dict[str, CheckResult]:
    r = base or healthy_laptop()
    put(r, "router.listener", "pass" if listening else "fail", listening=listening)
    ports = [{"port": 12345, "reachable": open_, "listener": listening, "via": "echoip"}]
    put(r, "router.port_open", "pass" if open_ else "fail", ports=ports, test_port_open=open_)
    return r


def test_table1_listener_up_open_proceeds():
    fs = run(t1(True, True))
    f = only(fs, "table1.open")
    assert f.severity == "info" and f.goto_step == "linux"
    assert "198.51.100.2:12345" in f.meaning
    assert not [x for x in fs if x.rule.startswith("table1.") and x.rule != "table1.open"]


def test_table1_listener_down_closed_starts_listener():
    fs = run(t1(False, False))
    f = only(fs, "table1.no_listener")
    assert f.severity == "fail" and f.goto_step == "router"
    assert "nc -l 12345" in text(f)
    assert not [x for x in fs if x.rule.startswith(advisor.T1)]
    assert "table1.open" not in ids(fs)


def test_table1_listener_down_closed_names_the_process_holding_the_port():
    r = t1(False, False)
    put(r, "router.port_free", "fail", in_use=True, process="python3", pid=4242)
    f = only(run(r), "table1.no_listener")
    assert "python3 (pid 4242)" in text(f)
    assert "router.port_free" in f.check_ids


def test_table1_listener_down_open_means_another_program():
    r = t1(False, True)
    put(r, "router.port_free", "fail", in_use=True, process="nginx", pid=7)
    f = only(run(r), "table1.no_listener_open")
    assert "nginx" in f.meaning and f.severity == "warn"


def test_table1_listener_up_closed_three_causes_the_connection_type_breaks_the_tie():
    r = t1(True, False)
    del r["isp.cgnat"], r["router.port_free"]          # no evidence at all
    fs = run(r)                                        # sami: a home connection
    causes = [f for f in fs if f.rule.startswith(advisor.T1)]
    assert ids(causes) == [f"{advisor.T1}.forwarding", f"{advisor.T1}.isp",
                           f"{advisor.T1}.port_in_use"]
    assert [f.order for f in causes] == [0, 1, 2]
    assert [f.goto_step for f in causes] == ["router", "isp", "router"]
    assert all(f.severity == "fail" for f in causes)
    assert "another port between 1024 and 65000" in text(causes[2])
    assert "forward TCP (and UDP if needed) 1024-65000 to 192.168.1.10" in text(causes[0])
    # the first failure of the whole list is Table 1's first cause
    assert first_failure(fs) is causes[0]
    # a carrier's line: the carrier first, when nothing else was seen
    causes = [f for f in run(r, laptop_settings(connection="telecom"))
              if f.rule.startswith(advisor.T1)]
    assert ids(causes)[:2] == [f"{advisor.T1}.isp", f"{advisor.T1}.forwarding"]


def test_table1_port_in_use_cause_names_the_process_and_comes_first():
    r = t1(True, False)
    put(r, "router.port_free", "warn", in_use=True, process="sshd", pid=99)
    put(r, "isp.cgnat", "pass", cgnat=False, double_nat=False, method="traceroute")
    fs = run(r)
    f = first_failure(fs)
    assert f.rule == f"{advisor.T1}.port_in_use"
    assert "sshd (pid 99)" in f.meaning
    assert "router.port_free" in f.check_ids
    # the standalone port-in-use rule is superseded by Table 1's cause (a)
    assert "router.port_in_use" not in ids(fs)


def test_table1_cgnat_makes_isp_first_and_explains_why():
    r = t1(True, False)
    put(r, "isp.cgnat", "warn", cgnat=True, wan_ip="100.64.0.2", method="upnp", hop="100.64.0.2")
    fs = run(r)
    f = first_failure(fs)
    assert f.rule == f"{advisor.T1}.isp" and f.order == 0 and f.goto_step == "isp"
    assert "Carrier-grade NAT" in f.meaning and "100.64.0.2" in f.meaning
    assert "not the public address 198.51.100.2" in f.meaning
    assert "never reaches this modem" in f.meaning
    assert any("public IP" in a for a in f.actions)
    assert any("another connection" in a for a in f.actions)
    assert "isp.cgnat" in f.check_ids
    # the standalone carrier-NAT warning is folded into it
    assert "isp.cgnat" not in ids(fs)


def test_table1_cgnat_beats_a_changed_local_ip():
    r = t1(True, False)
    put(r, "isp.cgnat", "warn", cgnat=True, hop="100.64.0.1", method="traceroute")
    put(r, "router.local_ip", "warn", local_ip="192.168.1.23", differs=True)
    assert first_failure(run(r)).rule == f"{advisor.T1}.isp"


def test_table1_double_nat_behind_our_own_router_puts_the_inner_router_first():
    r = t1(True, False)
    put(r, "isp.cgnat", "warn", double_nat=True, wan_ip="192.168.0.2", method="upnp",
        hop="192.168.0.2")
    fs = run(r)
    f = first_failure(fs)
    assert f.rule == f"{advisor.T1}.forwarding" and f.goto_step == "router"
    assert "inner router (192.168.1.254" in f.actions[0] and "bridge" in f.actions[0]
    assert "WAN address (192.168.0.2)" in f.actions[1]
    second = [x for x in fs if x.rule.startswith(advisor.T1)][1]
    assert second.rule == f"{advisor.T1}.isp" and "provider" in second.meaning


def test_table1_private_nat_far_up_the_provider_puts_isp_first():
    r = t1(True, False)
    put(r, "isp.cgnat", "warn", double_nat=True, method="traceroute", hop="10.20.30.1",
        hops=["192.168.1.254", "198.51.100.1", "10.20.30.1"])
    f = first_failure(run(r))
    assert f.rule == f"{advisor.T1}.isp" and f.goto_step == "isp"
    assert "Double NAT" in f.meaning and "bridge mode" in text(f)


def test_table1_changed_local_ip_makes_forwarding_first():
    r = t1(True, False)
    put(r, "router.local_ip", "warn", local_ip="192.168.1.23", expected_ip="192.168.1.10",
        differs=True)
    fs = run(r)
    f = first_failure(fs)
    assert f.rule == f"{advisor.T1}.forwarding" and f.order == 0
    assert "from 192.168.1.10 to 192.168.1.23" in text(f)
    assert any("Reserve 192.168.1.23" in a and "DHCP" in a for a in f.actions)
    assert "router.local_ip" in f.check_ids
    assert "router.local_ip.differs" not in ids(fs)   # folded into the cause


def test_table1_no_carrier_nat_on_home_puts_forwarding_before_isp():
    r = t1(True, False)   # healthy cgnat (traceroute, no NAT) and a free port
    causes = [f for f in run(r) if f.rule.startswith(advisor.T1)]
    assert ids(causes) == [f"{advisor.T1}.forwarding", f"{advisor.T1}.isp",
                           f"{advisor.T1}.port_in_use"]
    assert "Least likely here" in causes[2].meaning


def test_table1_corporate_keeps_the_administrator_before_forwarding():
    r = t1(True, False)
    fs = run(r, laptop_settings(connection="corporate"))
    causes = [f for f in fs if f.rule.startswith(advisor.T1)]
    assert ids(causes)[0] == f"{advisor.T1}.isp"
    assert "network administrator" in text(causes[0])


def test_table1_other_ports_open_points_at_the_forwarding_rule():
    r = t1(True, False)
    del r["isp.cgnat"]
    r["router.port_open"].data["ports"].append(
        {"port": 40000, "reachable": True, "listener": True, "via": "echoip"})
    f = first_failure(run(r))
    assert f.rule == f"{advisor.T1}.forwarding"
    assert "40000" in f.meaning


# --------------------------------------------------------------------------- per-rule cases
# Each case: rule id -> (build results + settings that trigger it, checks on the finding).
Case = Callable[[], tuple[dict[str, CheckResult], Settings]]


def _no_link():
    r = healthy_laptop()
    put(r, "router.local_ip", "fail", local_ip="", gateway="", differs=False)
    put(r, "isp.internet", "fail", dns_ok=False, http_ok=None, failed_part="dns")
    put(r, "isp.public_ip", "fail", public_ip=None, sources={}, agree=False)
    put(r, "router.port_open", "fail", test_port_open=None,
        ports=[{"port": 12345, "reachable": None, "listener": True, "via": "echoip"}])
    return r, laptop_settings()


def _no_dns():
    r = healthy_laptop()
    put(r, "isp.internet", "fail", dns_ok=False, http_ok=None, failed_part="dns")
    return r, laptop_settings()


def _no_http():
    r = healthy_laptop()
    put(r, "isp.internet", "fail", dns_ok=True, http_ok=False, failed_part="http")
    return r, laptop_settings()


def _public_unknown():
    r = healthy_laptop()
    put(r, "isp.public_ip", "fail", public_ip=None,
        sources={"http://a/ip": "error: timed out"}, agree=False, matches_settings=None)
    return r, laptop_settings()


def _disagree():
    r = healthy_laptop()
    put(r, "isp.public_ip", "warn", sources={"http://a/ip": "198.51.100.2",
                                             "http://b/ip": "192.0.2.77"}, agree=False)
    return r, laptop_settings()


def _changed():
    r = healthy_laptop()
    put(r, "isp.public_ip", "warn", public_ip="198.51.100.9", previous_ip="198.51.100.2",
        changed=True, matches_settings=False)
    return r, laptop_settings()


def _differs():
    r = healthy_laptop()
    put(r, "isp.public_ip", "warn", public_ip="198.51.100.9", matches_settings=False,
        settings_ip="198.51.100.2", previous_ip="198.51.100.9", changed=False)
    return r, laptop_settings()


def _cgnat_alone():
    r = healthy_laptop()
    put(r, "isp.cgnat", "warn", cgnat=True, wan_ip="100.64.0.2", method="upnp")
    return r, laptop_settings()


def _local_differs():
    r = healthy_laptop()
    put(r, "router.local_ip", "warn", local_ip="192.168.1.23", differs=True)
    return r, laptop_settings()


def _port_in_use():
    r = healthy_laptop()
    put(r, "router.port_free", "warn", in_use=True, process="java", pid=300)
    return r, laptop_settings()


def _partial():
    r = healthy_laptop()
    r["router.port_open"].data["ports"][1]["reachable"] = False
    r["router.port_open"].status = Status.FAIL
    return r, laptop_settings()


def _no_verdict():
    r = healthy_laptop()
    put(r, "router.port_open", "fail", test_port_open=None,
        ports=[{"port": 12345, "reachable": None, "listener": True, "via": "echoip"}])
    return r, laptop_settings()


def _loopback():
    r = healthy_laptop()
    put(r, "linux.hosts", "fail", loopback=["sami"])
    r["linux.resolve"].data["names"]["sami"]["resolved"] = "127.0.1.1"
    put(r, "linux.resolve", "fail", loopback=["sami"])
    return r, laptop_settings()


def _wrong():
    r = healthy_laptop()
    put(r, "linux.hosts", "fail", wrong=[{"name": "turtlebot", "found": "203.0.113.99",
                                          "expected": "203.0.113.2"}])
    r["linux.resolve"].data["names"]["turtlebot"]["resolved"] = "203.0.113.99"
    put(r, "linux.resolve", "fail", wrong=["turtlebot"])
    return r, laptop_settings()


def _missing():
    r = healthy_laptop()
    put(r, "linux.hosts", "warn", missing=["turtlebot"])
    return r, laptop_settings()


def _dupes():
    r = healthy_laptop()
    put(r, "linux.hosts", "warn", duplicates=["turtlebot"])
    return r, laptop_settings()


def _icmp_filtered():
    r = healthy_laptop()
    put(r, "linux.ping", "pass", peers={"turtlebot": {"icmp": False, "tcp22": True}})
    return r, laptop_settings()


def _unreachable():
    r = healthy_laptop()
    put(r, "linux.ping", "fail", peers={"turtlebot": {"icmp": False, "tcp22": False}})
    put(r, "linux.ssh", "fail", peers={"turtlebot": {"ok": False, "failure": "network",
                                                     "fingerprint": None}})
    no_ssh(r, "network")
    return r, laptop_settings()


def _ssh_refused():
    r = healthy_laptop()
    put(r, "linux.ping", "pass", peers={"turtlebot": {"icmp": True, "tcp22": False,
                                                      "tcp": "refused", "port": 22}})
    put(r, "linux.ssh", "fail", peers={"turtlebot": {"ok": False, "failure": "network",
                                                     "fingerprint": None, "tcp": "refused",
                                                     "port": 22}})
    no_ssh(r, "network")
    return r, laptop_settings()


def _bashrc():
    r = healthy_laptop()
    put(r, "ros.env", "warn", bashrc_uri=None, uri_ok=True)
    return r, laptop_settings()


def no_ssh(r: dict[str, CheckResult], failure: str) -> None:
    """The chats, as the checks report them when SSH to the peer failed (or is not set up)."""
    f = "no_user" if failure == "no_user" else f"ssh:{failure}"
    for cid in ("linux.chat_out", "linux.chat_in"):
        put(r, cid, "skip" if failure == "no_user" else "fail",
            peers={"turtlebot": {"ok": False, "failure": f}})


def _ssh(failure: str, status: str = "fail"):
    def build():
        r = healthy_laptop()
        put(r, "linux.ssh", status, peers={"turtlebot": {"ok": False, "failure": failure,
                                                         "fingerprint": "SHA256:NEWKEY"}})
        no_ssh(r, failure)
        return r, laptop_settings()
    return build


def _chat(out_ok: bool, in_ok: bool):
    def build():
        r = healthy_laptop()
        put(r, "linux.chat_out", "pass" if out_ok else "fail",
            peers={"turtlebot": {"ok": out_ok, "failure": None if out_ok else "timeout"}})
        put(r, "linux.chat_in", "pass" if in_ok else "fail",
            peers={"turtlebot": {"ok": in_ok, "failure": None if in_ok else "timeout"}})
        return r, laptop_settings()
    return build


def _master_uri():
    r = healthy_laptop()
    put(r, "ros.env", "fail", env_uri="http://203.0.113.2:11311",
        bashrc_uri="http://203.0.113.2:11311", uri_ok=False)
    return r, laptop_settings()


def _ros_ip():
    r = healthy_laptop()
    put(r, "ros.env", "warn", ros_ip="192.168.1.10")
    return r, laptop_settings()


def _master_down():
    r = healthy_laptop()
    put(r, "ros.master", "fail", reachable=False, topics=[], nodes=[])
    return r, laptop_settings()


def _node_uri(host: str, settings=laptop_settings):
    def build():
        r = healthy_robot() if settings is robot_settings else healthy_laptop()
        uri = f"http://{host}:41234/"
        put(r, "ros.node_uris", "fail", unreachable=[
            {"node": "/talker", "uri": uri, "host": host, "reason": "timed out",
             "from": "here"}], checked=3)
        return r, settings()
    return build


def _pubsub(out_ok: bool, in_ok: bool, hop="xmlrpc_callback", uri=None, node=None):
    def build():
        r = healthy_laptop()
        if not out_ok:
            put(r, "ros.pubsub_out", "fail", ok=False, failed_hop=hop, uri=uri, node=node)
        if not in_ok:
            put(r, "ros.pubsub_in", "fail", ok=False, failed_hop=hop, uri=uri, node=node)
        return r, laptop_settings()
    return build


def _peer_cannot_register():
    r = healthy_robot()
    put(r, "ros.pubsub_out", "fail", ok=False, failed_hop="registration",
        uri="http://turtlebot:11311", node="/sub")
    put(r, "ros.pubsub_in", "fail", ok=False, failed_hop="registration",
        uri="http://turtlebot:11311", node="/pub")
    put(r, "ros.node_uris", "warn", unreachable=[], checked=2)
    return r, robot_settings()


def _exposed():
    return healthy_laptop(), laptop_settings()


def _timed_out():
    r = healthy_laptop()
    r["linux.ping"] = CheckResult("linux.ping", "linux", Status.FAIL,
                                  "no verdict within 3 s (timed out)", ["stopped"], 3.0, 3.0, {})
    return r, laptop_settings()


def _unexplained():
    r = healthy_laptop()
    r["linux.ping"] = CheckResult("linux.ping", "linux", Status.FAIL, "something odd", [], 0.1,
                                  3.0, {"peers": {}})
    return r, laptop_settings()


CASES: dict[str, Case] = {
    "router.local_ip.no_link": _no_link,
    "isp.no_internet.dns": _no_dns,
    "isp.no_internet.http": _no_http,
    "isp.public_ip.unknown": _public_unknown,
    "isp.public_ip.disagree": _disagree,
    "isp.public_ip.changed": _changed,
    "isp.public_ip.differs": _differs,
    "table1.open": lambda: (t1(True, True), laptop_settings()),
    "table1.no_listener": lambda: (t1(False, False), laptop_settings()),
    "table1.no_listener_open": lambda: (t1(False, True), laptop_settings()),
    f"{advisor.T1}.port_in_use": lambda: (t1(True, False), laptop_settings()),
    f"{advisor.T1}.isp": lambda: (t1(True, False), laptop_settings()),
    f"{advisor.T1}.forwarding": lambda: (t1(True, False), laptop_settings()),
    "isp.cgnat": _cgnat_alone,
    "router.local_ip.differs": _local_differs,
    "router.port_in_use": _port_in_use,
    "router.port_open.partial": _partial,
    "router.port_open.no_verdict": _no_verdict,
    "linux.name.loopback": _loopback,
    "linux.name.wrong": _wrong,
    "linux.hosts.missing": _missing,
    "linux.hosts.duplicates": _dupes,
    "linux.ping.icmp_filtered": _icmp_filtered,
    "linux.peer.unreachable": _unreachable,
    "linux.ssh.refused": _ssh_refused,
    "linux.ssh.host_key_changed": _ssh("host_key_changed"),
    "linux.ssh.host_key_unknown": _ssh("host_key_unknown", "warn"),
    "linux.ssh.auth": _ssh("auth"),
    "linux.ssh.sshd": _ssh("sshd"),
    "linux.ssh.resolve": _ssh("resolve"),
    "linux.ssh.no_user": _ssh("no_user", "warn"),
    "linux.chat.in_fails": _chat(True, False),
    "linux.chat.out_fails": _chat(False, True),
    "linux.chat.both_fail": _chat(False, False),
    "ros.env.master_uri": _master_uri,
    "ros.env.bashrc": _bashrc,
    "ros.env.ros_ip": _ros_ip,
    "ros.master.unreachable": _master_down,
    "ros.master.peer_cannot_register": _peer_cannot_register,
    "ros.node_uri.local_ip": _node_uri("192.168.1.10"),
    "ros.node_uri.loopback": _node_uri("127.0.1.1"),
    "ros.node_uri.unknown_host": _node_uri("ubuntu-laptop"),
    "ros.node_uri.unreachable": _node_uri("turtlebot"),
    "ros.pubsub.out_fails": _pubsub(False, True),
    "ros.pubsub.in_fails": _pubsub(True, False),
    "ros.pubsub.both_fail": _pubsub(False, False),
    "security.exposed": _exposed,
    "check.no_verdict": _timed_out,
    "check.unexplained": _unexplained,
}
CASES.update(ROS2_CASES)  # the ROS 2 rules' cases (tests/test_advisor_ros2.py)
CASES.update(UPNP_CASES)  # router.upnp's rules (tests/test_advisor_upnp.py)
CASES.update(ROSBRIDGE_CASES)  # ros.rosbridge's rules (tests/test_rosbridge.py)
CASES.update(FIREWALL_CASES)  # linux.firewall's rules (tests/test_firewall.py)


def test_every_rule_has_a_case():
    assert set(CASES) == {r.id for r in all_rules()}


def test_rule_ids_are_unique_and_well_formed():
    rules = all_rules()
    assert len({r.id for r in rules}) == len(rules)
    for r in rules:
        assert r.severity in advisor.SEVERITIES
        assert r.goto_step in (*advisor.STEP_ORDER, None)
        assert r.condition and r.meaning and r.action


@pytest.mark.parametrize("rule_id", sorted(CASES))
def test_rule_fires_on_its_case(rule_id):
    results, s = CASES[rule_id]()
    fs = run(results, s)
    assert rule_id in ids(fs), ids(fs)
    for f in fs:
        if f.rule == rule_id:
            assert f.meaning and f.actions
            assert all(isinstance(a, str) and a for a in f.actions)
            assert f.check_ids


# table1.open and security.exposed describe a working forwarding: they belong on a healthy network.
@pytest.mark.parametrize("rule_id", sorted(set(CASES) - {"table1.open", "security.exposed"}))
def test_rule_is_silent_on_the_healthy_network(rule_id):
    assert rule_id not in ids(run(healthy_laptop()))
    assert rule_id not in ids(run(healthy_robot(), robot_settings()))


def test_rule_ignores_skipped_checks():
    """A skipped check says nothing: none of its data may fire a rule."""
    for rule_id, build in CASES.items():
        results, s = build()
        for r in results.values():
            r.status = Status.SKIP
        assert run(results, s) == [], rule_id


# --------------------------------------------------------------------------- rule details
def test_no_internet_dns_vs_http():
    fs = run(_no_dns()[0])
    assert "isp.no_internet.http" not in ids(fs)
    f = only(fs, "isp.no_internet.dns")
    assert "probe.lab.test" in text(f) and "resolv" in text(f)
    assert first_failure(fs) is f
    fs = run(_no_http()[0])
    assert "isp.no_internet.dns" not in ids(fs)
    assert "captive portal" in text(only(fs, "isp.no_internet.http"))


def test_public_ip_unknown_is_superseded_by_no_internet():
    r, s = _public_unknown()
    put(r, "isp.internet", "fail", dns_ok=False, failed_part="dns")
    fs = run(r, s)
    assert "isp.public_ip.unknown" not in ids(fs)


def test_public_ip_disagree_names_both_addresses_and_ignores_errors():
    f = only(run(_disagree()[0]), "isp.public_ip.disagree")
    assert "198.51.100.2" in f.meaning and "192.0.2.77" in f.meaning
    r = healthy_laptop()
    put(r, "isp.public_ip", "warn", sources={"http://a/ip": "198.51.100.2",
                                             "http://b/ip": "error: timed out"}, agree=False)
    assert "isp.public_ip.disagree" not in ids(run(r))


def test_public_ip_changed_points_to_sync_and_peers_hosts():
    fs = run(_changed()[0])
    f = only(fs, "isp.public_ip.changed")
    t = text(f)
    assert "rosnet-tui sync" in t
    assert "`198.51.100.9 sami`" in t and "on turtlebot" in t
    assert 'public_ip = "198.51.100.9"' in t
    assert "isp.public_ip.differs" not in ids(fs)      # superseded


def test_public_ip_differs_from_settings():
    f = only(run(_differs()[0]), "isp.public_ip.differs")
    assert "198.51.100.9" in f.meaning and "198.51.100.2" in f.meaning
    assert 'public_ip = "198.51.100.9"' in text(f)


def test_local_ip_differs_alone():
    f = only(run(_local_differs()[0]), "router.local_ip.differs")
    assert "192.168.1.23" in text(f) and "DHCP" in text(f)


def test_port_partial_says_which_ports_and_ssh_separately():
    r, s = _partial()
    r["router.port_open"].data["ports"][2]["reachable"] = False   # 22
    f = only(run(r, s), "router.port_open.partial")
    assert "23456" in f.meaning and "22" in f.meaning
    assert any("TCP 22" in a for a in f.actions)
    assert any("1024-65000" in a for a in f.actions)


def test_exposure_is_security_and_names_ssh_and_the_master():
    fs = run(healthy_robot(), robot_settings())
    f = only(fs, "security.exposed")
    assert f.severity == "security"
    assert "SSH (22)" in f.meaning and "ROS 1 has no authentication" in f.meaning
    assert any("PasswordAuthentication no" in a for a in f.actions)
    assert any("sami 198.51.100.2" in a for a in f.actions)
    # not shown when nothing is reachable from outside
    r = t1(True, False)
    assert "security.exposed" not in ids(run(r))


def test_name_wrong_names_the_hosts_line():
    f = only(run(_wrong()[0]), "linux.name.wrong")
    assert "`203.0.113.99 turtlebot`" in text(f) and "`203.0.113.2 turtlebot`" in text(f)
    assert set(f.check_ids) == {"linux.hosts", "linux.resolve"}
    # resolver wrong while the hosts file is right: look elsewhere
    r = healthy_laptop()
    r["linux.resolve"].data["names"]["turtlebot"]["resolved"] = "192.0.2.200"
    put(r, "linux.resolve", "fail", wrong=["turtlebot"])
    f = only(run(r), "linux.name.wrong")
    assert "nsswitch" in text(f) and f.check_ids == ["linux.resolve"]


def test_name_loopback_names_the_127_line():
    fs = run(_loopback()[0])
    f = only(fs, "linux.name.loopback")
    assert "127.0.1.1" in text(f) and "`192.168.1.10 sami`" in text(f)
    assert "linux.name.wrong" not in ids(fs)


def test_ping_filtered_is_info_not_failure():
    f = only(run(_icmp_filtered()[0]), "linux.ping.icmp_filtered")
    assert f.severity == "info" and "Not a problem" in f.meaning


def test_peer_unreachable_collects_the_failing_checks():
    fs = run(_unreachable()[0])
    f = only(fs, "linux.peer.unreachable")
    assert set(f.check_ids) == {"linux.ping", "linux.ssh", "linux.chat_out", "linux.chat_in"}
    assert "10.10.10.1" in text(f)   # the peer's local IP, for its forwarding
    assert "linux.chat.both_fail" not in ids(fs)


def test_ssh_host_key_changed_says_verify_then_keygen_r():
    f = only(run(_ssh("host_key_changed")()[0]), "linux.ssh.host_key_changed")
    t = text(f)
    assert "SHA256:NEWKEY" in t and "ssh-keygen -R turtlebot" in t
    assert "intercepting" in f.meaning and "out of band" in t
    assert t.index("Verify") < t.index("ssh-keygen -R")


def test_ssh_failures_are_told_apart():
    for failure, rule_id, needle in (("auth", "linux.ssh.auth", "ssh-copy-id root@turtlebot"),
                                     ("sshd", "linux.ssh.sshd", "systemctl enable --now ssh"),
                                     ("network", "linux.peer.unreachable", "forwards TCP 22")):
        fs = run(_ssh(failure)()[0])
        assert needle in text(only(fs, rule_id)), failure
        others = {"linux.ssh.auth", "linux.ssh.sshd", "linux.peer.unreachable"} - {rule_id}
        assert not others & set(ids(fs)), failure


def test_chat_one_way_blames_the_right_side():
    f = only(run(_chat(True, False)()[0]), "linux.chat.in_fails")
    assert "sami's modem" in text(f) and "192.168.1.10" in text(f)     # ours
    f = only(run(_chat(False, True)()[0]), "linux.chat.out_fails")
    assert "turtlebot's modem" in text(f) and "10.10.10.1" in text(f)  # the peer's


def test_master_uri_wrong_for_member_and_master():
    f = only(run(_master_uri()[0]), "ros.env.master_uri")
    assert "http://203.0.113.2:11311" in f.meaning and "member" in f.meaning
    assert "export ROS_MASTER_URI=http://turtlebot:11311" in text(f)
    r = healthy_robot()
    put(r, "ros.env", "fail", env_uri="http://203.0.113.2:11311", bashrc_uri=None,
        expected_uri="http://turtlebot:11311", uri_ok=False)
    f = only(run(r, robot_settings()), "ros.env.master_uri")
    assert "is the master" in f.meaning and "public IP" in f.meaning
    # ~/.bashrc right but the shell stale
    r = healthy_laptop()
    put(r, "ros.env", "warn", env_uri="http://sami:11311", uri_ok=False)
    f = only(run(r), "ros.env.master_uri")
    assert "opened before the change" in f.meaning


def test_ros_ip_warns_on_remote_and_becomes_the_cause_when_ros_fails():
    f = only(run(_ros_ip()[0]), "ros.env.ros_ip")
    assert f.severity == "warn"
    assert "Unset ROS_IP on sami" in f.actions[0] and "`unset ROS_IP`" in f.actions[0]
    assert "~/.bashrc on sami" in f.actions[0]
    r, s = _ros_ip()
    put(r, "ros.pubsub_out", "fail", ok=False, failed_hop="xmlrpc_callback",
        uri="http://192.168.1.10:40001/", node="/probe")
    fs = run(r, s)
    f = first_failure(fs)
    assert f.rule == "ros.env.ros_ip" and f.severity == "fail"
    assert "ros.pubsub_out" in f.check_ids
    # on a LAN profile it is fine (info only)
    r, _ = _ros_ip()
    f = only(run(r, laptop_settings(profile="office")), "ros.env.ros_ip")
    assert f.severity == "info"
    # ROS_HOSTNAME set to the component's own network name is harmless
    r = healthy_laptop()
    put(r, "ros.env", "warn", ros_hostname="sami")
    assert only(run(r), "ros.env.ros_ip").severity == "info"


def test_master_unreachable_member_and_master():
    f = only(run(_master_down()[0]), "ros.master.unreachable")
    t = text(f)
    assert "roscore" in t and "turtlebot's modem" in t and "10.10.10.1" in t
    assert "getent hosts turtlebot" in t and "203.0.113.2" in t
    r = healthy_robot()
    put(r, "ros.master", "fail", reachable=False)
    f = only(run(r, robot_settings()), "ros.master.unreachable")
    assert "`roscore`" in text(f) and "on turtlebot" in text(f)


def test_node_uri_local_ip_names_the_component_to_fix():
    fs = run(*_node_uri("192.168.1.10")())
    f = first_failure(fs)
    assert f.rule == "ros.node_uri.local_ip"
    assert "/talker on sami" in f.meaning
    assert f.actions[0].startswith("Unset ROS_IP on sami")
    # from the robot's seat the laptop's local address maps to sami too
    fs = run(*_node_uri("192.168.1.10", robot_settings)())
    f = only(fs, "ros.node_uri.local_ip")
    assert "Unset ROS_IP on sami" in f.actions[0]
    # on a LAN profile a local address is the right one: not this rule
    r, _ = _node_uri("192.168.1.10")()
    assert "ros.node_uri.local_ip" not in ids(run(r, laptop_settings(profile="office")))


def test_node_uri_unreachable_names_the_component_and_its_forwarding():
    f = only(run(*_node_uri("turtlebot")()), "ros.node_uri.unreachable")
    assert "turtlebot's modem" in text(f) and "10.10.10.1" in text(f)
    assert "41234" in text(f)
    f = only(run(*_node_uri("203.0.113.2")()), "ros.node_uri.unreachable")
    assert "turtlebot" in f.meaning


def test_node_uri_unknown_host_and_loopback():
    f = only(run(*_node_uri("ubuntu-laptop")()), "ros.node_uri.unknown_host")
    assert "hostnamectl set-hostname" in text(f)
    f = only(run(*_node_uri("192.0.2.99")()), "ros.node_uri.unknown_host")
    assert "unset ROS_IP" in text(f)
    f = only(run(*_node_uri("127.0.1.1")()), "ros.node_uri.loopback")
    assert "127.0.1.1" in text(f)


def test_pubsub_one_way_uses_the_failed_hop_and_uri():
    fs = run(*_pubsub(False, True, uri="http://192.168.1.10:40001/", node="/probe")())
    f = only(fs, "ros.pubsub.out_fails")
    assert "Unset ROS_IP on sami" in text(f)
    assert "ros.node_uri.local_ip" in ids(fs)      # the same evidence, by component
    f = only(run(*_pubsub(True, False, hop="tcpros", uri="http://turtlebot:40002/")()),
             "ros.pubsub.in_fails")
    assert "turtlebot's modem" in text(f)
    f = only(run(*_pubsub(True, False, hop="registration")()), "ros.pubsub.in_fails")
    assert "ROS_MASTER_URI" in text(f)


def test_pubsub_both_fail_is_superseded_by_a_dead_master():
    r, s = _pubsub(False, False, hop="registration")()
    put(r, "ros.master", "fail", reachable=False)
    fs = run(r, s)
    assert "ros.pubsub.both_fail" not in ids(fs)
    assert "ros.master.unreachable" in ids(fs)


def test_catch_alls():
    f = only(run(_timed_out()[0]), "check.no_verdict")
    assert "timeout_s" in text(f) and f.check_ids == ["linux.ping"] and f.goto_step == "linux"
    f = only(run(_unexplained()[0]), "check.unexplained")
    assert "something odd" in f.meaning


# --------------------------------------------------------------------------- ordering
def test_order_failures_by_step_then_warnings_security_info():
    r = t1(True, False)
    put(r, "isp.internet", "fail", dns_ok=True, http_ok=False, failed_part="http")
    put(r, "linux.hosts", "fail", wrong=[{"name": "turtlebot", "found": "203.0.113.99",
                                          "expected": "203.0.113.2"}])
    put(r, "ros.env", "warn", ros_ip="192.168.1.10")
    put(r, "linux.ping", "pass", peers={"turtlebot": {"icmp": False, "tcp22": True}})
    r["router.port_open"].data["ports"].append(
        {"port": 22, "reachable": True, "listener": True, "via": "echoip"})
    fs = run(r)
    sev = [f.severity for f in fs]
    assert sev == sorted(sev, key=advisor.SEVERITIES.index)
    fails = [f for f in fs if f.severity == "fail"]
    steps = [{"isp.": 0, "table": 1, "linux": 2, "ros.e": 3}[
        next(k for k in ("isp.", "table", "linux", "ros.e") if f.rule.startswith(k))]
        for f in fails]
    assert steps == sorted(steps)
    assert fails[0].rule == "isp.no_internet.http"
    assert ids(fs)[-1] == "linux.ping.icmp_filtered"


def test_advice_by_check_and_to_json_contract():
    fs = run(*_chat(True, False)())
    by = advice_by_check(fs)
    assert [f.rule for f in by["linux.chat_in"]] == ["linux.chat.in_fails"]
    j = fs[0].to_json()
    assert set(j) == {"rule", "meaning", "actions", "goto_step"}
    assert set(fs[0].to_dict()) >= {"rule", "severity", "check_ids", "condition", "evidence"}


def test_advise_accepts_a_list_and_survives_malformed_data():
    r = healthy_laptop()
    assert ids(advise(list(r.values()), laptop_settings())) == ids(run(r))
    bad = copy.deepcopy(r)
    for x in bad.values():
        x.status = Status.FAIL
        x.data = {k: 7 for k in x.data}           # every key the wrong type
    fs = advise(bad, laptop_settings())           # not strict: never raises
    assert {f.rule for f in fs} >= {"check.unexplained"}
    with pytest.raises((TypeError, AttributeError, ValueError, KeyError)):
        advise(bad, laptop_settings(), strict=True)


def test_empty_settings_still_give_readable_text():
    r, _ = _unreachable()
    fs = advise(r, Settings(), strict=True)
    assert fs and all("None" not in text(f) for f in fs)


# --------------------------------------------------------------------------- docs
def test_docs_match_the_rules():
    doc = ROOT / "docs" / "TROUBLESHOOTING.md"
    assert doc.read_text(encoding="utf-8") == advisor.render_rules_markdown(), (
        "docs/TROUBLESHOOTING.md is stale: run "
        "`python -m rosnet_tui.core.advisor --markdown > docs/TROUBLESHOOTING.md`")


def test_docs_list_every_rule_and_table1_rows():
    md = advisor.render_rules_markdown()
    for r in all_rules():
        assert f"`{r.id}`" in md
    assert "| up | Open | `table1.open`" in md
    assert "| down | Closed | `table1.no_listener`" in md
    assert md.count("| up | Closed |") == 3


def test_docs_script_prints_the_markdown():
    out = subprocess.run([sys.executable, "-m", "rosnet_tui.core.advisor", "--markdown"],
                         capture_output=True, text=True, cwd=ROOT, timeout=60, check=True)
    assert out.stdout == advisor.render_rules_markdown()


def test_chat_failure_kinds_get_their_own_fix():
    r, s = _chat(True, False)()
    r["linux.chat_in"].data["peers"]["turtlebot"]["failure"] = "peer_resolve"
    f = only(run(r, s), "linux.chat.in_fails")
    assert "On turtlebot: add `198.51.100.2 sami` to /etc/hosts" in text(f)
    r, s = _chat(False, True)()
    r["linux.chat_out"].data["peers"]["turtlebot"]["failure"] = "wrong_peer"
    f = only(run(r, s), "linux.chat.out_fails")
    assert "another machine answers" in f.meaning and "10.10.10.1" in text(f)


def test_chats_that_failed_for_lack_of_ssh_belong_to_the_ssh_finding():
    r, s = _ssh("auth")()
    put(r, "linux.chat_out", "fail", peers={"turtlebot": {"ok": False, "failure": "ssh:auth"}})
    put(r, "linux.chat_in", "fail", peers={"turtlebot": {"ok": False, "failure": "ssh:auth"}})
    fs = run(r, s)
    assert [f.rule for f in fs if f.severity == "fail"] == ["linux.ssh.auth"]
    assert only(fs, "linux.ssh.auth").check_ids == ["linux.ssh", "linux.chat_out",
                                                    "linux.chat_in"]
    # a peer without an SSH user is not a chat failure either
    r = healthy_laptop()
    put(r, "linux.chat_out", "skip", peers={"turtlebot": {"ok": False, "failure": "no_user"}})
    put(r, "linux.chat_in", "pass", peers={"turtlebot": {"ok": False, "failure": "no_user"}})
    assert not [f for f in run(r) if f.rule.startswith("linux.chat")]


def test_peer_unreachable_tells_ping_answering_modem_from_silence():
    r = healthy_laptop()
    put(r, "linux.ping", "pass", peers={"turtlebot": {"icmp": True, "tcp22": False}})
    put(r, "linux.ssh", "fail", peers={"turtlebot": {"ok": False, "failure": "network",
                                                     "fingerprint": None}})
    no_ssh(r, "network")
    f = only(run(r), "linux.peer.unreachable")
    assert "answers ping" in f.meaning and "modem is online" in f.meaning
    assert f.actions[0].startswith("Check that turtlebot's modem forwards TCP 22")
    # silence at a stale address: the hosts line first
    r, s = _wrong()
    put(r, "linux.ping", "fail", peers={"turtlebot": {"icmp": False, "tcp22": False}})
    put(r, "linux.ssh", "fail", peers={"turtlebot": {"ok": False, "failure": "network",
                                                     "fingerprint": None}})
    no_ssh(r, "network")
    fs = run(r, s)
    f = only(fs, "linux.peer.unreachable")
    assert "Nothing answers at 203.0.113.99" in f.meaning
    assert "settings say turtlebot is at 203.0.113.2" in f.meaning
    assert f.actions[0].startswith("Check our hosts line")
    assert ids(fs).index("linux.name.wrong") < ids(fs).index("linux.peer.unreachable")
    # a peer we chatted with is reachable, whatever port 22 says
    r = healthy_laptop()
    put(r, "linux.ping", "pass", peers={"turtlebot": {"icmp": True, "tcp22": False}})
    assert "linux.peer.unreachable" not in ids(run(r))


def test_dead_master_explains_the_ros_checks_that_follow_from_it():
    r, s = _master_down()
    put(r, "ros.node_uris", "fail", unreachable=[], checked=0)
    put(r, "ros.pubsub_out", "fail", ok=False, failed_hop="registration",
        uri="http://turtlebot:11311")
    fs = run(r, s)
    assert [f.rule for f in fs if f.severity == "fail"] == ["ros.master.unreachable"]
    assert only(fs, "ros.master.unreachable").check_ids == ["ros.master", "ros.node_uris",
                                                            "ros.pubsub_out"]


def test_master_seat_peer_cannot_register():
    fs = run(*_peer_cannot_register())
    f = first_failure(fs)
    assert f.rule == "ros.master.peer_cannot_register"
    assert "sami's nodes cannot register" in f.meaning
    assert "10.10.10.1" in text(f) and "getent hosts turtlebot" in text(f)
    assert set(f.check_ids) == {"ros.pubsub_out", "ros.pubsub_in", "ros.node_uris"}
    assert not {"ros.pubsub.both_fail", "check.unexplained"} & set(ids(fs))


def test_link_down_comes_first_and_explains_the_offline_checks():
    fs = run(*_no_link())
    f = first_failure(fs)
    assert f.rule == "router.local_ip.no_link"
    assert "no IPv4 address on eth0" in f.meaning and "ip addr show eth0" in text(f)
    assert set(f.check_ids) == {"router.local_ip", "isp.internet", "isp.public_ip",
                                "router.port_open"}
    assert [x.rule for x in fs if x.severity == "fail"] == ["router.local_ip.no_link"]
    r, s = _no_link()
    put(r, "router.local_ip", "fail", local_ip="192.168.1.10", gateway="")
    assert "no default route" in only(run(r, s), "router.local_ip.no_link").meaning


def test_peer_unreachable_on_a_lan_profile_does_not_talk_about_modems():
    r, _ = _unreachable()
    s = laptop_settings(profile="office")
    f = only(run(r, s), "linux.peer.unreachable")
    assert "office LAN" in f.meaning and "modem" not in text(f)
    assert "must print 10.10.10.1" in text(f)
