"""`rosnet-tui report`: its arguments, running the checks or reading saved results, and printing
the document :mod:`rosnet_tui.core.wizard.report` builds."""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from rosnet_tui.core.config.settings_model import Settings, SettingsError
from rosnet_tui.core.procedure import STEP_IDS
from rosnet_tui.core.results import CheckResult
from rosnet_tui.core.saved.settings import atomic_write_text
from rosnet_tui.core.wizard.report import (
    ReportError,
    build_report,
    load_results_json,
    render_json,
    render_markdown,
    ros_environment,
)

EXIT_OK, EXIT_FAIL, EXIT_USAGE = 0, 1, 2


# --------------------------------------------------------------------------- CLI
def register(sub: argparse._SubParsersAction) -> None:
    from rosnet_tui.cli.common import add_config_option

    p = sub.add_parser(
        "report", help="write a shareable report: settings, results and advice",
        description="Run the checks (or read a saved `rosnet-tui check --json`) and write a "
                    "report for the provider, the IT administrator or a colleague: this "
                    "component's settings (no secrets), every check's result and evidence, and "
                    "the advisor's findings with what to do.",
        epilog="Exit codes: 0 no check failed, 1 a check failed, 2 usage, settings or input "
               "error.")
    p.add_argument("--format", choices=("md", "json"), default="md",
                   help="Markdown (default; plain-text readable) or JSON")
    p.add_argument("-o", "--output", metavar="FILE", type=Path,
                   help="write the report to FILE (default: standard output)")
    add_config_option(p)
    p.add_argument("--step", choices=STEP_IDS, action="extend", nargs="+", metavar="STEP",
                   help="only these steps' checks: isp, router, linux, ros (default: all)")
    p.add_argument("--from-json", metavar="FILE", type=Path,
                   help="read results saved by `rosnet-tui check --json` (or a JSON report) "
                        "instead of running the checks; '-' reads standard input")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    try:
        doc = make_report(args)
    except ReportError as exc:
        print(f"rosnet-tui report: {exc}", file=sys.stderr)
        return EXIT_USAGE
    text = render_json(doc) if args.format == "json" else render_markdown(doc)
    # Text from a saved file may hold lone surrogates (JSON "\\ud800"): shown escaped.
    text = text.encode("utf-8", "backslashreplace").decode("utf-8")
    out: Path | None = getattr(args, "output", None)
    if out is None:
        sys.stdout.write(text)
    else:
        try:
            atomic_write_text(out.expanduser(), text)
        except OSError as exc:
            print(f"rosnet-tui report: cannot write {out}: {exc.strerror or exc}",
                  file=sys.stderr)
            return EXIT_USAGE
        print(f"report written to {out}", file=sys.stderr)
    return EXIT_FAIL if doc["summary"]["fail"] else EXIT_OK


def _load_settings(args: argparse.Namespace, *, required: bool) -> tuple[Settings | None, Path]:
    from rosnet_tui.cli.common import config_path
    from rosnet_tui.core.saved.settings import load_settings

    path = config_path(args)
    try:
        s = load_settings(path)
    except SettingsError as exc:
        raise ReportError(str(exc)) from None
    if s is None and required:
        raise ReportError(f"no settings file at {path}: run `rosnet-tui` to set up, or pass "
                          "--config FILE")
    return s, path


def make_report(args: argparse.Namespace) -> dict[str, Any]:
    """The report document (the JSON form) for *args*: live checks or a saved file."""
    steps = list(dict.fromkeys(args.step)) if getattr(args, "step", None) else None
    src: Path | None = getattr(args, "from_json", None)
    env: dict[str, str] | None = None
    if src is not None:
        results, saved_settings, meta = load_results_json(src)
        settings: Settings | None = None
        if getattr(args, "config", None) or saved_settings is None:
            settings, _ = _load_settings(args, required=False)
        if settings is None:
            settings = saved_settings
        if steps:
            results = [r for r in results if r.step in steps]
        source = f"results saved in {'standard input' if str(src) == '-' else src}"
        if meta.get("generated"):
            source += f" ({meta['generated']})"
        env = meta.get("environment")
    else:
        settings, path = _load_settings(args, required=True)
        assert settings is not None
        settings = complete_for_run(settings, path)
        results = run_checks_now(settings, steps)
        source = "checks run live on this machine"
        env = ros_environment(os.environ)
    known = settings is not None
    if settings is None:
        settings = Settings()
        source += "; no settings were found, so the advice knows no names"
    doc = build_report(results, settings, source=source, steps=steps, environment=env)
    if not known:
        doc["report"].update(role=None, connection=None, profile=None)
        doc["settings"] = {}
    return doc


# --------------------------------------------------------------------------- running the checks
def complete_for_run(settings: Settings, path: Path) -> Settings:
    """Fill in this machine's local IP/interface when the file leaves them out (for this run
    only, as `rosnet-tui check` does); refuse incomplete settings."""
    from rosnet_tui.core.net.netinfo import with_detected

    settings = with_detected(settings)
    problems = settings.problems()
    if problems:
        raise ReportError(f"the settings in {path} are not complete: "
                          + "; ".join(f"{k}: {why}" for k, why in problems)
                          + " (fix them by hand or with the wizard: rosnet-tui --setup)")
    return settings


def run_checks_now(settings: Settings, steps: Iterable[str] | None) -> list[CheckResult]:
    """Run the checks of *steps* (all when None), as `rosnet-tui check` does."""
    from rosnet_tui.cli.check import collect_results

    return collect_results(settings, list(steps) if steps else None)


