"""The advisor on the network lab: the real checks, the real CLI, the right cause named first.

Each broken variant of the lab must make `rosnet-tui check`/`report` on the right component name
the right first failure, with an action a technician can follow; the healthy network must give no
failure finding at all.
"""

from __future__ import annotations

import json

import pytest

from tests.lab.firewall import secured

pytestmark = pytest.mark.lab
PUBSUB = ("ros.pubsub_out", "ros.pubsub_in")  # (importing the check module would register it first)

T1 = "table1.listener_up_closed"


def _env(lab, host: str, state) -> dict:
    # A fresh state folder per test: the public-IP history of other tests stays out of it.
    return dict(lab.ros_env(host), XDG_STATE_HOME=str(state))


def report(lab, host: str, state, *args: str, input: str | None = None) -> tuple[int, dict]:
    """`rosnet-tui report --format json` on *host*: (exit code, the report)."""
    r = lab.rosnet(host, "report", "--format", "json", "--config", str(lab.config_path(host)),
                   *args, env=_env(lab, host, state), input=input, timeout=120)
    assert r.stdout.strip(), r.stderr
    return r.returncode, json.loads(r.stdout)


def check_json(lab, host: str, state) -> tuple[int, str]:
    r = lab.rosnet(host, "check", "--json", "-q", "--config", str(lab.config_path(host)),
                   env=_env(lab, host, state), timeout=120)
    assert r.stdout.strip(), r.stderr
    return r.returncode, r.stdout


def failures(doc: dict) -> list[dict]:
    return [f for f in doc["findings"] if f["severity"] == "fail"]


def explain(doc: dict) -> str:
    lines = [f"{c['status']:4} {c['id']}: {c['summary']}" for c in doc["checks"]]
    lines += [f"[{f['severity']}] {f['rule']}: {f['meaning']}" for f in doc["findings"]]
    return "\n".join(lines)


def test_healthy_network_gives_no_failure_findings(ros1_lab, tmp_path):
    lab = ros1_lab
    lab.reset()
    exposed = {}
    with secured(lab):                  # ROS 1 as the product sets it up: the firewall on
        docs = {h: report(lab, h, tmp_path / h) for h in ("robot", "laptop")}
    for host in ("robot", "laptop"):
        code, doc = docs[host]
        assert code == 0, explain(doc)
        assert doc["summary"]["fail"] == 0, explain(doc)
        assert failures(doc) == [], explain(doc)
        rules = [f["rule"] for f in doc["findings"]]
        assert "table1.open" in rules, explain(doc)
        # forwarding is in use, so the exposure is always pointed out
        exposed[host] = next(f for f in doc["findings"] if f["rule"] == "security.exposed")
        assert exposed[host]["severity"] == "security"
        assert any("PasswordAuthentication no" in a for a in exposed[host]["actions"])
    # on the robot the ROS master itself is reachable from the internet
    assert "ROS 1 has no authentication" in exposed["robot"]["meaning"]


def test_no_forwarding_names_the_modem_forwarding_first(ros1_lab, tmp_path):
    lab = ros1_lab
    with lab.variant("no_forwarding", side="robot"):
        code, out = check_json(lab, "robot", tmp_path)
        assert code == 1
        checks = {c["id"]: c for c in json.loads(out)["checks"]}
        # `check --json` carries the advice on the failed check, Table 1's causes in order
        advice = checks["router.port_open"]["advice"]
        assert [a["rule"] for a in advice[:3]] == [f"{T1}.forwarding", f"{T1}.isp",
                                                   f"{T1}.port_in_use"], advice
        assert advice[0]["goto_step"] == "router"
        # the same results, as a report read back from that output
        code, doc = report(lab, "robot", tmp_path, "--from-json", "-", input=out)
        assert code == 1
    first = failures(doc)[0]
    assert first["rule"] == f"{T1}.forwarding", explain(doc)
    assert any("forward TCP (and UDP if needed) 1024-65000 to 10.10.10.1" in a
               for a in first["actions"]), first
    assert "router.port_open" in first["check_ids"]


