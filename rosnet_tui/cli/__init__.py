"""Command line: `rosnet-tui` opens the wizard; sub-commands run the same core headless.

Each sub-command lives in its own module exposing ``register(subparsers)``; it sets ``func`` on
its parser, a callable ``func(args) -> int`` (the exit code). Exit codes: 0 fine, 1 a check or an
action failed, 2 usage or settings error.
"""

from __future__ import annotations

import argparse
import importlib
import math
import os
import re
import stat
import sys
from pathlib import Path

from rosnet_tui import __version__

EXIT_OK, EXIT_FAIL, EXIT_USAGE = 0, 1, 2

# Sub-command modules, in the order --help lists them.
SUBCOMMAND_MODULES = ("check", "hosts", "ros", "router", "firewall", "undo", "report", "sync",
                      "probe_server")
# What `rosnet-tui --help` says of each without importing it (a test keeps these equal to the
# modules' own help): only the command being run is imported, so start-up stays light.
SUBCOMMAND_HELP = {
    "check": "run the live checks headless and print what they saw",
    "hosts": "write this component's hosts set into /etc/hosts",
    "ros": "write ROS_MASTER_URI for this component's role into ~/.bashrc",
    "router": "let the modem forward this component's port itself (UPnP IGD, NAT-PMP, PCP)",
    "firewall": "ROS 1: let only the peers reach the forwarded ports",
    "undo": "restore the files of the last change rosnet-tui made",
    "report": "write a shareable report: settings, results and advice",
    "sync": "keep hosts entries and ROS_MASTER_URI right when public IPs change (a service)",
    "probe_server": "run your own what-is-my-IP and port-check service (echoip-compatible)",
}


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # argparse's default, with a hint
        self.print_usage(sys.stderr)
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message}\n"
                              f"Try '{self.prog} --help' for more.\n")


_DECIMAL = re.compile(r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?")
_WHOLE = re.compile(r"[+-]?\d{1,18}")


def number_in(lo: float, hi: float, *, whole: bool = False):
    """An argparse type: a plain decimal number (a whole one with *whole*) from *lo* to *hi*.

    NaN, infinities, hexadecimal, digit separators and values out of range are refused, so
    argparse exits 2 naming the option. Say the range in the option's help (``lo-hi``)."""
    def convert(text: str) -> float | int:
        t = text.strip()
        if not (_WHOLE if whole else _DECIMAL).fullmatch(t):
            raise argparse.ArgumentTypeError(
                f"'{text[:40]}' is not {'a whole number' if whole else 'a number'} "
                f"(from {lo:g} to {hi:g})")
        value: float | int = int(t) if whole else float(t)
        if not math.isfinite(value) or not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"{text[:40]} is out of range: from {lo:g} to "
                                             f"{hi:g}")
        return value
    convert.__name__ = "whole number" if whole else "number"
    return convert


def state_dir_problem(path: Path) -> str | None:
    """Why *path* cannot be a state dir (None: it can, or it does not exist yet)."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return None
    except NotADirectoryError:
        return f"--state-dir {path}: a part of this path is a file, not a folder"
    except OSError as exc:
        return f"--state-dir {path}: {exc.strerror}"
    if not stat.S_ISDIR(st.st_mode):
        return f"--state-dir {path} is not a folder"
    return None


def add_config_option(parser: argparse.ArgumentParser, *, top: bool = False) -> None:
    parser.add_argument(
        "--config", metavar="FILE", type=Path,
        default=None if top else argparse.SUPPRESS,
        help="settings file (default: $XDG_CONFIG_HOME/rosnet-tui/config.toml)")


def _wanted(argv: list[str] | None) -> set[str]:
    """The sub-commands *argv* may run (None: all of them, e.g. to test every parser)."""
    if argv is None:
        return set(SUBCOMMAND_MODULES)
    names = {m.replace("_", "-"): m for m in SUBCOMMAND_MODULES}
    return {names[a] for a in argv if a in names}


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    parser = _Parser(
        prog="rosnet-tui",
        description="Put a robot and its operators on one ROS network across the internet, by "
                    "port forwarding, and prove that it works. With no command, opens the wizard.",
        epilog="Exit codes: 0 all good, 1 a check or action failed, 2 usage or settings error.")
    parser.add_argument("--version", action="version", version=f"rosnet-tui {__version__}")
    add_config_option(parser, top=True)
    parser.add_argument("--setup", action="store_true",
                        help="open the wizard on the set-up screen even when settings are complete")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    wanted = _wanted(argv)
    for name in SUBCOMMAND_MODULES:
        if name in wanted:
            importlib.import_module(f"rosnet_tui.cli.{name}").register(sub)
        else:  # listed in --help; its module is imported only when it runs
            sub.add_parser(name.replace("_", "-"), help=SUBCOMMAND_HELP[name], add_help=False)
    return parser


def config_path(args: argparse.Namespace) -> Path:
    from rosnet_tui.core.settings import default_config_path

    return Path(args.config).expanduser() if getattr(args, "config", None) else default_config_path()


def say(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def load_settings_or_say(args: argparse.Namespace, *, complete: bool = False):
    """The settings named by --config (Settings), or None after saying why on stderr.

    With *complete*, blank local IP and interface are filled in from this machine for this run,
    and settings that are still incomplete are refused (the caller exits 2).
    """
    from rosnet_tui.core.netinfo import with_detected
    from rosnet_tui.core.settings import SettingsError, load_settings

    path = config_path(args)
    try:
        settings = load_settings(path)
    except SettingsError as exc:
        say(f"rosnet-tui: the settings file cannot be used: {exc}")
        return None
    if settings is None:
        say(f"rosnet-tui: no settings file at {path}; run 'rosnet-tui' (the wizard) first, "
            "or pass --config FILE")
        return None
    if not complete:
        return settings
    settings = with_detected(settings)
    problems = settings.problems()
    if problems:
        say(f"rosnet-tui: the settings in {path} are not complete:")
        for key, why in problems:
            say(f"  {key}: {why}")
        say("Fix them by hand or with the wizard (rosnet-tui --setup).")
        return None
    return settings


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv:  # the wizard, as most people start it: no parser to build
        from rosnet_tui.cli.wizard import run_wizard

        return run_wizard(argparse.Namespace(config=None, setup=False, command=None))
    parser = build_parser(argv)
    args = parser.parse_args(argv)
    if args.command is None:
        from rosnet_tui.cli.wizard import run_wizard

        return run_wizard(args)
    try:
        return int(args.func(args))
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
