"""The advisor's engine: rules as data, the registry, and :func:`advise` that applies them.

A rule (:class:`Rule`) has a stable id, the condition in words, a generic meaning and action
(docs/TROUBLESHOOTING.md), the step to go back to, a severity, the check ids it explains, and a
predicate over :class:`~rosnet_tui.core.advisor.evidence.Evidence` that returns concrete
:class:`Hit` objects. The step modules (isp, router, linux, ros) declare theirs with :func:`rule`.

Nothing here depends on the order in which rules are declared or modules imported:

- the order findings are listed in (and the docs, and ``--ids``) is :data:`RULE_ORDER` in
  :mod:`.order`, every rule named exactly once;
- a rule that reads whether other rules fired names them in ``after=(...)``: the engine
  evaluates those first (a topological order, ties broken by :data:`RULE_ORDER`) and refuses
  reads of any other rule's firing;
- ``superseded_by`` drops a rule's findings when one of the named rules fired (applied after
  all rules ran).

:func:`seal` (called when the package is imported) checks all of it and fails loudly on an
unknown id, a rule without a place in the order, or a cycle.
"""

from __future__ import annotations

import heapq
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field

from rosnet_tui.core.advisor.evidence import Evidence, RuleOrderError, status_of
from rosnet_tui.core.checks import data as check_data
from rosnet_tui.core.config.settings_model import Settings
from rosnet_tui.core.procedure import SEVERITIES, STEP_IDS, step_title
from rosnet_tui.core.results import CheckResult, Status

__all__ = ["CATCH_ALL_IDS", "CATCH_ALL_RULES", "RULES", "Finding", "Hit", "Rule", "RuleOrderError",
           "advice_by_check", "advise", "all_rules", "first_failure", "rule", "rule_by_id", "seal"]


@dataclass
class Finding:
    rule: str                  # stable rule id, e.g. "table1.listener_up_closed.forwarding"
    meaning: str               # what it means
    actions: list[str]         # what to do, concrete
    goto_step: str | None      # "isp" | "router" | "linux" | "ros" | None
    check_ids: list[str] = field(default_factory=list)  # the checks this finding explains
    severity: str = "fail"     # "fail" | "warn" | "info" | "security"
    order: int = 0             # rank among several possible causes (0 = most likely)
    condition: str = ""        # the rule's condition in words (the Table-1 "condition" column)
    evidence: list[str] = field(default_factory=list)  # the facts from the results that fired it

    def to_json(self) -> dict:
        return {"rule": self.rule, "meaning": self.meaning, "actions": list(self.actions),
                "goto_step": self.goto_step}

    def to_dict(self) -> dict:
        """Every field (the report's JSON form)."""
        return {"rule": self.rule, "severity": self.severity, "condition": self.condition,
                "meaning": self.meaning, "actions": list(self.actions),
                "goto_step": self.goto_step, "check_ids": list(self.check_ids),
                "order": self.order, "evidence": list(self.evidence)}


@dataclass
class Hit:
    """What a rule's predicate returns for one match; unset fields fall back to the rule's."""

    meaning: str
    actions: list[str]
    check_ids: list[str] | None = None
    severity: str | None = None
    goto_step: str | None = "-"        # "-" = the rule's goto_step
    order: int = 0
    evidence: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class Rule:
    id: str
    step: str                  # the step of the symptom (sort order: procedure order)
    check_ids: tuple[str, ...]  # the checks it reads and explains
    condition: str             # the condition in words
    meaning: str               # the generic meaning (docs / full table)
    action: str                # the generic action (docs / full table)
    goto_step: str | None
    severity: str
    evaluate: Callable[[Evidence], list[Hit]]
    group: str | None = None   # rules of one group (Table 1's causes) are ranked together
    superseded_by: tuple[str, ...] = ()  # drop this rule's hits when one of these fired
    after: tuple[str, ...] = ()  # rules whose firing it reads (ev.fired_any): evaluated first

    def row(self) -> dict:
        """The rule as a table row (the TUI's full-table view, the docs)."""
        return {"id": self.id, "step": self.step, "condition": self.condition,
                "meaning": self.meaning, "action": self.action, "goto_step": self.goto_step,
                "severity": self.severity, "check_ids": list(self.check_ids)}


# --------------------------------------------------------------------------- the registry
_REGISTRY: dict[str, Rule] = {}
# Every rule, in RULE_ORDER (filled by seal()): display order, docs order, tie-break.
RULES: list[Rule] = []
_EVAL_ORDER: list[Rule] = []          # RULES in dependency order (``after`` first)
_POS: dict[str, int] = {}             # rule id -> its sort position (a group shares its first)


