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
from tests.builders import healthy_laptop, laptop_settings, put, result
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


# --------------------------------------------------------------------------- issue 36: the seal
def _hit_rule(rid: str, step: str = "ros", severity: str = "fail", hits=None, **kw) -> None:
    """A test rule that always fires: *hits* (default one Hit naming ros.env)."""
    made = hits if hits is not None else [Hit(rid, ["a"], check_ids=["ros.env"])]
    engine.rule(rid, step, ("ros.env",), "c", "m", "a", step, severity, **kw)(
        lambda ev: [Hit(h.meaning, list(h.actions), h.check_ids, h.severity, h.goto_step,
                        h.order, list(h.evidence)) for h in made])


def _ours(order=()) -> list:
    """The findings of the test rules (test.*) on a healthy round, sealed with *order* added."""
    engine.seal((*RULE_ORDER, *order))
    fs = advisor.advise(healthy_laptop(), laptop_settings(), strict=True)
    return [f for f in fs if f.rule.startswith("test.")]


@pytest.mark.parametrize("kind", ["after", "superseded_by"])
def test_a_rule_naming_itself_or_an_unknown_rule_is_refused_by_name(registry, kind):
    _declare("test.a", **{kind: ("test.a",)})
    with pytest.raises(RuleOrderError, match=rf"^rule test\.a: {kind} names unknown rule\(s\) "
                                             r"test\.a$"):
        engine.seal((*RULE_ORDER, "test.a"))
    registry.pop("test.a")
    _declare("test.a", **{kind: ("isp.cgnat", "no.such", "test.a")})
    with pytest.raises(RuleOrderError, match=rf"^rule test\.a: {kind} names unknown rule\(s\) "
                                             r"no\.such, test\.a$"):
        engine.seal((*RULE_ORDER, "test.a"))


def test_the_seal_names_every_kind_of_listing_fault_at_once(registry):
    with pytest.raises(RuleOrderError) as got:
        engine.seal((*RULE_ORDER[1:], "isp.cgnat", "no.such"))
    assert str(got.value) == (f"RULE_ORDER must name every declared rule once: listed twice: "
                              f"isp.cgnat; not listed: {RULE_ORDER[0]}; listed, not declared: "
                              "no.such")
    # a refused seal leaves the sealed order as it was
    assert [r.id for r in advisor.RULES] == list(RULE_ORDER)


def test_a_rule_with_an_unknown_step_or_severity_is_refused_when_declared(registry):
    with pytest.raises(ValueError, match="rule test.a: unknown step 'nowhere'"):
        engine.rule("test.a", "nowhere", (), "c", "m", "a", None, "fail")
    with pytest.raises(ValueError, match="loud"):
        engine.rule("test.a", "ros", (), "c", "m", "a", None, "loud")
    assert "test.a" not in registry


# --------------------------------------------------------------------------- superseded_by
def test_a_superseded_finding_is_dropped_only_when_its_superseder_fired(registry):
    _hit_rule("test.generic", superseded_by=("test.never", "test.specific"))
    engine.rule("test.never", "ros", ("ros.env",), "c", "m", "a", "ros", "fail")(lambda ev: [])
    _hit_rule("test.specific")
    order = ("test.specific", "test.never", "test.generic")
    assert [f.rule for f in _ours(order)] == ["test.specific"]      # one of the two fired
    registry.pop("test.specific")
    engine.rule("test.specific", "ros", ("ros.env",), "c", "m", "a", "ros", "fail")(
        lambda ev: [])
    assert [f.rule for f in _ours(order)] == ["test.generic"]       # neither fired: kept


def test_a_chain_of_superseders_hands_the_checks_to_the_last_that_fired(registry):
    """A superseded by B, B by C: with all three firing only C is left, and its first finding
    carries the checks A and B explained that nothing kept explains; without C, B is left with
    A's."""
    _hit_rule("test.a", hits=[Hit("a", ["x"], check_ids=["ros.env", "ros.master"])],
              superseded_by=("test.b",))
    _hit_rule("test.b", hits=[Hit("b", ["x"], check_ids=["ros.env", "ros.node_uris"])],
              superseded_by=("test.c",))
    _hit_rule("test.c", hits=[Hit("c", ["x"], check_ids=["ros.pubsub"]),
                              Hit("c2", ["x"], check_ids=["ros.env"])])
    order = ("test.a", "test.b", "test.c")
    fs = _ours(order)
    assert [(f.rule, f.check_ids) for f in fs] == [      # ros.env: C explains it itself
        ("test.c", ["ros.pubsub", "ros.master", "ros.node_uris"]), ("test.c", ["ros.env"])], fs
    registry.pop("test.c")
    engine.rule("test.c", "ros", ("ros.env",), "c", "m", "a", "ros", "fail")(lambda ev: [])
    fs = _ours(order)
    assert [(f.rule, f.check_ids) for f in fs] == [
        ("test.b", ["ros.env", "ros.node_uris", "ros.master"])], fs


