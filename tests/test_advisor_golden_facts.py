"""What the advisor's golden files pin, stated as behaviour (issue 36): a golden file is
re-recorded from the code under test, so a fact it alone holds is lost the day it is recorded
again. Each test here was found by putting a small bug into the advisor's engine and seeing
that only tests/test_advisor_golden.py failed."""

from __future__ import annotations

from rosnet_tui.core import advisor
from rosnet_tui.core.results import CheckResult, Status
from tests.advisor_support import ISP_CASES, run
from tests.builders import healthy_laptop, t1


def test_a_findings_order_is_its_rank_among_competing_causes_and_0_without_competitors():
    """engine.Hit.order's default (0): the report's "order" field (Finding.to_dict) says which of the competing
    causes of one symptom comes first; a finding that competes with none is 0."""
    fs = run(t1(True, False))
    assert [(f.rule, f.order) for f in fs if f.rule.startswith(advisor.T1)] == [
        (f"{advisor.T1}.forwarding", 0), (f"{advisor.T1}.isp", 1),
        (f"{advisor.T1}.port_in_use", 2)]
    assert [f.to_dict()["order"] for f in fs if f.rule.startswith(advisor.T1)] == [0, 1, 2]
    for rule, case in ISP_CASES.items():
        found = run(*case())
        assert found and rule in {f.rule for f in found}, rule
        assert {f.order for f in found} == {0}, (rule, [(f.rule, f.order) for f in found])


def test_a_failure_no_rule_explains_gets_the_catch_all_with_the_checks_first_three_lines():
    """engine._catch_all: its finding competes with none (order 0) and carries the first three
    lines of the check's evidence, no more (the order 0 -> 1 and [:3] -> [:4] bugs passed every
    test but the golden one, or every test)."""
    r = healthy_laptop()
    r["isp.internet"] = CheckResult("isp.internet", "isp", Status.FAIL, "odd failure",
                                    ["e1", "e2", "e3", "e4", "e5"], 0.1, 3.0, {})
    r["linux.hosts"] = CheckResult("linux.hosts", "linux", Status.WARN, "odd warning",
                                   ["w1"], 0.1, 3.0, {})
    fs = {f.check_ids[0]: f for f in run(r) if f.rule == "check.unexplained"}
    f, w = fs["isp.internet"], fs["linux.hosts"]
    assert (f.severity, f.order, f.evidence, f.goto_step) == ("fail", 0, ["e1", "e2", "e3"], "isp")
    assert (w.severity, w.order, w.evidence, w.goto_step) == ("warn", 0, ["w1"], "linux")
    assert f.meaning == "isp.internet: odd failure"


def test_within_a_severity_findings_follow_the_procedures_steps_the_catch_all_too():
    """engine._sort_key: a failure no rule explains is listed in its check's step (ISP before
    the Router's Table 1, Linux after it), not after every rule's findings (the step part of
    the key dropped failed only the golden test)."""
    r = t1(True, False)
    r["isp.internet"] = CheckResult("isp.internet", "isp", Status.FAIL, "odd failure", ["e1"],
                                    0.1, 3.0, {})
    r["linux.hosts"] = CheckResult("linux.hosts", "linux", Status.FAIL, "odd", ["e1"], 0.1,
                                   3.0, {})
    fails = [(f.rule, f.check_ids[0]) for f in run(r) if f.severity == "fail"]
    assert fails[0] == ("check.unexplained", "isp.internet")
    assert [rule for rule, _ in fails[1:4]] == [f"{advisor.T1}.forwarding", f"{advisor.T1}.isp",
                                               f"{advisor.T1}.port_in_use"]
    assert fails[4:] == [("check.unexplained", "linux.hosts")]