def rule(id: str, step: str, checks: tuple[str, ...], condition: str, meaning: str, action: str,
         goto: str | None, severity: str, group: str | None = None,
         superseded_by: tuple[str, ...] = (), after: tuple[str, ...] = ()
         ) -> Callable[[Callable], Callable]:
    """Declare a rule; its place in the listings is given by RULE_ORDER, not by this call."""
    if severity not in SEVERITIES:
        raise ValueError(severity)
    if step not in STEP_IDS:
        raise ValueError(f"rule {id}: unknown step {step!r}")

    def deco(fn: Callable[[Evidence], list[Hit]]) -> Callable[[Evidence], list[Hit]]:
        if id in _REGISTRY or id in CATCH_ALL_IDS:
            raise RuleOrderError(f"rule {id} is declared twice")
        _REGISTRY[id] = Rule(id, step, checks, condition, meaning, action, goto, severity, fn,
                             group, tuple(superseded_by), tuple(after))
        return fn

    return deco


def seal(order: Iterable[str]) -> None:
    """Check the declared rules against *order* and their dependencies; fix the orders.

    Raises :class:`RuleOrderError` on a rule missing from *order* (or listed twice, or listed
    but not declared), an unknown id in ``after``/``superseded_by``, or a cycle.
    """
    order = list(order)
    dupes = sorted({i for i in order if order.count(i) > 1})
    missing = sorted(set(_REGISTRY) - set(order))
    unknown = sorted(set(order) - set(_REGISTRY))
    if dupes or missing or unknown:
        raise RuleOrderError(
            "RULE_ORDER must name every declared rule once: "
            + "; ".join(f"{what}: {', '.join(ids)}" for what, ids in
                        (("listed twice", dupes), ("not listed", missing),
                         ("listed, not declared", unknown)) if ids))
    for r in _REGISTRY.values():
        for kind, ids in (("after", r.after), ("superseded_by", r.superseded_by)):
            bad = [i for i in ids if i not in _REGISTRY or i == r.id]
            if bad:
                raise RuleOrderError(f"rule {r.id}: {kind} names unknown rule(s) {', '.join(bad)}")
    rank = {rid: i for i, rid in enumerate(order)}
    _acyclic({r.id: r.superseded_by for r in _REGISTRY.values()}, rank, "superseded_by")
    evaluation = _acyclic({r.id: r.after for r in _REGISTRY.values()}, rank, "after")
    RULES[:] = [_REGISTRY[i] for i in order]
    _EVAL_ORDER[:] = [_REGISTRY[i] for i in evaluation]
    first_of: dict[str, int] = {}
    _POS.clear()
    for i, r in enumerate(RULES):
        _POS[r.id] = first_of.setdefault(r.group or r.id, i)


def _acyclic(deps: dict[str, tuple[str, ...]], rank: dict[str, int], kind: str) -> list[str]:
    """A topological order of *deps* (each id after the ids it names), ties by *rank*."""
    waiting = {rid: set(ds) for rid, ds in deps.items()}
    users: dict[str, list[str]] = {rid: [] for rid in deps}
    for rid, ds in deps.items():
        for d in ds:
            users[d].append(rid)
    ready = [(rank[rid], rid) for rid, ds in waiting.items() if not ds]
    heapq.heapify(ready)
    out: list[str] = []
    while ready:
        _, rid = heapq.heappop(ready)
        out.append(rid)
        for u in users[rid]:
            waiting[u].discard(rid)
            if not waiting[u]:
                heapq.heappush(ready, (rank[u], u))
    if len(out) != len(deps):
        stuck = sorted(set(deps) - set(out), key=rank.__getitem__)
        raise RuleOrderError(f"{kind} forms a cycle among: {', '.join(stuck)}")
    return out


# --------------------------------------------------------------------------- catch-alls
CATCH_ALL_IDS = ("check.no_verdict", "check.unexplained")
CATCH_ALL_RULES = [
    Rule("check.no_verdict", "-", (), "a check ran out of time or crashed",
         "The check gave no verdict (it timed out or stopped on an error), so no rule can read it.",
         "Re-run the step; on a slow link raise timeout_s under [checks].", None, "fail",
         lambda ev: []),
    Rule("check.unexplained", "-", (), "a check failed or warned and no rule explains it",
         "No rule recognises this case; the check's own summary and evidence say what was seen.",
         "Read the check's evidence and re-run its step.", None, "fail", lambda ev: []),
]


def _catch_all(ev: Evidence, explained: set[str]) -> list[Finding]:
    out: list[Finding] = []
    for cid, r in ev.results.items():
        st = status_of(r)
        if st not in (Status.FAIL, Status.WARN) or cid in explained:
            continue
        sev = "fail" if st is Status.FAIL else "warn"
        step = r.step if r.step in STEP_IDS else None
        if not r.data and ("timed out" in r.summary or "unexpectedly" in r.summary):
            rl = CATCH_ALL_RULES[0]
            meaning = f"{cid} did not finish: {r.summary}."
            acts = [f"Re-run {step_title(step)}." if step else "Re-run the check.",
                    f"On a slow or lossy link, raise timeout_s under [checks] (now "
                    f"{r.timeout_s:g} s for this check)."]
        else:
            rl = CATCH_ALL_RULES[1]
            meaning = f"{cid}: {r.summary}"
            acts = [f"Read the evidence of {cid}; fix what it shows, then re-run "
                    f"{step_title(step)}." if step else f"Read the evidence of {cid}."]
        out.append(Finding(rl.id, meaning, acts, step, [cid], sev, 0, rl.condition,
                           list(r.evidence[:3])))
    return out


