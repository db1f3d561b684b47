"""Advisor rules read only what the checks declare (rosnet_tui/core/checks/data/).

Two guards, so a renamed key fails the ordinary test run instead of silently switching a rule
off: every rule runs over every golden input with undeclared reads made fatal (the declared view
raises UndeclaredKeyError, which advise() lets through in strict mode), and a static pass over
the rule modules checks every literal key read from ``ev.data("<check id>")``, also on paths no
test input reaches.
"""

from __future__ import annotations

import ast
import json
from pathlib import Path

import pytest

from rosnet_tui.core.advisor import advise
from rosnet_tui.core.checks import data as check_data
from tests.golden import codec, record

ADVISOR = Path(__file__).resolve().parents[1] / "rosnet_tui" / "core" / "advisor"
# Every advisor module that reads check data (rules, evidence, ranking), found by what it does so a
# new rule file is covered the day it is added.
RULE_FILES = tuple(sorted(p.name for p in ADVISOR.glob("*.py")
                          if ".data(" in p.read_text(encoding="utf-8")))


def _cases() -> list[dict]:
    return json.loads(record.INPUTS.read_text(encoding="utf-8"))["cases"]


def test_the_suite_runs_with_strict_data():
    assert check_data.strict(), "tests/conftest.py sets ROSNET_TUI_STRICT_DATA=1"


def test_no_rule_reads_an_undeclared_key_on_any_golden_input(monkeypatch):
    monkeypatch.setenv(check_data.STRICT_ENV, "1")
    malformed = []
    for c in _cases():
        results = codec.results_from_json(c["results"])
        settings = codec.settings_from_json(c["settings"])
        # Not strict: every rule runs (malformed data is skipped), undeclared reads still raise.
        advise(results, settings)
        try:
            advise(results, settings, strict=True)
        except (TypeError, AttributeError, ValueError, KeyError):
            malformed.append(c["case"])     # a wrong value type; UndeclaredKeyError is not one
    # only test_advise_accepts_a_list_and_survives_malformed_data's input has wrong types
    assert malformed and all("malformed" in m for m in malformed), malformed


def test_undeclared_reads_raise_only_in_strict_mode(monkeypatch):
    """What advise() does with UndeclaredKeyError: through when strict, skipped otherwise."""
    from rosnet_tui.core.advisor import engine
    from rosnet_tui.core.advisor.order import RULE_ORDER
    from tests.builders import healthy_laptop, laptop_settings

    def reads_a_typo(ev):
        return [engine.Hit("m", ["a"])] if ev.data("isp.internet").get("dns_okay") else []

    saved = dict(engine._REGISTRY)
    try:
        engine.rule("test.typo", "isp", ("isp.internet",), "c", "m", "a", "isp", "info")(
            reads_a_typo)
        engine.seal((*RULE_ORDER, "test.typo"))
        monkeypatch.setenv(check_data.STRICT_ENV, "1")
        with pytest.raises(check_data.UndeclaredKeyError, match="dns_okay"):
            advise(healthy_laptop(), laptop_settings())
        monkeypatch.setenv(check_data.STRICT_ENV, "0")
        with pytest.raises(check_data.UndeclaredKeyError):
            advise(healthy_laptop(), laptop_settings(), strict=True)
        fs = advise(healthy_laptop(), laptop_settings())       # in production: skipped
        assert "test.typo" not in [f.rule for f in fs] and "table1.open" in [f.rule for f in fs]
    finally:
        engine._REGISTRY.clear()
        engine._REGISTRY.update(saved)
        engine.seal(RULE_ORDER)


# --------------------------------------------------------------------------- static
def _data_call(node: ast.AST) -> str | None:
    """'isp.internet' for ``ev.data("isp.internet")`` (or ``self.data(...)``), else None."""
    if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
            and node.func.attr == "data" and isinstance(node.func.value, ast.Name)
            and node.func.value.id in ("ev", "self") and len(node.args) == 1
            and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)):
        return node.args[0].value
    return None


def _bindings(fn: ast.AST) -> dict[str, str]:
    """Names assigned from ``ev.data("<id>")`` in *fn* (only when every assignment agrees)."""
    seen: dict[str, set[str | None]] = {}

    def bind(target: ast.AST, value: ast.AST) -> None:
        if isinstance(target, ast.Name):
            seen.setdefault(target.id, set()).add(_data_call(value))
        elif isinstance(target, ast.Tuple):
            values = value.elts if isinstance(value, ast.Tuple) else []
            for i, t in enumerate(target.elts):
                bind(t, values[i] if len(values) == len(target.elts) else ast.Constant(None))

    for node in ast.walk(fn):
        if isinstance(node, ast.Assign):
            for t in node.targets:
                bind(t, node.value)
        elif isinstance(node, (ast.AnnAssign, ast.NamedExpr)) and node.value is not None:
            bind(node.target, node.value)
        elif isinstance(node, (ast.For, ast.comprehension)):
            bind(node.target, ast.Constant(None))
    return {n: next(iter(ids)) for n, ids in seen.items() if len(ids) == 1 and None not in ids}


def literal_reads(source: str, filename: str = "<rules>") -> list[tuple[str, str, str]]:
    """(check id, key, where) for every literal key read from a check's data in *source*."""
    out: list[tuple[str, str, str]] = []
    tree = ast.parse(source, filename)
    for fn in ast.walk(tree):
        if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        names = _bindings(fn)

        def cid_of(node: ast.AST, names=names) -> str | None:
            if isinstance(node, ast.Name):
                return names.get(node.id)
            return _data_call(node)

        for node in ast.walk(fn):
            key = cid = None
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                    and node.func.attr == "get" and node.args):
                cid, key = cid_of(node.func.value), node.args[0]
            elif isinstance(node, ast.Subscript):
                cid, key = cid_of(node.value), node.slice
            elif (isinstance(node, ast.Compare) and len(node.ops) == 1
                  and isinstance(node.ops[0], (ast.In, ast.NotIn))):
                cid, key = cid_of(node.comparators[0]), node.left
            if cid and isinstance(key, ast.Constant) and isinstance(key.value, str):
                out.append((cid, key.value, f"{filename}:{node.lineno} ({fn.name})"))
    return out


def test_the_static_reader_sees_every_form():
    src = '''
def rule(ev):
    a = ev.data("isp.internet").get("k1")
    b = ev.data("isp.internet")["k2"]
    d = ev.data("isp.cgnat")
    hd, rd = ev.data("linux.hosts"), ev.data("linux.resolve")
    if "k3" in d or "k4" not in rd:
        return d.get("k5"), d["k6"], hd.get("k7")
    x = ev.data(cid).get("dynamic")          # not a literal check id: not judged
'''
    got = {(c, k) for c, k, _ in literal_reads(src)}
    assert got == {("isp.internet", "k1"), ("isp.internet", "k2"), ("isp.cgnat", "k3"),
                   ("linux.resolve", "k4"), ("isp.cgnat", "k5"), ("isp.cgnat", "k6"),
                   ("linux.hosts", "k7")}


def test_every_literal_key_a_rule_reads_is_declared():
    reads = []
    for name in RULE_FILES:
        reads += literal_reads((ADVISOR / name).read_text(encoding="utf-8"), name)
    assert len(reads) >= 100, len(reads)      # the patterns still match the rules' style
    assert {c for c, _, _ in reads} == set(check_data.DATA)
    bad = [f"{where}: {cid} has no key {key!r}" for cid, key, where in reads
           if key not in check_data.declared_keys(cid)]
    assert not bad, "\n".join(bad)
