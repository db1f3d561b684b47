"""What the advisor tests share: how they run the advisor and read its findings, and one case
per rule (results and settings that trigger it), in a table per step.

The builders of settings and results are in tests/builders.py.
"""

from __future__ import annotations

import json
from collections.abc import Callable

from rosnet_tui.core import advisor
from rosnet_tui.core.advisor import Finding, advise
from rosnet_tui.core.config.settings_model import Settings
from rosnet_tui.core.results import CheckResult, Status
from tests.builders import (
    healthy_laptop,
    healthy_robot,
    laptop_settings,
    no_ssh,
    put,
    robot_settings,
    t1,
)


# --------------------------------------------------------------------------- the report's JSON
def lab_report(lab, host: str, cfg, env: dict, *args: str, timeout: float = 150) -> dict:
    """`rosnet-tui report --format json` run on the lab's *host*, read (the lab tests)."""
    r = lab.rosnet(host, "report", "--format", "json", "--config", str(cfg), *args, env=env,
                   timeout=timeout)
    assert r.stdout.strip(), r.stderr
    return json.loads(r.stdout)


def first_failure_in(doc: dict) -> dict:
    """The report's first finding of severity fail (there must be one)."""
    fails = [f for f in doc["findings"] if f["severity"] == "fail"]
    assert fails, explain_report(doc)
    return fails[0]


def explain_report(doc: dict) -> str:
    """The report's checks and findings, a line each (an assertion's message)."""
    lines = [f"{c['status']:4} {c['id']}: {c['summary']}" for c in doc["checks"]]
    lines += [f"[{f['severity']}] {f['rule']} -> {f['goto_step']}: {f['meaning']}"
              for f in doc["findings"]]
    return "\n".join(lines)


# --------------------------------------------------------------------------- running the advisor
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


# --------------------------------------------------------------------------- per-rule cases
# Each case: rule id -> (build results + settings that trigger it, checks on the finding).
Case = Callable[[], tuple[dict[str, CheckResult], Settings]]


# --------------------------------------------------------------------------- ISP

def no_dns():
    r = healthy_laptop()
    put(r, "isp.internet", "fail", dns_ok=False, http_ok=None, failed_part="dns")
    return r, laptop_settings()


def no_http():
    r = healthy_laptop()
    put(r, "isp.internet", "fail", dns_ok=True, http_ok=False, failed_part="http")
    return r, laptop_settings()


def public_unknown():
    r = healthy_laptop()
    put(r, "isp.public_ip", "fail", public_ip=None,
        sources={"http://a/ip": "error: timed out"}, agree=False, matches_settings=None)
    return r, laptop_settings()


def disagree():
    r = healthy_laptop()
    put(r, "isp.public_ip", "warn", sources={"http://a/ip": "198.51.100.2",
                                             "http://b/ip": "192.0.2.77"}, agree=False)
    return r, laptop_settings()


def changed():
    r = healthy_laptop()
    put(r, "isp.public_ip", "warn", public_ip="198.51.100.9", previous_ip="198.51.100.2",
        changed=True, matches_settings=False)
    return r, laptop_settings()


def differs():
    r = healthy_laptop()
    put(r, "isp.public_ip", "warn", public_ip="198.51.100.9", matches_settings=False,
        settings_ip="198.51.100.2", previous_ip="198.51.100.9", changed=False)
    return r, laptop_settings()


def cgnat_alone():
    r = healthy_laptop()
    put(r, "isp.cgnat", "warn", cgnat=True, wan_ip="100.64.0.2", method="upnp")
    return r, laptop_settings()


ISP_CASES: dict[str, Case] = {
    "isp.no_internet.dns": no_dns,
    "isp.no_internet.http": no_http,
    "isp.public_ip.unknown": public_unknown,
    "isp.public_ip.disagree": disagree,
    "isp.public_ip.changed": changed,
    "isp.public_ip.differs": differs,
    "isp.cgnat": cgnat_alone,
}


# --------------------------------------------------------------------------- Router

def no_link():
    r = healthy_laptop()
    put(r, "router.local_ip", "fail", local_ip="", gateway="", differs=False)
    put(r, "isp.internet", "fail", dns_ok=False, http_ok=None, failed_part="dns")
    put(r, "isp.public_ip", "fail", public_ip=None, sources={}, agree=False)
    put(r, "router.port_open", "fail", test_port_open=None,
        ports=[{"port": 12345, "reachable": None, "listener": True, "via": "echoip"}])
    return r, laptop_settings()


def local_differs():
    r = healthy_laptop()
    put(r, "router.local_ip", "warn", local_ip="192.168.1.23", differs=True)
    return r, laptop_settings()


def port_in_use():
    r = healthy_laptop()
    put(r, "router.port_free", "warn", in_use=True, process="java", pid=300)
    return r, laptop_settings()


def partial():
    r = healthy_laptop()
    r["router.port_open"].data["ports"][1]["reachable"] = False
    r["router.port_open"].status = Status.FAIL
    return r, laptop_settings()


