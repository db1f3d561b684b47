"""Command line: `rosnet-tui` opens the wizard; sub-commands run the same core headless.

Each sub-command lives in its own module exposing ``register(subparsers)``; it sets ``func`` on
its parser, a callable ``func(args) -> int`` (the exit code). Exit codes: 0 fine, 1 a check or an
action failed, 2 usage or settings error. What the commands share is in :mod:`.common` (exit codes,
options, settings loading) and :mod:`.writing` (the preview, ask and write flow of the writers).
"""

from __future__ import annotations

import argparse
import gc
import importlib
import sys

from rosnet_tui import __version__
from rosnet_tui.cli.common import EXIT_USAGE, add_config_option, complete_cut_writes

# Sub-command modules, in the order --help lists them.
SUBCOMMAND_MODULES = ("check", "hosts", "ros", "router", "firewall", "undo", "report", "sync",
                      "relay", "probe_server")
# What `rosnet-tui --help` says of each without importing it (a test keeps these equal to the
# modules' own help): only the command being run is imported, so start-up stays light.
SUBCOMMAND_HELP = {
    "check": "run the live checks headless and print what they saw",
    "hosts": "write this component's hosts set into /etc/hosts",
    "ros": "write the ROS environment for this component's role (ROS 1 or 2) into ~/.bashrc",
    "router": "let the modem forward this component's port itself (UPnP IGD, NAT-PMP, PCP)",
    "firewall": "ROS 1: let only the peers reach the forwarded ports",
    "undo": "take back the last change rosnet-tui made: files, firewall or modem forwards",
    "report": "write a shareable report: settings, results and advice",
    "sync": "keep hosts entries (and ROS 1's ROS_MASTER_URI) right when public IPs change; "
            "renew forwards and certificates (a service)",
    "relay": "ROS 2 across carrier NAT: the relay's Zenoh router every component dials out to",
    "probe_server": "run your own what-is-my-IP and port-check service (echoip-compatible)",
}

# The commands a warm process runs (rosnet_tui.cli.warm): a re-run of the checks.
WARM_COMMANDS = ("check",)


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # argparse's default, with a hint
        self.print_usage(sys.stderr)
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message}\n"
                              f"Try '{self.prog} --help' for more.\n")


def _wanted(argv: list[str] | None) -> set[str]:
    """The sub-command *argv* runs: its first word that is not an option (nor --config's file);
    None: all of them, e.g. to test every parser. (Any word once counted: `check --step router`
    imported the router command and the modem's protocols.)"""
    if argv is None:
        return set(SUBCOMMAND_MODULES)
    names = {m.replace("_", "-"): m for m in SUBCOMMAND_MODULES}
    words = iter(argv)
    for a in words:
        if a == "--config":
            next(words, None)
        elif not a.startswith("-"):
            return {names[a]} if a in names else set()
    return set()


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


def main(argv: list[str] | None = None) -> int:
    """The command line; *argv* None: this process's own (the launcher's), and then the process
    ends after it, so what it made is left out of the interpreter's last garbage collection
    (``gc.freeze``: a round of checks made some hundred thousand objects, and collecting them at
    exit took about 30 ms of every run; files are closed and atexit handlers run as before)."""
    if argv is not None:
        return _main(list(argv))
    argv = sys.argv[1:]
    try:
        if argv[:1] and argv[0] in WARM_COMMANDS:   # run by the warm process a last run left
            from rosnet_tui.cli import warm

            if warm.enabled():
                code = warm.run_through(argv)
                if code is not None:
                    return code
        return _main(argv)
    finally:
        gc.freeze()


def serve_warm(argv: list[str]) -> int:
    """The warm process (:mod:`.warm`): serves `rosnet-tui check` by :func:`main`."""
    from rosnet_tui.cli import warm

    return warm.main(argv, run=main, preload=preload_warm)


def preload_warm() -> None:
    """Import what a run of the warm process's commands imports."""
    from rosnet_tui.cli.check import preload as preload_check

    build_parser(list(WARM_COMMANDS))
    preload_check()


def _main(argv: list[str]) -> int:
    complete_cut_writes(argv)   # a write a killed run left half done, before anything reads
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
