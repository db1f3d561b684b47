"""ISP, Router/modem and Linux checks on the network lab, through the real CLI, from both sides.

Healthy: every check passes from the laptop and from the robot. Each broken variant fails the
right check with the right evidence, and an unplugged laptop still gets every verdict within its
timeout.
"""

from __future__ import annotations

import json
import time

import pytest

from tests.lab.firewall import secured

pytestmark = pytest.mark.lab

STEPS = ("--step", "isp", "--step", "router", "--step", "linux")


def check(lab, host: str, state, *extra: str, steps=STEPS, timeout: float = 90
          ) -> tuple[int, dict[str, dict]]:
    """`rosnet-tui check --json` on *host* for the three steps: (exit code, checks by id)."""
    env = dict(lab.ros_env(host), XDG_STATE_HOME=str(state))
    r = lab.rosnet(host, "check", "--json", "-q", *steps, *extra,
                   "--config", str(lab.config_path(host)), env=env, timeout=timeout)
    assert r.stdout.strip(), r.stderr
    doc = json.loads(r.stdout)
    return r.returncode, {c["id"]: c for c in doc["checks"]}


def table(checks: dict[str, dict]) -> str:
    return "\n".join(f"{c['status']:4} {c['id']}: {c['summary']} {c['evidence']}"
                     for c in checks.values())


@pytest.mark.parametrize("host,peer", [("laptop", "turtlebot"), ("robot", "sami")])
def test_healthy_network_passes_everything(lab, tmp_path, host, peer):
    lab.reset()
    with secured(lab, [host]):                 # ROS 1 as the product sets it up
        code, checks = check(lab, host, tmp_path)
    assert code == 0, table(checks)
    assert all(c["status"] == "pass" for c in checks.values()), table(checks)
    d = {k: c["data"] for k, c in checks.items()}
    assert len(checks) == 15
    assert d["security.ssh_auth"]["methods"] == ["publickey"]    # no password for strangers
    assert d["isp.public_ip"]["public_ip"] == lab.public_ip(host)
    assert d["isp.cgnat"]["method"] == "traceroute" and not d["isp.cgnat"]["cgnat"]
    assert d["router.port_open"]["test_port_open"] is True
    assert all(p["via"] == f"peer:{peer}" for p in d["router.port_open"]["ports"])
    assert d["linux.ssh"]["peers"][peer]["ok"]
    assert d["linux.chat_out"]["peers"][peer]["ok"] and d["linux.chat_in"]["peers"][peer]["ok"]


def test_no_forwarding_closes_the_port_while_our_listener_runs(lab, tmp_path):
    with lab.variant("no_forwarding", side="robot"):
        code, checks = check(lab, "robot", tmp_path)
    assert code == 1
    assert checks["router.listener"]["status"] == "pass"
    assert checks["router.port_free"]["status"] == "pass"
    po = checks["router.port_open"]
    assert po["status"] == "fail", table(checks)
    assert po["data"]["test_port_open"] is False
    assert po["data"]["ports"][0]["listener"] is True and po["data"]["ports"][0]["via"] == "peer:sami"
    assert "while our listener runs" in po["summary"]
    assert any("sami -> 203.0.113.2:12345: no answer" in e for e in po["evidence"])
    assert checks["linux.chat_in"]["status"] == "fail"   # sami cannot reach us...
    assert checks["linux.chat_out"]["status"] == "pass"  # ...but we reach sami


def test_wrong_forward_is_caught_from_the_peer(lab, tmp_path):
    with lab.variant("wrong_forward", side="robot"):
        code, checks = check(lab, "robot", tmp_path)
    assert code == 1
    po = checks["router.port_open"]
    assert po["status"] == "fail" and checks["router.listener"]["status"] == "pass"
    assert po["data"]["test_port_open"] is False and "while our listener runs" in po["summary"]
    assert checks["router.local_ip"]["status"] == "pass"  # this side is right; the modem is not


