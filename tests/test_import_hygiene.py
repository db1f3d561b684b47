"""The core never imports Textual: the CLI and the tests use it without a UI."""

from __future__ import annotations

import pkgutil
import subprocess
import sys

import rosnet_tui.core


def test_core_imports_no_textual():
    modules = [f"rosnet_tui.core.{m.name}" for m in pkgutil.walk_packages(
        rosnet_tui.core.__path__) if not m.name.startswith("_")]
    modules += ["rosnet_tui.core.checks"]
    code = (
        "import importlib, sys\n"
        f"mods = {modules!r}\n"
        "from rosnet_tui.core.checks import load_builtin_checks\n"
        "for m in mods: importlib.import_module(m)\n"
        "load_builtin_checks()\n"
        "bad = sorted(m for m in sys.modules if m == 'textual' or m.startswith('textual.'))\n"
        "print(bad)\n"
        "sys.exit(1 if bad else 0)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stdout + out.stderr


def test_headless_cli_does_not_load_textual():
    code = ("import sys\nfrom rosnet_tui.cli import build_parser\nbuild_parser()\n"
            "sys.exit(1 if 'textual' in sys.modules else 0)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr


ROOT = __import__("pathlib").Path(__file__).resolve().parents[1]


def test_layering_contracts_hold():
    """pyproject's [tool.importlinter] contracts: core apart from UI/CLI, rules apart from checks,
    check modules independent of each other."""
    import shutil

    exe = shutil.which("lint-imports")
    assert exe, "import-linter is a test dependency (pip install -e .[test])"
    out = subprocess.run([exe, "--config", str(ROOT / "pyproject.toml"), "--no-cache"],
                         capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert out.returncode == 0, out.stdout[-4000:] + out.stderr[-2000:]
    assert "0 broken" in out.stdout


# rosproto.py is one stdlib-only file on purpose: it is piped to peers over SSH as it is.
_SIZE_EXEMPT = {"rosnet_tui/core/peer/rosproto.py"}


def test_no_source_file_is_over_650_lines():
    big = {}
    for path in sorted((ROOT / "rosnet_tui").rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        n = len(path.read_text(encoding="utf-8").splitlines())
        if n > 650 and rel not in _SIZE_EXEMPT:
            big[rel] = n
    assert not big, f"split these files (600 lines is the aim, 650 the limit): {big}"
