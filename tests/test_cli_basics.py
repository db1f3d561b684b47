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


def test_help_summaries_match_each_commands_own_help():
    """--help lists every command without importing it; the summaries must not drift."""
    import argparse

    from rosnet_tui.cli import SUBCOMMAND_HELP, build_parser

    parser = build_parser(None)  # every module registers its own parser
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    own = {c.dest: c.help for c in sub._choices_actions}
    assert own == {name.replace("_", "-"): text for name, text in SUBCOMMAND_HELP.items()}


def test_wizard_start_does_not_import_the_subcommands():
    # cli.common (exit codes, --config) is what the parser itself needs; no sub-command module.
    code = ("import sys\nfrom rosnet_tui.cli import build_parser\n"
            "build_parser(['--config', 'x.toml']).parse_args(['--config', 'x.toml'])\n"
            "loaded = [m for m in sys.modules if m.startswith('rosnet_tui.cli.')\n"
            "          and m != 'rosnet_tui.cli.common']\n"
            "print(loaded)\nsys.exit(1 if loaded else 0)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stdout + out.stderr


def test_the_launchers_run_leaves_what_it_made_out_of_the_last_collection():
    """The process ends after the launcher's main(): its objects are frozen (gc.freeze), so the
    interpreter's exit does not collect them one by one (about 30 ms of every round's exit,
    bench row 2); main() with arguments, as tests and the wizard's callers use it, does not."""
    code = ("import atexit, gc, sys\n"
            "from rosnet_tui.cli import main\n"
            "atexit.register(lambda: print('FROZEN', gc.get_freeze_count() > 0))\n"
            "main(['--version'] if sys.argv[1] == 'args' else None)\n")
    for how, frozen in (("launcher", True), ("args", False)):
        r = subprocess.run([sys.executable, "-c", code, how], capture_output=True, text=True,
                           timeout=60, stdin=subprocess.DEVNULL)
        if how == "launcher":       # sys.argv[1:] is ['launcher']: an unknown command, exit 2
            assert r.returncode == 2, r.stderr
        assert f"FROZEN {frozen}" in r.stdout, (how, r.stdout, r.stderr)
