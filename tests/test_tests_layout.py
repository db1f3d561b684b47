"""The tests mirror the product (issue 23): one home for the builders, fixtures as conftest plugins,
the advisor's tests per step."""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent


def sources() -> dict[str, ast.Module]:
    return {p.relative_to(ROOT).as_posix(): ast.parse(p.read_text(encoding="utf-8"))
            for p in sorted(TESTS.rglob("*.py"))}


def top_level_defs(tree: ast.Module) -> set[str]:
    return {n.name for n in tree.body if isinstance(n, ast.FunctionDef | ast.ClassDef)}


@pytest.mark.parametrize("name", ["free_port", "laptop_settings", "robot_settings",
                                  "complete_settings", "healthy_laptop", "healthy_robot"])
def test_each_builder_is_defined_once_in_builders(name):
    homes = [path for path, tree in sources().items() if name in top_level_defs(tree)]
    assert homes == ["tests/builders.py"]


def test_no_fixture_is_imported_from_another_test_module():
    """Fixtures shared between modules are plugins (tests/conftest.py lists them)."""
    bad = []
    for path, tree in sources().items():
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("tests.test_"):
                module = importlib.import_module(node.module)
                bad += [f"{path}: {a.name} from {node.module}" for a in node.names
                        if hasattr(getattr(module, a.name, None), "_fixture_function_marker")]
    assert bad == []


def test_the_shared_fixtures_are_plugins():
    from tests import conftest

    for plugin in ("tests.plugins.ssh", "tests.plugins.roscore", "tests.plugins.web"):
        assert plugin in conftest.pytest_plugins


def test_the_advisor_has_a_test_module_per_step():
    from rosnet_tui.core.procedure import STEP_IDS

    for step in STEP_IDS:
        assert (TESTS / f"test_advisor_{step}.py").exists(), step
    assert not (TESTS / "test_advisor.py").exists()