def test_a_check_two_superseded_rules_lost_goes_to_one_heir_only(registry):
    _hit_rule("test.x1", hits=[Hit("x1", ["x"], check_ids=["ros.master"])],
              superseded_by=("test.h1",))
    _hit_rule("test.x2", hits=[Hit("x2", ["x"], check_ids=["ros.master"])],
              superseded_by=("test.h2",))
    _hit_rule("test.h1", hits=[Hit("h1", ["x"], check_ids=["ros.env"])])
    _hit_rule("test.h2", hits=[Hit("h2", ["x"], check_ids=["ros.pubsub"])])
    fs = _ours(("test.h1", "test.h2", "test.x1", "test.x2"))
    assert [(f.rule, f.check_ids) for f in fs] == [("test.h1", ["ros.env", "ros.master"]),
                                                   ("test.h2", ["ros.pubsub"])], fs


# --------------------------------------------------------------------------- RULE_ORDER
def test_rule_order_decides_between_findings_of_equal_rank(registry):
    """Same severity, same step: RULE_ORDER alone puts them in order (the order the rules were
    declared in plays no part), whichever way it lists them."""
    _hit_rule("test.one")
    _hit_rule("test.two")
    assert [f.rule for f in _ours(("test.one", "test.two"))] == ["test.one", "test.two"]
    assert [f.rule for f in _ours(("test.two", "test.one"))] == ["test.two", "test.one"]


def test_severity_then_step_come_before_rule_order_and_a_group_ranks_by_its_evidence(registry):
    _hit_rule("test.warn_isp", step="isp", severity="warn")
    _hit_rule("test.fail_ros", step="ros")
    _hit_rule("test.fail_isp", step="isp")
    # one group: both take the place of its first rule; the hits' own order decides
    _hit_rule("test.g_late", hits=[Hit("late", ["x"], order=2)], group="test.g")
    _hit_rule("test.g_early", hits=[Hit("early", ["x"], order=1)], group="test.g")
    order = ("test.g_late", "test.warn_isp", "test.fail_ros", "test.g_early", "test.fail_isp")
    assert [f.rule for f in _ours(order)] == [
        "test.fail_isp", "test.g_early", "test.g_late", "test.fail_ros", "test.warn_isp"]


def test_a_catch_all_comes_after_the_rules_of_its_severity_and_step(registry):
    _hit_rule("test.last_listed", hits=[Hit("m", ["a"], check_ids=["ros.env"])])
    engine.seal((*RULE_ORDER, "test.last_listed"))
    r = healthy_laptop()
    put(r, "ros.master", "fail")
    r["ros.master"].summary = "something no rule knows"
    fs = [f for f in advisor.advise(r, laptop_settings(), strict=True)
          if f.goto_step == "ros" and f.severity == "fail"]
    assert [f.rule for f in fs][-2:] == ["test.last_listed", "check.unexplained"], fs


# --------------------------------------------------------------------------- hits
def test_what_a_hit_leaves_unset_comes_from_its_rule_and_what_it_sets_stays(registry):
    _hit_rule("test.h", severity="warn", hits=[
        Hit("unset", ["x"]),
        Hit("set", ["x"], check_ids=[], severity="info", goto_step=None, order=3,
            evidence=["seen"])])
    fs = {f.meaning: f for f in _ours(("test.h",))}
    assert (fs["unset"].check_ids, fs["unset"].severity, fs["unset"].goto_step,
            fs["unset"].order, fs["unset"].condition) == (["ros.env"], "warn", "ros", 0, "c")
    assert (fs["set"].check_ids, fs["set"].severity, fs["set"].goto_step, fs["set"].order,
            fs["set"].evidence) == ([], "info", None, 3, ["seen"])


def test_a_rule_that_trips_is_skipped_unless_strict(registry):
    def trips(ev: Evidence) -> list[Hit]:
        raise KeyError("no such key")

    engine.rule("test.trips", "ros", ("ros.env",), "c", "m", "a", "ros", "fail")(trips)
    _hit_rule("test.after_it")
    engine.seal((*RULE_ORDER, "test.trips", "test.after_it"))
    fs = advisor.advise(healthy_laptop(), laptop_settings())
    assert [f.rule for f in fs if f.rule.startswith("test.")] == ["test.after_it"]
    with pytest.raises(KeyError):
        advisor.advise(healthy_laptop(), laptop_settings(), strict=True)


def test_a_cycle_is_named_in_rule_order(registry):
    _declare("test.a", after=("test.b",))
    _declare("test.b", after=("test.a",))
    with pytest.raises(RuleOrderError, match="after forms a cycle among: test.b, test.a$"):
        engine.seal((*RULE_ORDER, "test.b", "test.a"))