def no_verdict():
    r = healthy_laptop()
    put(r, "router.port_open", "fail", test_port_open=None,
        ports=[{"port": 12345, "reachable": None, "listener": True, "via": "echoip"}])
    return r, laptop_settings()


ROUTER_CASES: dict[str, Case] = {
    "router.local_ip.no_link": no_link,
    "table1.open": lambda: (t1(True, True), laptop_settings()),
    "table1.no_listener": lambda: (t1(False, False), laptop_settings()),
    "table1.no_listener_open": lambda: (t1(False, True), laptop_settings()),
    f"{advisor.T1}.port_in_use": lambda: (t1(True, False), laptop_settings()),
    f"{advisor.T1}.isp": lambda: (t1(True, False), laptop_settings()),
    f"{advisor.T1}.forwarding": lambda: (t1(True, False), laptop_settings()),
    "router.local_ip.differs": local_differs,
    "router.port_in_use": port_in_use,
    "router.port_open.partial": partial,
    "router.port_open.no_verdict": no_verdict,
}


# --------------------------------------------------------------------------- Linux

def loopback():
    r = healthy_laptop()
    put(r, "linux.hosts", "fail", loopback=["sami"])
    r["linux.resolve"].data["names"]["sami"]["resolved"] = "127.0.1.1"
    put(r, "linux.resolve", "fail", loopback=["sami"])
    return r, laptop_settings()


def wrong():
    r = healthy_laptop()
    put(r, "linux.hosts", "fail", wrong=[{"name": "turtlebot", "found": "203.0.113.99",
                                          "expected": "203.0.113.2"}])
    r["linux.resolve"].data["names"]["turtlebot"]["resolved"] = "203.0.113.99"
    put(r, "linux.resolve", "fail", wrong=["turtlebot"])
    return r, laptop_settings()


def missing():
    r = healthy_laptop()
    put(r, "linux.hosts", "warn", missing=["turtlebot"])
    return r, laptop_settings()


def fresh_names(r: dict[str, CheckResult] | None = None) -> dict[str, CheckResult]:
    """sami's round on a fresh install: /etc/hosts has no line for either name and no DNS knows
    them, so everything that connects to turtlebot by name fails there (the data as the checks
    give it: linux.ping's tcp "resolve", linux.ssh's failure "resolve", the chats "ssh:resolve")."""
    r = r or healthy_laptop()
    put(r, "linux.hosts", "fail", missing=["sami", "turtlebot"])
    for n in ("sami", "turtlebot"):
        r["linux.resolve"].data["names"][n]["resolved"] = None
    put(r, "linux.resolve", "fail", wrong=["sami", "turtlebot"])
    put(r, "linux.ping", "fail", peers={"turtlebot": {"icmp": None, "tcp22": False,
                                                     "tcp": "resolve", "port": 22}})
    put(r, "linux.ssh", "fail", peers={"turtlebot": {
        "ok": False, "failure": "resolve", "fingerprint": None, "address": None, "port": 22}})
    no_ssh(r, "resolve")
    return r


def unresolved():
    return fresh_names(), laptop_settings()


def dupes():
    r = healthy_laptop()
    put(r, "linux.hosts", "warn", duplicates=["turtlebot"])
    return r, laptop_settings()


def icmp_filtered():
    r = healthy_laptop()
    put(r, "linux.ping", "pass", peers={"turtlebot": {"icmp": False, "tcp22": True}})
    return r, laptop_settings()


def ssh_shut_out(r: dict[str, CheckResult], tcp: str | None, *, icmp: bool = True,
                 address: str | None = None) -> dict[str, CheckResult]:
    """sami's round *r* where turtlebot's port 22 answers *tcp* ("refused", "timeout",
    "unreachable"; None: data without the TCP answer) and ping answers *icmp*: SSH fails on the
    network, and so do the checks that run over it (linux.ssh's data with the *address* it
    dialled, when given)."""
    how = {} if tcp is None else {"tcp": tcp, "port": 22}
    put(r, "linux.ping", "pass" if icmp else "fail",
        peers={"turtlebot": {"icmp": icmp, "tcp22": False, **how}})
    peer = {"ok": False, "failure": "network", "fingerprint": None, **how}
    if address is not None:
        peer["address"] = address
    put(r, "linux.ssh", "fail", peers={"turtlebot": peer})
    no_ssh(r, "network")
    return r


def unreachable():
    return ssh_shut_out(healthy_laptop(), None, icmp=False), laptop_settings()


def ssh_refused():
    return ssh_shut_out(healthy_laptop(), "refused"), laptop_settings()


def ssh(failure: str, status: str = "fail"):
    def build():
        r = healthy_laptop()
        put(r, "linux.ssh", status, peers={"turtlebot": {"ok": False, "failure": failure,
                                                         "fingerprint": "SHA256:NEWKEY"}})
        no_ssh(r, failure)
        return r, laptop_settings()
    return build


def chat(out_ok: bool, in_ok: bool):
    def build():
        r = healthy_laptop()
        put(r, "linux.chat_out", "pass" if out_ok else "fail",
            peers={"turtlebot": {"ok": out_ok, "failure": None if out_ok else "timeout"}})
        put(r, "linux.chat_in", "pass" if in_ok else "fail",
            peers={"turtlebot": {"ok": in_ok, "failure": None if in_ok else "timeout"}})
        return r, laptop_settings()
    return build