def test_cgnat_names_the_carrier_nat_first(ros1_lab, tmp_path):
    lab = ros1_lab
    with lab.variant("cgnat"):
        code, doc = report(lab, "robot", tmp_path)
    assert code == 1
    first = failures(doc)[0]
    assert first["rule"] == f"{T1}.isp", explain(doc)
    assert first["goto_step"] == "isp"
    assert "Carrier-grade NAT" in first["meaning"] and "100.64." in first["meaning"], first
    assert "isp.cgnat" in first["check_ids"]
    assert any("public IP" in a for a in first["actions"])
    # ROS 1: forwarding cannot cross it anywhere; the ways out are named (issue 30)
    assert "Under ROS 1 no forwarding" in first["meaning"], first
    assert any("relay" in a for a in first["actions"]) and \
        any("VPN" in a for a in first["actions"]), first


def test_ros_ip_on_the_laptop_says_unset_it_on_sami(ros1_lab, tmp_path):
    lab = ros1_lab
    with lab.variant("ros_ip_laptop"):
        code_l, on_laptop = report(lab, "laptop", tmp_path / "laptop")
        code_r, on_robot = report(lab, "robot", tmp_path / "robot")
    assert code_l == 1 and code_r == 1
    first = failures(on_laptop)[0]
    assert first["rule"] == "ros.env.ros_ip", explain(on_laptop)
    assert first["actions"][0].startswith("Unset ROS_IP on sami"), first
    # from the robot's seat: the node on sami advertises sami's local address
    first = failures(on_robot)[0]
    assert first["rule"] == "ros.node_uri.local_ip", explain(on_robot)
    assert first["actions"][0].startswith("Unset ROS_IP on sami"), first
    for doc in (on_laptop, on_robot):   # no path: ros.link says so once a pub/sub check has
        checks = {c["id"]: c for c in doc["checks"]}
        link, shared = checks["ros.link"], (*PUBSUB, "ros.master", "ros.node_uris")
        assert link["status"] == "skip" and "found no message passing" in link["summary"], link
        assert link["duration_s"] <= max(checks[c]["duration_s"] for c in shared) + 1.0, \
            explain(doc)   # once the checks asking the master end, not at its budget's (11 s)


def test_markdown_report_on_a_broken_network_reads_well(ros1_lab, tmp_path):
    lab = ros1_lab
    with lab.variant("stale_hosts"):
        r = lab.rosnet("laptop", "report", "--config", str(lab.config_path("laptop")),
                       env=_env(lab, "laptop", tmp_path), timeout=120)
    assert r.returncode == 1, r.stderr
    md = r.stdout
    assert md.startswith("# rosnet-tui report: sami")
    head = md.split("### Warnings")[0].split("### Security")[0]
    assert "1. [FAIL] turtlebot resolves to 203.0.113.99 on sami" in head, md
    assert "change `203.0.113.99 turtlebot` to `203.0.113.2 turtlebot`" in head
    assert "## Results by step" in md and "## Settings" in md
    assert "ROS_MASTER_URI=http://turtlebot:11311" in md


@pytest.mark.parametrize("variant, host, rule, needle", [
    ("wrong_forward", "robot", f"{T1}.forwarding", "to 10.10.10.1"),
    ("unplugged", "laptop", "router.local_ip.no_link", "no IPv4 address on eth0"),
    ("unplugged", "robot", "linux.peer.unreachable", "sami's modem is online"),
])
def test_more_variants_name_their_cause_first(ros1_lab, tmp_path, variant, host, rule, needle):
    lab = ros1_lab
    with lab.variant(variant):
        code, doc = report(lab, host, tmp_path)
    assert code == 1
    first = failures(doc)[0]
    assert first["rule"] == rule, explain(doc)
    assert needle in first["meaning"] + " ".join(first["actions"]), first