def test_stale_hosts_entry_fails_resolve_and_ssh(lab, tmp_path):
    with lab.variant("stale_hosts"):
        code, checks = check(lab, "laptop", tmp_path)
    assert code == 1
    res = checks["linux.resolve"]
    assert res["status"] == "fail", table(checks)
    assert res["data"]["wrong"] == ["turtlebot"]
    tb = res["data"]["names"]["turtlebot"]
    assert (tb["resolved"], tb["expected"]) == ("203.0.113.99", "203.0.113.2")
    # the settings file the lab just wrote dates the address the settings give
    assert [(d["ip"], d["by"]) for d in tb["dated"]] == [("203.0.113.2", "settings")]
    assert 0 <= tb["dated"][0]["age_s"] < 120
    ssh = checks["linux.ssh"]
    assert ssh["status"] == "fail" and ssh["data"]["peers"]["turtlebot"]["failure"] == "network"
    assert "203.0.113.99" in " ".join(ssh["evidence"])
    hosts = checks["linux.hosts"]["data"]
    assert hosts["wrong"] == [{"name": "turtlebot", "found": "203.0.113.99", "expected": "203.0.113.2"}]
    for cid in ("isp.internet", "isp.public_ip", "router.local_ip", "router.listener"):
        assert checks[cid]["status"] == "pass", cid


def test_cgnat_warns_and_names_the_carrier_hop(lab, tmp_path):
    with lab.variant("cgnat"):
        _code, checks = check(lab, "robot", tmp_path)
    cg = checks["isp.cgnat"]
    assert cg["status"] == "warn", table(checks)
    assert cg["data"]["cgnat"] is True and cg["data"]["hop"] == "100.64.0.1"
    assert cg["data"]["method"] == "traceroute"
    assert checks["router.port_open"]["status"] == "fail"
    assert checks["isp.public_ip"]["data"]["public_ip"] == "203.0.113.3"
    assert checks["isp.public_ip"]["data"]["matches_settings"] is False


def test_unplugged_gives_every_verdict_within_its_timeout(lab, tmp_path):
    with lab.variant("unplugged"):
        t0 = time.monotonic()
        code, checks = check(lab, "laptop", tmp_path)
        took = time.monotonic() - t0
    assert code == 1
    for c in checks.values():
        assert c["duration_s"] <= c["timeout_s"] + 0.5, c
        assert "timed out" not in c["summary"], c  # each check ended on its own terms
    assert checks["router.local_ip"]["status"] == "fail" and "down" in checks["router.local_ip"]["summary"]
    assert checks["isp.internet"]["status"] == "fail"
    assert checks["isp.internet"]["data"]["failed_part"] == "dns"
    assert checks["linux.ssh"]["data"]["peers"]["turtlebot"]["failure"] == "network"
    assert took < 30


def test_a_new_public_ip_is_noticed_and_recorded(lab, tmp_path):
    lab.reset()
    _, first = check(lab, "robot", tmp_path, steps=("--step", "isp"))
    assert first["isp.public_ip"]["status"] == "pass"
    with lab.set_robot_wan("203.0.113.50"):
        _, after = check(lab, "robot", tmp_path, steps=("--step", "isp"))
    pub = after["isp.public_ip"]
    assert pub["status"] == "warn"
    assert pub["data"]["public_ip"] == "203.0.113.50" and pub["data"]["previous_ip"] == "203.0.113.2"
    assert pub["data"]["changed"] is True and pub["data"]["matches_settings"] is False
    assert [h["ip"] for h in pub["data"]["history"]] == ["203.0.113.2", "203.0.113.50"]


def test_an_unknown_host_key_is_shown_not_accepted(lab, tmp_path):
    lab.reset()
    known = lab.home("laptop") / ".ssh" / "known_hosts"
    saved = known.read_text()
    try:
        known.write_text("")
        code, checks = check(lab, "laptop", tmp_path, timeout=60)
        assert known.read_text() == ""  # nothing was added behind the user's back
    finally:
        known.write_text(saved)
    ssh = checks["linux.ssh"]
    peer = ssh["data"]["peers"]["turtlebot"]
    assert code == 1 and ssh["status"] == "fail"
    assert peer["failure"] == "host_key_unknown" and peer["fingerprint"].startswith("SHA256:")
    assert peer["fingerprint"] in " ".join(ssh["evidence"])
    assert checks["linux.chat_out"]["data"]["peers"]["turtlebot"]["failure"] == "ssh:host_key_unknown"
