"""Every advisor rule on its case (tests/advisor_support.py), silent on a healthy network and on
skipped checks; the order of findings, the JSON contract, the documentation.

Results are built by hand following the checks contract (check ids and their ``data`` keys): these
test the pure logic of the rules, no network involved."""

from __future__ import annotations

import copy
import re
import subprocess
import sys
from pathlib import Path

import pytest

from rosnet_tui.core import advisor
from rosnet_tui.core.advisor import advice_by_check, advise, all_rules
from rosnet_tui.core.config.settings_model import Settings
from rosnet_tui.core.procedure import STEP_IDS
from rosnet_tui.core.results import Status
from tests.advisor_support import (
    GENERAL_CASES,
    ISP_CASES,
    LINUX_CASES,
    ROS_CASES,
    ROUTER_CASES,
    Case,
    chat,
    ids,
    only,
    run,
    text,
    timed_out,
    unexplained,
    unreachable,
)
from tests.builders import healthy_laptop, healthy_robot, laptop_settings, put, robot_settings, t1
from tests.test_advisor_ros2 import ROS2_CASES
from tests.test_advisor_security import SECURITY_CASES
from tests.test_advisor_upnp import UPNP_CASES
from tests.test_firewall import FIREWALL_CASES
from tests.test_relay_tunnel_check import RELAY_TUNNEL_CASES
from tests.test_rosbridge import ROSBRIDGE_CASES

ROOT = Path(__file__).resolve().parents[1]

CASES: dict[str, Case] = {**ISP_CASES, **ROUTER_CASES, **LINUX_CASES, **ROS_CASES, **GENERAL_CASES,
                          **ROS2_CASES, **UPNP_CASES, **ROSBRIDGE_CASES,
                          **SECURITY_CASES, **FIREWALL_CASES, **RELAY_TUNNEL_CASES}


def test_healthy_network_has_no_failures_or_warnings():
    for results, s in ((healthy_laptop(), laptop_settings()), (healthy_robot(), robot_settings())):
        fs = run(results, s)
        assert [f.severity for f in fs if f.severity in ("fail", "warn")] == []
        assert "table1.open" in ids(fs)
        # Forwarding is in use, so the exposure warning is always there.
        assert "security.exposed" in ids(fs)


def test_empty_results_give_no_findings():
    assert run({}) == []


def test_every_rule_has_a_case():
    assert set(CASES) == {r.id for r in all_rules()}


def test_rule_ids_are_unique_and_well_formed():
    rules = all_rules()
    assert len({r.id for r in rules}) == len(rules)
    for r in rules:
        assert r.severity in advisor.SEVERITIES
        assert r.goto_step in (*STEP_IDS, None)
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


def test_catch_alls():
    f = only(run(timed_out()[0]), "check.no_verdict")
    assert "timeout_s" in text(f) and f.check_ids == ["linux.ping"] and f.goto_step == "linux"
    f = only(run(unexplained()[0]), "check.unexplained")
    assert "something odd" in f.meaning


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
    fs = run(*chat(True, False)())
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
    r, _ = unreachable()
    fs = advise(r, Settings(), strict=True)
    assert fs and all("None" not in text(f) for f in fs)


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


COMMAND = re.compile(r"`([^`]+)`")
FILLER = re.compile(r"\b(the|its|this|a|an)\b|\?")    # words a fallback puts where a value goes


def test_printed_commands_can_be_run_as_printed():
    """Issue 29 (section 4, row 10): with the gateway unknown the advice printed the command
    `ping the modem`. Every rule on its case, and on it again with the gateway, the interface and
    the test URL unknown: what is printed as a command holds no words standing in for a value."""
    bad = []
    for _, build in sorted(CASES.items()):
        for blank in (False, True):
            results, s = build()
            if blank:
                for r in results.values():
                    for key in ("gateway", "interface", "url"):
                        if key in (r.data or {}):
                            r.data[key] = ""
                s.this.interface = ""
            for f in run(results, s):
                for cmd in COMMAND.findall(" ".join(f.actions)):
                    if FILLER.search(cmd):
                        bad.append(f"{f.rule}{' (blank)' if blank else ''}: `{cmd}`")
    assert bad == []


def test_exposure_says_what_the_peers_only_firewall_lets_in():
    """ROS 1's default protection is the peers-only firewall: the advisor's exposure text says
    who really gets in (the router card's sentence), and the whole internet only without it."""
    from rosnet_tui.core.exposure.router_card import ros1_exposure

    s = robot_settings()
    assert s.ros.security == "firewall"
    f = only(run(healthy_robot(), s), "security.exposed")
    assert ros1_exposure(s) in f.meaning
    assert "only the peers, this machine's LAN" in f.meaning and "until it is loaded" in f.meaning
    s.ros.security = "none"
    f = only(run(healthy_robot(), s), "security.exposed")
    assert ros1_exposure(s) in f.meaning and "whole internet" in f.meaning
    assert "only the peers" not in f.meaning
