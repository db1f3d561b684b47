"""What the advisor's golden files pin, stated as behaviour (issue 36): a golden file is
re-recorded from the code under test, so a fact it alone holds is lost the day it is recorded
again. Each test here was found by putting a small bug into the advisor's engine and seeing
that only tests/test_advisor_golden.py failed."""

from __future__ import annotations

from rosnet_tui.core import advisor
from tests.advisor_support import ISP_CASES, run
from tests.builders import t1


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
