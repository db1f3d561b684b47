"""The command line: --help, --version, usage errors, and the wizard's refusals."""

from __future__ import annotations

import subprocess
import sys

from rosnet_tui import __version__


def run(*args: str, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "rosnet_tui", *args], capture_output=True,
                          text=True, timeout=60, stdin=subprocess.DEVNULL, **kw)


def test_help_lists_the_commands():
    out = run("--help")
    assert out.returncode == 0
    for word in ("check", "probe-server", "--config", "--version"):
        assert word in out.stdout


def test_version():
    out = run("--version")
    assert out.returncode == 0 and __version__ in out.stdout


def test_unknown_argument_is_exit_2_with_a_hint():
    out = run("--frobnicate")
    assert out.returncode == 2
    assert "unrecognized arguments" in out.stderr and "--help" in out.stderr


def test_unknown_command_is_exit_2():
    assert run("frobnicate").returncode == 2


def test_malformed_settings_exit_2_naming_line_and_key(tmp_path):
    cfg = tmp_path / "c.toml"
    cfg.write_text('[this]\nname = "a b"\n')
    out = run("--config", str(cfg))
    assert out.returncode == 2
    assert "line 2" in out.stderr and "this.name" in out.stderr
    assert "Traceback" not in out.stderr
    assert cfg.read_text() == '[this]\nname = "a b"\n'


def test_wizard_without_a_terminal_says_so(tmp_path):
    out = run("--config", str(tmp_path / "c.toml"))
    assert out.returncode == 2 and "needs a terminal" in out.stderr
