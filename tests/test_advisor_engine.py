"""The advisor's engine: order and dependencies are declared, never implied by file order."""

from __future__ import annotations

import ast
import json
import random
from pathlib import Path

import pytest

from rosnet_tui.core import advisor
from rosnet_tui.core.advisor import engine
from rosnet_tui.core.advisor.engine import Hit
from rosnet_tui.core.advisor.evidence import Evidence, RuleOrderError
from rosnet_tui.core.advisor.order import RULE_ORDER
from tests.builders import healthy_laptop, laptop_settings, put
from tests.golden import codec, record

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def registry():
    """The real registry, restored (and re-sealed) after a test that fiddles with it."""
    saved = dict(engine._REGISTRY)
    yield engine._REGISTRY
    engine._REGISTRY.clear()
    engine._REGISTRY.update(saved)
    engine.seal(RULE_ORDER)


def _declare(rid: str, **kw) -> None:
    engine.rule(rid, "ros", ("ros.env",), "c", "m", "a", "ros", "info", **kw)(lambda ev: [])


def test_every_rule_has_one_place_in_the_order():
    assert [r.id for r in advisor.RULES] == list(RULE_ORDER)
    assert len(set(RULE_ORDER)) == len(RULE_ORDER)


def test_rules_that_read_firing_are_evaluated_after_what_they_read():
    pos = {r.id: i for i, r in enumerate(engine._EVAL_ORDER)}
    readers = [r for r in advisor.RULES if r.after]
    assert {r.id for r in readers} == {"ros.pubsub.out_fails", "ros.pubsub.in_fails",
                                       "ros2.peer_mode", "ros2.link.missing"}
    for r in readers:
        assert all(pos[a] < pos[r.id] for a in r.after), r.id


@pytest.mark.parametrize("order", ["reversed", "shuffled"])
def test_findings_do_not_depend_on_declaration_or_listing_order(registry, order):
    """Declared in another order and listed in another order: the same findings per case
    (their display order follows the listing, so compare them as sets)."""
    cases = json.loads(record.INPUTS.read_text(encoding="utf-8"))["cases"]
    before = [record.replay(advisor.advise, c) for c in cases]
    ids = list(RULE_ORDER)
    if order == "reversed":
        ids.reverse()
    else:
        random.Random(11).shuffle(ids)
    items = list(registry.items())
    random.Random(7).shuffle(items)
    registry.clear()
    registry.update(items)
    engine.seal(ids)
    assert [r.id for r in advisor.RULES] == ids
    after = [record.replay(advisor.advise, c) for c in cases]
    for c, b, a in zip(cases, before, after, strict=True):
        if "raises" in b:
            assert "raises" in a, c["case"]
            continue
        key = lambda f: json.dumps(f, sort_keys=True)    # noqa: E731
        assert sorted(map(key, a["findings"])) == sorted(map(key, b["findings"])), c["case"]


def test_the_order_must_name_every_rule_once(registry):
    with pytest.raises(RuleOrderError, match="not listed: security.exposed"):
        engine.seal(RULE_ORDER[:-1])
    with pytest.raises(RuleOrderError, match="listed twice: isp.cgnat"):
        engine.seal((*RULE_ORDER, "isp.cgnat"))
    with pytest.raises(RuleOrderError, match="listed, not declared: no.such.rule"):
        engine.seal((*RULE_ORDER, "no.such.rule"))


def test_unknown_ids_and_cycles_fail_loudly(registry):
    _declare("test.a", after=("no.such.rule",))
    with pytest.raises(RuleOrderError, match="test.a: after names unknown rule"):
        engine.seal((*RULE_ORDER, "test.a"))
    registry.pop("test.a")
    _declare("test.a", after=("test.b",))
    _declare("test.b", after=("test.a",))
    with pytest.raises(RuleOrderError, match="after forms a cycle among: test.a, test.b"):
        engine.seal((*RULE_ORDER, "test.a", "test.b"))
    registry.pop("test.a"), registry.pop("test.b")
    _declare("test.a", superseded_by=("test.b",))
    _declare("test.b", superseded_by=("test.a",))
    with pytest.raises(RuleOrderError, match="superseded_by forms a cycle"):
        engine.seal((*RULE_ORDER, "test.a", "test.b"))