# --------------------------------------------------------------------------- advise
_SEV_RANK = {s: i for i, s in enumerate(SEVERITIES)}


def _sort_key(f: Finding, pos: dict[str, int], steps: dict[str, str]) -> tuple:
    step = steps.get(f.rule) or f.goto_step or ""
    return (_SEV_RANK.get(f.severity, 9),
            STEP_IDS.index(step) if step in STEP_IDS else len(STEP_IDS),
            pos.get(f.rule, len(pos)), f.order)


def _supersede(by_rule: dict[str, list[Finding]]) -> list[Finding]:
    """The findings of the rules not superseded, in RULE_ORDER.

    A superseded rule's findings are dropped, not the checks they explained: a check that no
    kept finding names goes to the first kept finding of the rule that superseded it (a more
    specific account of the same failure), so it never ends up with no advice at all.
    """
    def dropped(rid: str) -> bool:
        return any(s in by_rule for s in _REGISTRY[rid].superseded_by)

    def heir(rid: str) -> str | None:         # acyclic: seal() checked superseded_by
        for s in _REGISTRY[rid].superseded_by:
            if s in by_rule:
                h = s if not dropped(s) else heir(s)
                if h is not None:
                    return h
        return None

    kept = [f for rl in RULES if rl.id in by_rule and not dropped(rl.id) for f in by_rule[rl.id]]
    explained = {c for f in kept for c in f.check_ids}
    for rl in RULES:
        if rl.id not in by_rule or not dropped(rl.id):
            continue
        lost = [c for f in by_rule[rl.id] for c in f.check_ids if c not in explained]
        h = heir(rl.id)
        if lost and h is not None:
            target = by_rule[h][0]
            target.check_ids.extend(dict.fromkeys(c for c in lost if c not in target.check_ids))
            explained.update(lost)
    return kept


def advise(results: Mapping[str, CheckResult] | Iterable[CheckResult], settings: Settings,
           *, strict: bool = False) -> list[Finding]:
    """All findings that apply to *results*, most important first.

    Order: failures, then warnings, security findings, information; within each, the
    procedure's step order (ISP before Router before Linux before ROS), RULE_ORDER, and for
    competing causes (Table 1) the order the evidence gives. A rule that trips over malformed
    data is skipped (``strict=True`` raises instead, for tests). A rule that reads a key its
    check does not declare raises when ``strict`` or :func:`checks.data.strict` (the test
    suite) is on, and is skipped otherwise.
    """
    if not isinstance(results, Mapping):
        results = {r.id: r for r in results}
    ev = Evidence(results, settings)
    strict_data = strict or check_data.strict()
    by_rule: dict[str, list[Finding]] = {}
    for rl in _EVAL_ORDER:
        ev._reading = (rl.id, rl.after)
        try:
            hits = rl.evaluate(ev) or []
        except RuleOrderError:
            raise                       # a wrong declaration, never data: always loud
        except check_data.UndeclaredKeyError:
            if strict_data:
                raise
            continue
        except Exception:
            if strict:
                raise
            continue
        finally:
            ev._reading = None
        if hits:
            ev._fired.add(rl.id)
            by_rule[rl.id] = [
                Finding(rl.id, h.meaning, list(h.actions),
                        rl.goto_step if h.goto_step == "-" else h.goto_step,
                        list(h.check_ids if h.check_ids is not None else rl.check_ids),
                        h.severity or rl.severity, h.order, rl.condition, list(h.evidence))
                for h in hits]
    findings = _supersede(by_rule)
    explained = {c for f in findings for c in f.check_ids}
    findings.extend(_catch_all(ev, explained))
    steps = {rl.id: rl.step for rl in RULES}
    findings.sort(key=lambda f: _sort_key(f, _POS, steps))
    return findings


def advice_by_check(findings: Iterable[Finding]) -> dict[str, list[Finding]]:
    """The findings each check id should carry (``check --json``'s "advice")."""
    out: dict[str, list[Finding]] = {}
    for f in findings:
        for cid in f.check_ids:
            out.setdefault(cid, []).append(f)
    return out


def first_failure(findings: Iterable[Finding]) -> Finding | None:
    return next((f for f in findings if f.severity == "fail"), None)


def all_rules() -> list[Rule]:
    """Every rule, in RULE_ORDER, catch-alls last (the TUI's full-table view, --ids)."""
    return [*RULES, *CATCH_ALL_RULES]


def rule_by_id(rule_id: str) -> Rule | None:
    return next((r for r in all_rules() if r.id == rule_id), None)