def test_a_rule_sorts_by_the_step_of_its_symptom_and_keeps_what_it_declared(registry):
    """Its step (where the symptom is), not the step it sends the user to, places a finding;
    the rule as declared is what the table and rule_by_id show."""
    engine.rule("test.seen_in_ros", "ros", ("ros.env",), "cond", "mean", "act", "isp", "fail",
                group="test.g")(lambda ev: [Hit("r", ["x"])])
    engine.rule("test.seen_in_isp", "isp", ("ros.env",), "c", "m", "a", "ros", "fail")(
        lambda ev: [Hit("i", ["x"])])
    fs = _ours(("test.seen_in_ros", "test.seen_in_isp"))
    assert [f.rule for f in fs] == ["test.seen_in_isp", "test.seen_in_ros"]
    r = advisor.rule_by_id("test.seen_in_ros")
    assert r.row() == {"id": "test.seen_in_ros", "step": "ros", "condition": "cond",
                       "meaning": "mean", "action": "act", "goto_step": "isp",
                       "severity": "fail", "check_ids": ["ros.env"]}
    assert r.group == "test.g"


def test_rule_by_id_finds_that_rule_or_none():
    assert advisor.rule_by_id("isp.cgnat").id == "isp.cgnat"
    assert advisor.rule_by_id(RULE_ORDER[-1]).id == RULE_ORDER[-1]
    assert advisor.rule_by_id("check.unexplained").id == "check.unexplained"
    assert advisor.rule_by_id("no.such.rule") is None


def test_a_failing_check_of_no_known_step_gets_a_catch_all_without_a_step():
    """A result whose step the procedure does not know (a newer version's, a peer's report):
    its catch-all sends nowhere and says to read its evidence; it sorts after the steps'."""
    r = healthy_laptop()
    r["x.odd"] = result("x.odd", "fail", "odd", evidence=["e1"])
    r["x.late"] = result("x.late", "fail", "check timed out")      # no data: no verdict
    put(r, "ros.master", "fail")
    r["ros.master"].summary = "something no rule knows"
    fs = advisor.advise(r, laptop_settings(), strict=True)
    odd = next(f for f in fs if f.check_ids == ["x.odd"])
    assert (odd.rule, odd.goto_step, odd.actions, odd.evidence) == (
        "check.unexplained", None, ["Read the evidence of x.odd."], ["e1"])
    late = next(f for f in fs if f.check_ids == ["x.late"])
    assert late.rule == "check.no_verdict" and late.goto_step is None
    assert late.actions[0] == "Re-run the check.", late.actions
    ids = [f.check_ids for f in fs]
    assert ids.index(["ros.master"]) < ids.index(["x.odd"]), ids


def test_a_hit_of_an_unknown_severity_is_listed_last_not_a_crash(registry):
    _hit_rule("test.odd", hits=[Hit("odd", ["x"], severity="whatever")])
    _hit_rule("test.info", severity="info")
    assert [f.rule for f in _ours(("test.odd", "test.info"))] == ["test.info", "test.odd"]


def test_advise_takes_the_results_as_a_list_too():
    r = healthy_laptop()
    put(r, "ros.master", "fail")
    as_map = advisor.advise(r, laptop_settings(), strict=True)
    assert as_map and advisor.advise(list(r.values()), laptop_settings(), strict=True) == as_map


def test_a_rule_reading_an_undeclared_key_is_skipped_and_the_rules_after_it_run(
        registry, monkeypatch):
    """In production (not strict) such a rule is skipped: the rules evaluated after it still
    give their findings."""
    from rosnet_tui.core.checks import data as check_data

    engine.rule("test.typo", "isp", ("isp.internet",), "c", "m", "a", "isp", "info")(
        lambda ev: [Hit("m", ["a"])] if ev.data("isp.internet").get("dns_okay") else [])
    engine.seal(("test.typo", *RULE_ORDER))          # evaluated first
    monkeypatch.setenv(check_data.STRICT_ENV, "0")
    rules = [f.rule for f in advisor.advise(healthy_laptop(), laptop_settings())]
    assert "test.typo" not in rules and "table1.open" in rules, rules


def test_findings_by_check_the_first_failure_and_the_short_json(registry):
    _hit_rule("test.w", severity="warn", hits=[Hit("w", ["x"], check_ids=["ros.env"])])
    _hit_rule("test.f1", hits=[Hit("f1", ["y"], check_ids=["ros.env", "ros.master"])])
    _hit_rule("test.f2", hits=[Hit("f2", ["z"], check_ids=["ros.master"])])
    fs = _ours(("test.w", "test.f1", "test.f2"))
    by = engine.advice_by_check(fs)
    assert {c: [f.meaning for f in v] for c, v in by.items()} == {
        "ros.env": ["f1", "w"], "ros.master": ["f1", "f2"]}
    assert engine.first_failure(fs).meaning == "f1"
    assert engine.first_failure([f for f in fs if f.severity == "warn"]) is None
    assert fs[0].to_json() == {"rule": "test.f1", "meaning": "f1", "actions": ["y"],
                               "goto_step": "ros"}