LINUX_CASES: dict[str, Case] = {
    "linux.ssh.host_key_changed": ssh("host_key_changed"),
    "linux.name.loopback": loopback,
    "linux.name.unresolved": unresolved,
    "linux.name.wrong": wrong,
    "linux.hosts.missing": missing,
    "linux.hosts.duplicates": dupes,
    "linux.ping.icmp_filtered": icmp_filtered,
    "linux.peer.unreachable": unreachable,
    "linux.ssh.refused": ssh_refused,
    "linux.ssh.host_key_unknown": ssh("host_key_unknown", "warn"),
    "linux.ssh.auth": ssh("auth"),
    "linux.ssh.sshd": ssh("sshd"),
    "linux.ssh.resolve": ssh("resolve"),
    "linux.ssh.no_user": ssh("no_user", "warn"),
    "linux.chat.in_fails": chat(True, False),
    "linux.chat.out_fails": chat(False, True),
    "linux.chat.both_fail": chat(False, False),
}


# --------------------------------------------------------------------------- ROS

def bashrc():
    r = healthy_laptop()
    put(r, "ros.env", "warn", bashrc_uri=None, uri_ok=True)
    return r, laptop_settings()


def master_uri_unset():
    r = healthy_laptop()
    put(r, "ros.env", "fail", env_uri=None, bashrc_uri=None, uri_ok=False)
    return r, laptop_settings()


def master_uri():
    r = healthy_laptop()
    put(r, "ros.env", "fail", env_uri="http://203.0.113.2:11311",
        bashrc_uri="http://203.0.113.2:11311", uri_ok=False)
    return r, laptop_settings()


def ros_ip():
    r = healthy_laptop()
    put(r, "ros.env", "warn", ros_ip="192.168.1.10")
    return r, laptop_settings()


def master_down():
    r = healthy_laptop()
    put(r, "ros.master", "fail", reachable=False, topics=[], nodes=[])
    return r, laptop_settings()


def node_uri(host: str, settings=laptop_settings):
    def build():
        r = healthy_robot() if settings is robot_settings else healthy_laptop()
        uri = f"http://{host}:41234/"
        put(r, "ros.node_uris", "fail", unreachable=[
            {"node": "/talker", "uri": uri, "host": host, "reason": "timed out",
             "from": "here"}], checked=3)
        return r, settings()
    return build


def pubsub(out_ok: bool, in_ok: bool, hop="xmlrpc_callback", uri=None, node=None):
    def build():
        r = healthy_laptop()
        if not out_ok:
            put(r, "ros.pubsub_out", "fail", ok=False, failed_hop=hop, uri=uri, node=node)
        if not in_ok:
            put(r, "ros.pubsub_in", "fail", ok=False, failed_hop=hop, uri=uri, node=node)
        return r, laptop_settings()
    return build


def peer_cannot_register():
    r = healthy_robot()
    put(r, "ros.pubsub_out", "fail", ok=False, failed_hop="registration",
        uri="http://turtlebot:11311", node="/sub")
    put(r, "ros.pubsub_in", "fail", ok=False, failed_hop="registration",
        uri="http://turtlebot:11311", node="/pub")
    put(r, "ros.node_uris", "warn", unreachable=[], checked=2)
    return r, robot_settings()


ROS_CASES: dict[str, Case] = {
    "ros.env.master_uri_unset": master_uri_unset,
    "ros.env.master_uri": master_uri,
    "ros.env.bashrc": bashrc,
    "ros.env.ros_ip": ros_ip,
    "ros.master.unreachable": master_down,
    "ros.master.peer_cannot_register": peer_cannot_register,
    "ros.node_uri.local_ip": node_uri("192.168.1.10"),
    "ros.node_uri.loopback": node_uri("127.0.1.1"),
    "ros.node_uri.unknown_host": node_uri("ubuntu-laptop"),
    "ros.node_uri.unreachable": node_uri("turtlebot"),
    "ros.pubsub.out_fails": pubsub(False, True),
    "ros.pubsub.in_fails": pubsub(True, False),
    "ros.pubsub.both_fail": pubsub(False, False),
}


# --------------------------------------------------------------------------- every step (security, checks without a verdict)

def exposed():
    return healthy_laptop(), laptop_settings()


def timed_out():
    r = healthy_laptop()
    r["linux.ping"] = CheckResult("linux.ping", "linux", Status.FAIL,
                                  "no verdict within 3 s (timed out)", ["stopped"], 3.0, 3.0, {})
    return r, laptop_settings()


def unexplained():
    r = healthy_laptop()
    r["linux.ping"] = CheckResult("linux.ping", "linux", Status.FAIL, "something odd", [], 0.1,
                                  3.0, {"peers": {}})
    return r, laptop_settings()


GENERAL_CASES: dict[str, Case] = {
    "security.exposed": exposed,
    "check.no_verdict": timed_out,
    "check.unexplained": unexplained,
}
