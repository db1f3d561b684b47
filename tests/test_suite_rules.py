"""Rules the suite keeps about itself (issue 36): a missing or broken dependency fails, it is
never turned into skips. Every module the tests import is a dependency pyproject.toml declares
(the product's or the test extra's), so the tests import it plainly: no ``pytest.importorskip``,
no ``except ImportError: pytest.skip(...)``. Read from the source, so a new test file is covered
the day it is added."""

from __future__ import annotations

import ast
from pathlib import Path

TESTS = Path(__file__).resolve().parent
IMPORT_ERRORS = {"ImportError", "ModuleNotFoundError"}


def _name(node: ast.AST) -> str:
    if isinstance(node, ast.Attribute):
        return node.attr
    return node.id if isinstance(node, ast.Name) else ""


def _skips(body: list[ast.stmt]) -> bool:
    return any(isinstance(n, ast.Call) and _name(n.func) in ("skip", "importorskip")
               for stmt in body for n in ast.walk(stmt))


def offences(source: str) -> list[int]:
    """Lines of *source* that turn a missing module into a skip."""
    out = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Call) and _name(node.func) == "importorskip":
            out.append(node.lineno)
        elif isinstance(node, ast.ExceptHandler) and node.type is not None:
            caught = node.type.elts if isinstance(node.type, ast.Tuple) else [node.type]
            if {_name(c) for c in caught} & IMPORT_ERRORS and _skips(node.body):
                out.append(node.lineno)
    return sorted(out)


def test_the_rule_finds_both_forms():
    assert offences("import pytest\nz = pytest.importorskip('zenoh')\n") == [2]
    assert offences("import pytest\ntry:\n    import zenoh\n"
                    "except (OSError, ImportError):\n    pytest.skip('no zenoh')\n") == [4]
    assert offences("try:\n    import pyte\nexcept ImportError:\n    pyte = None\n") == []


def test_no_test_turns_a_missing_dependency_into_a_skip():
    found = {str(p.relative_to(TESTS)): lines for p in sorted(TESTS.rglob("*.py"))
             if p.name != Path(__file__).name and (lines := offences(p.read_text()))}
    assert found == {}, f"declare the module in pyproject.toml and import it plainly: {found}"
