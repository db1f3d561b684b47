"""The results: a rich table on the terminal, Markdown for docs/PERFORMANCE.md, JSON for machines."""

from __future__ import annotations

import json
import os
import platform
import sys
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from bench.model import Line, Options, RowResult


def fmt(value: float | None, unit: str) -> str:
    if value is None:
        return "—"
    if unit == "s":
        return f"{value:.1f} s" if abs(value) >= 10 else f"{value:.2f} s"
    if unit == "ms":
        return f"{value:.1f} ms" if abs(value) < 10 else f"{value:.0f} ms"
    if unit == "MB":
        return f"{value:.1f} MB"
    if unit == "B":
        return f"{value / 1000:.1f} kB" if value >= 10000 else f"{value:.0f} B"
    if unit == "B/s":
        return f"{value:.0f} B/s"
    return f"{value:g} {unit}"


def fmt_ratio(line: Line) -> str:
    r = line.ratio
    if r is None:
        return "—"
    return f"{r:.1f}x" if r >= 10 else f"{r:.2f}x"


def fmt_met(line: Line) -> str:
    if line.status == "error":
        return "ERROR"
    return {True: "yes", False: "NO", None: "—"}[line.met]


def table_rows(results: list[RowResult]) -> list[dict[str, str]]:
    """One dict per table line (the same cells for the terminal and for Markdown)."""
    out = []
    for res in sorted(results, key=lambda r: r.row):
        letters = "abcdefghijklmnopqrstuvwxyz" if len(res.lines) > 1 else [""] * len(res.lines)
        if res.status != "measured" or not res.lines:
            out.append({"row": str(res.row), "measure": res.title, "short": res.title,
                        "baseline": "", "app": "—", "base": "—", "ratio": "—", "goal": "—",
                        "met": "ERROR" if res.status == "error" else "—",
                        "note": f"{res.status}: {res.reason}"})
            continue
        for ln, letter in zip(res.lines, letters, strict=False):
            measure = ln.measure + (f" (vs {ln.baseline})" if ln.baseline else "")
            out.append({"row": f"{res.row}{letter}", "measure": measure, "short": ln.measure,
                        "baseline": ln.baseline, "app": fmt(ln.app_median, ln.unit),
                        "base": fmt(ln.base_median, ln.unit), "ratio": fmt_ratio(ln),
                        "goal": ln.goal or "—", "met": fmt_met(ln), "note": ln.note})
    return out


HEADERS = [("row", "#"), ("measure", "Measure (vs baseline)"), ("app", "rosnet-tui"),
           ("base", "Baseline"), ("ratio", "Ratio"), ("goal", "Goal"), ("met", "Met"),
           ("note", "Notes")]


def print_table(results: list[RowResult], opts: Options, meta: dict[str, Any]) -> None:
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    console = Console(highlight=False)
    if not console.is_terminal:  # a file or a pipe: room for the table without folding
        console = Console(highlight=False, width=120)
    table = Table(title=f"rosnet-tui benchmarks — median of {opts.reps} repetition(s)"
                        + (" (--quick)" if opts.quick else ""), expand=False)
    cols = [("row", "#"), ("short", "Measure"), ("app", "rosnet-tui"), ("base", "Baseline"),
            ("ratio", "Ratio"), ("goal", "Goal"), ("met", "Met")]
    for key, head in cols:
        table.add_column(head, overflow="fold", no_wrap=key != "short",
                         justify="right" if key in ("app", "base", "ratio") else "left")
    styles = {"yes": "green", "NO": "bold red", "ERROR": "bold red"}
    rows = table_rows(results)
    for cells in rows:
        met = cells["met"]
        table.add_row(*[escape(cells[k]) for k, _ in cols[:-1]],
                      f"[{styles[met]}]{met}[/]" if met in styles else met)
    console.print(table)
    for cells in rows:
        text = "; ".join(x for x in (f"vs {cells['baseline']}" if cells["baseline"] else "",
                                     cells["note"]) if x)
        if text:
            console.print(f"[bold]{cells['row']}[/bold] {escape(text)}")
    console.print(f"[dim]{escape(meta['machine']['summary'])}[/dim]")


def markdown(results: list[RowResult], opts: Options, meta: dict[str, Any]) -> str:
    def cell(text: str) -> str:
        return text.replace("|", "\\|").replace("\n", " ")

    lines = [f"Measured with `{meta['command']}` on {meta['when'][:10]} "
             f"({meta['machine']['summary']}); median of {opts.reps} repetition(s)"
             + (", --quick" if opts.quick else "") + ".", "",
             "| " + " | ".join(h for _, h in HEADERS) + " |",
             "|" + "|".join("---:" if k in ("app", "base", "ratio") else "---"
                            for k, _ in HEADERS) + "|"]
    for cells in table_rows(results):
        lines.append("| " + " | ".join(cell(cells[k]) for k, _ in HEADERS) + " |")
    return "\n".join(lines) + "\n"


def metadata(opts: Options, argv: list[str]) -> dict[str, Any]:
    try:
        import textual
        textual_version = textual.__version__
    except Exception:  # pragma: no cover
        textual_version = "?"
    from rosnet_tui import __version__

    cpu = ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    cores = os.cpu_count() or 0
    py = platform.python_version()
    try:
        load = round(os.getloadavg()[0], 2)
    except OSError:  # pragma: no cover
        load = None
    return {
        "when": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "command": " ".join(["bench/run", *argv]).strip(),
        "options": {"reps": opts.reps, "quick": opts.quick, "quiet_s": opts.quiet_s,
                    "idle_s": opts.idle_s, "tool_cap_s": opts.tool_cap_s},
        "machine": {"cores": cores, "cpu": cpu, "python": py, "textual": textual_version,
                    "rosnet_tui": __version__, "platform": platform.platform(),
                    "root": os.geteuid() == 0 if hasattr(os, "geteuid") else False,
                    "load_1min_at_end": load,
                    "summary": f"{cores} cores{', ' + cpu if cpu else ''}, Python {py}, "
                               f"Textual {textual_version}, rosnet-tui {__version__}"
                               + (f", load {load:g} at the end" if load is not None else "")},
        "python_executable": sys.executable,
    }


def write_json(path: Path, results: list[RowResult], meta: dict[str, Any]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    doc = {**meta, "rows": [r.to_json() for r in sorted(results, key=lambda r: r.row)]}
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(json.dumps(doc, indent=2, default=str) + "\n", encoding="utf-8")
    tmp.replace(path)
