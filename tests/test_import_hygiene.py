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