def test_a_rule_is_declared_once(registry):
    with pytest.raises(RuleOrderError, match="declared twice"):
        _declare("isp.cgnat")
    with pytest.raises(RuleOrderError, match="declared twice"):
        _declare("check.unexplained")


def test_reading_an_undeclared_firing_is_an_error_even_when_not_strict(registry):
    def peeks(ev: Evidence) -> list[Hit]:
        return [Hit("m", ["a"])] if ev.fired_any("table1.open") else []

    engine.rule("test.peek", "ros", ("ros.env",), "c", "m", "a", "ros", "info")(peeks)
    engine.seal((*RULE_ORDER, "test.peek"))
    with pytest.raises(RuleOrderError, match="test.peek reads whether table1.open fired"):
        advisor.advise(healthy_laptop(), laptop_settings())
    registry.pop("test.peek")
    engine.rule("test.peek", "ros", ("ros.env",), "c", "m", "a", "ros", "info",
                after=("table1.open",))(peeks)
    engine.seal((*RULE_ORDER, "test.peek"))
    fs = advisor.advise(healthy_laptop(), laptop_settings(), strict=True)
    assert "test.peek" in [f.rule for f in fs]


def test_a_superseded_rule_leaves_no_check_without_advice(registry):
    """Issue 29 (section 4, row 4): a rule superseded by a more specific one dropped the checks
    it explained with its findings, and they ended as "no rule explains it". They go to the
    finding of the rule that superseded it now."""
    engine.rule("test.specific", "ros", ("ros.master",), "c", "m", "a", "ros", "fail")(
        lambda ev: [Hit("specific", ["a"], check_ids=["ros.master"])])
    engine.rule("test.generic", "ros", ("ros.env",), "c", "m", "a", "ros", "fail",
                superseded_by=("test.specific",))(
        lambda ev: [Hit("generic", ["a"], check_ids=["ros.env", "ros.master"])])
    engine.seal((*RULE_ORDER, "test.specific", "test.generic"))
    r = healthy_laptop()
    put(r, "ros.env", "fail")
    put(r, "ros.master", "fail")
    fs = advisor.advise(r, laptop_settings(), strict=True)
    rules = [f.rule for f in fs]
    assert "test.generic" not in rules and "check.unexplained" not in rules, rules
    assert next(f for f in fs if f.rule == "test.specific").check_ids == ["ros.master", "ros.env"]


def test_the_package_keeps_its_old_names():
    from rosnet_tui.core.procedure import SEVERITIES
    assert advisor.SEVERITIES == SEVERITIES
    assert advisor.T1 == "table1.listener_up_closed"
    assert advisor.step_title("router") == "step 2 (Router/modem)"
    assert advisor.rule_by_id("isp.cgnat").step == "isp"


def test_rule_modules_import_no_check_module():
    """Rules read the checks' declared data (checks.data), never the check modules themselves."""
    allowed = {"rosnet_tui.core.checks", "rosnet_tui.core.checks.data"}
    for p in (ROOT / "rosnet_tui" / "core" / "advisor").glob("*.py"):
        for node in ast.walk(ast.parse(p.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
                if node.module == "rosnet_tui.core.checks":
                    names = [f"{node.module}.{a.name}" for a in node.names]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            else:
                continue
            for n in names:
                if n.startswith("rosnet_tui.core.checks"):
                    assert n in allowed or n.startswith("rosnet_tui.core.checks.data."), \
                        (p.name, n)


def test_no_advisor_file_is_long():
    for p in (ROOT / "rosnet_tui" / "core" / "advisor").glob("*.py"):
        assert len(p.read_text(encoding="utf-8").splitlines()) <= 600, p.name


def test_codec_round_trip_is_exact():
    r, s = healthy_laptop(), laptop_settings()
    assert codec.results_from_json(codec.results_to_json(r)) == r
    assert codec.settings_from_json(codec.settings_to_json(s)) == s
