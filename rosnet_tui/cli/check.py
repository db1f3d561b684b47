"""`rosnet-tui check`: run the live checks headless, print a table (or JSON), exit 0/1/2.

Progress lines go to stderr as results land; the verdicts go to stdout in the registry's order,
so the output is the same however the concurrent checks happened to finish.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from rosnet_tui.cli import warm
from rosnet_tui.cli.common import (
    EXIT_FAIL,
    EXIT_OK,
    EXIT_USAGE,
    add_config_option,
    load_settings_or_say,
    number_in,
    preload_settings,
)
from rosnet_tui.core.procedure import STEP_IDS

_STYLES = {"pass": "green", "warn": "yellow", "fail": "bold red", "skip": "dim"}


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "check", help="run the live checks headless and print what they saw",
        description="Run each step's live checks (concurrently, each under its timeout) and print "
                    "the verdicts: a table, or JSON with --json. Progress goes to stderr.",
        epilog="Exit codes: 0 no check failed, 1 a check failed, 2 usage or settings error.")
    p.add_argument("--step", action="append", choices=STEP_IDS, metavar="STEP",
                   help=f"only this step's checks ({'|'.join(STEP_IDS)}); repeatable; "
                        "default: every step")
    p.add_argument("--json", action="store_true",
                   help='print {"checks": [...]} as JSON instead of a table')
    add_config_option(p)
    p.add_argument("--timeout", type=number_in(0.1, 120), metavar="S", default=None,
                   help="seconds each check may take, 0.1-120 (default: checks.timeout_s in "
                        "the settings)")
    p.add_argument("--no-upnp", action="store_true",
                   help="do not ask the modem over UPnP (isp.cgnat then relies on the path probe)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress lines on stderr")
    p.set_defaults(func=run)


def _err(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def run(args: argparse.Namespace) -> int:
    timeout = args.timeout
    settings = load_settings_or_say(args, complete=True)
    if settings is None:
        return EXIT_USAGE
    steps = list(dict.fromkeys(args.step)) if args.step else None
    ordered = collect_results(settings, steps, timeout=timeout, upnp=not args.no_upnp,
                              progress=not args.quiet)
    results = {r.id: r for r in ordered}
    advice = _advice(results, settings)
    failed = any(r.status.value == "fail" for r in ordered)
    if args.json:
        out = []
        for r in ordered:
            entry = r.to_json()
            entry["advice"] = [f.to_json() for f in advice if r.id in f.check_ids]
            out.append(entry)
        sys.stdout.write(json.dumps({"checks": out}, indent=2, default=str) + "\n")
        sys.stdout.flush()
    else:
        _print_table(ordered, advice)
    warm.after_run(settings.checks.keep_warm_s)
    return EXIT_FAIL if failed else EXIT_OK


def preload() -> None:
    """Import what :func:`run` imports as it goes (for the warm process, :mod:`.warm`)."""
    import rich.console
    import rich.markup
    import rich.table  # noqa: F401

    from rosnet_tui.core.advisor import advise  # noqa: F401
    from rosnet_tui.core.checks.runner import preload as preload_round

    preload_settings()
    preload_round()


def collect_results(settings: Any, steps: list[str] | None = None, *, timeout: float | None = None,
                    upnp: bool = True, progress: bool = False) -> list:
    """Run the checks of *steps* (all when None) concurrently; results in registry order.

    The one way the headless commands (check, report) run checks; *progress* prints each
    verdict to stderr as it lands.
    """
    from rosnet_tui.core.checks.runner import RunOptions, prestart_ssh, run_now, select

    def say(r: Any, done: int, total: int) -> None:
        _err(f"[{done}/{total}] {r.status.label:<4} {r.id}: {r.summary}")

    # The SSH connections to the peers start now, while the checks are being imported.
    options = prestart_ssh(settings, RunOptions(timeout_s=timeout, upnp=upnp), steps)
    return run_now(settings, select(steps, settings=settings), options,
                   on_result=say if progress else None)


def _advice(results: dict, settings: Any) -> list:
    try:
        from rosnet_tui.core.advisor import advise

        return list(advise(results, settings))
    except Exception as exc:  # the verdicts matter more than the advice
        _err(f"(no advice: the advisor failed: {type(exc).__name__}: {exc})")
        return []


def _print_table(ordered: list, advice: list) -> None:
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    console = Console(highlight=False, soft_wrap=False)
    table = Table(show_header=True, header_style="bold", expand=False, show_lines=False)
    table.add_column("Status", no_wrap=True)
    table.add_column("Check", no_wrap=True)
    table.add_column("What was seen", overflow="fold")
    for r in ordered:
        st = r.status.value
        text = escape(r.summary)
        if st != "pass" and r.evidence:
            text += "\n" + "\n".join(f"[dim]  {escape(e)}[/dim]" for e in r.evidence)
        for f in advice:
            if r.id in f.check_ids and st in ("fail", "warn"):
                text += f"\n[bold]-> {escape(f.meaning)}[/bold]"
                for a in f.actions:
                    text += f"\n   - {escape(a)}"
        table.add_row(f"[{_STYLES[st]}]{r.status.label}[/]", r.id, text)
    console.print(table)
    counts = {s: sum(1 for r in ordered if r.status.value == s) for s in _STYLES}
    console.print(", ".join(f"{n} {s}" for s, n in counts.items() if n) or "no checks ran")
