"""The advisor's rules over router.upnp, the modem's own word (UPnP IGD, PCP, NAT-PMP)."""

from __future__ import annotations

from rosnet_tui.core.advisor import advise
from rosnet_tui.core.results import CheckResult, Status
from tests.builders import ros2_master as master
from tests.builders import ros2_member as member


def r(status: str, summary: str = "s", **data) -> CheckResult:
    base = {"protocol": "upnp", "protocols": ["upnp", "pcp", "natpmp"],
            "gateway": "10.10.10.254", "external_ip": "203.0.113.2", "wan": "public",
            "cgnat": False, "needed": [7447], "present": [], "missing": [], "conflicts": [],
            "forwards": [], "can_list": True, "range_needed": False, "tried": []}
    base.update(data)
    return CheckResult("router.upnp", "router", Status(status), summary, [], 0.1, 4.5, base)


def only(findings, rule: str):
    got = [f for f in findings if f.rule == rule]
    assert len(got) == 1, [f.rule for f in findings]
    return got[0]


def test_a_missing_forward_the_modem_could_make_names_the_command():
    f = only(advise([r("warn", missing=[7447])], master()), "router.upnp.missing")
    assert f.severity == "warn" and f.goto_step == "router"
    assert "TCP 7447" in f.meaning and "UPnP IGD, PCP and NAT-PMP" in f.meaning
    assert "`rosnet-tui router map`" in f.actions[0] and "undo" in f.actions[1]


def test_a_conflict_names_the_other_machine():
    fs = advise([r("fail", conflicts=[{"port": 7447, "internal_client": "10.10.10.3",
                                       "description": "NAT-PMP 7447 tcp"}])], master())
    f = only(fs, "router.upnp.conflict")
    assert f.severity == "fail" and "10.10.10.3" in f.meaning and "another machine" in f.meaning
    assert "router.upnp.missing" not in [x.rule for x in fs]


def test_the_modems_empty_address_is_carrier_grade_nat():
    fs = advise([r("warn", external_ip="", wan="none", cgnat=True, missing=[7447])], master())
    f = only(fs, "router.upnp.cgnat")
    assert "carrier-grade NAT" in f.meaning and "no public address" in f.meaning
    assert f.goto_step == "isp" and "router.upnp.missing" not in [x.rule for x in fs]


def test_a_pass_or_a_skip_says_nothing():
    assert not advise([r("pass", present=[7447])], master())
    assert not advise([r("skip", protocol=None, protocols=[])], member())


def test_the_members_missing_forward_advice_mentions_router_map():
    fs = advise([CheckResult("ros2.router", "ros", Status.FAIL, "s", [], 0.1, 3.0,
                             {"failure": "timeout", "endpoint": "tcp/turtlebot:7447",
                              "address": "203.0.113.2", "reachable": False})], member())
    f = only(fs, "ros2.port.not_forwarded")
    assert any("rosnet-tui router" in a and "map` on turtlebot" in a for a in f.actions)


def _case(*results: CheckResult):
    return lambda: ({x.id: x for x in results}, master())


# One case per rule, for tests/test_advisor_rules.py's every-rule tests (and the golden inputs).
UPNP_CASES = {
    "router.upnp.missing": _case(r("warn", missing=[7447])),
    "router.upnp.conflict": _case(r("fail", conflicts=[{"port": 7447,
                                                        "internal_client": "10.10.10.3",
                                                        "description": "x"}])),
    "router.upnp.cgnat": _case(r("warn", external_ip="", wan="none", cgnat=True,
                                 missing=[7447])),
}


def test_isp_cgnat_from_the_modems_empty_address_is_worded_as_such():
    from rosnet_tui.core.checks.isp import judge_no_wan
    from rosnet_tui.core.results import Status as S

    st, summary, upd = judge_no_wan({})
    assert st is S.WARN and upd == {"cgnat": True, "hop": None}
    assert summary.startswith("carrier-grade NAT: the modem reports no public address")
    st, summary, upd = judge_no_wan({"double_nat": True, "hop": "192.168.0.1"})
    assert upd["double_nat"] and "192.168.0.1" in summary
    res = CheckResult("isp.cgnat", "isp", Status.WARN, summary, [], 0.1, 6.0,
                      {"wan_ip": "", "method": "upnp", "cgnat": True, "double_nat": False,
                       "hop": None})
    f = only(advise([res], member()), "ros2.cgnat")   # a member: harmless under ROS 2
    assert f.severity == "info"
    from rosnet_tui.core.config.settings_model import Settings, ThisComponent

    ros1 = Settings(this=ThisComponent(name="turtlebot", role="master"))
    f = only(advise([res], ros1), "isp.cgnat")
    assert "the modem itself reports no public address" in f.meaning, f.meaning
    # ROS 1 (issue 30): no forward crosses it, and the ways out are named
    assert "Under ROS 1 no forwarding anywhere gets around it" in f.meaning, f.meaning
    said = " ".join(f.actions)
    assert "public IP" in said and "relay" in said and "Tailscale" in said, f.actions
