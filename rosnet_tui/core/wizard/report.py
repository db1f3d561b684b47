"""The report: a shareable document of the settings, the check results and the advice
(``rosnet-tui report`` prints it; :mod:`rosnet_tui.cli.report` handles its arguments).

For the provider, the IT administrator or a colleague: what this component is, what every check
saw, what the advisor makes of it and what to do, in Markdown (readable as plain text, in a
terminal or an e-mail) or JSON. Nothing secret goes in: the settings without key material and
no environment variable but ``ROS_*``.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import json
import os
import re
import sys
import textwrap
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from rosnet_tui import __version__
from rosnet_tui.core.advisor import advice_by_check, advise
from rosnet_tui.core.config.settings_model import (
    CheckSettings,
    Gap,
    Peer,
    ProbeSettings,
    RosbridgeSettings,
    RosSettings,
    Settings,
    ThisComponent,
)
from rosnet_tui.core.files.regular_file import FileRefusedError, read_regular
from rosnet_tui.core.jsonsafe import JsonInputError, loads_bounded
from rosnet_tui.core.procedure import STEP_IDS, STEP_TITLES, step_title
from rosnet_tui.core.results import CheckResult, ResultFormatError, Status

MAX_INPUT_BYTES = 16 << 20        # a saved `check --json` is a few hundred KB at most
MAX_INPUT_DEPTH = 64
# Settings keys that could hold or point at secrets never go into a report.
_SECRET_KEY = re.compile(r"key|secret|passw|token|tsig|credential", re.IGNORECASE)
WIDTH = 100


class ReportError(Exception):
    """A report that cannot be made (unreadable input, bad settings): exit code 2."""


# --------------------------------------------------------------------------- reading saved results
def load_results_json(path: Path) -> tuple[list[CheckResult], Settings | None, dict[str, Any]]:
    """Results from `check --json` output or a JSON report; also its settings and header."""
    text = _read_input(path)
    try:
        obj = loads_bounded(text, max_depth=MAX_INPUT_DEPTH, unique_keys=False)
    except JsonInputError as exc:
        raise ReportError(f"{path} is not JSON we can use ({exc}); expected the output of "
                          "`rosnet-tui check --json`") from None
    if not isinstance(obj, dict) or not isinstance(obj.get("checks"), list):
        raise ReportError(f"{path}: expected {{\"checks\": [...]}} as written by "
                          "`rosnet-tui check --json`")
    results = []
    for i, c in enumerate(obj["checks"]):
        try:
            results.append(CheckResult.from_json(c))
        except ResultFormatError as exc:
            raise ReportError(f"{path}, check {i + 1}: {exc}") from None
    try:
        settings = settings_from_dict(obj["settings"]) if isinstance(obj.get("settings"),
                                                                     dict) else None
    except ReportError as exc:
        raise ReportError(f"{path}: {exc}") from None
    meta: dict[str, Any] = dict(obj.get("report") or {}) if isinstance(obj.get("report"),
                                                                       dict) else {}
    if isinstance(obj.get("environment"), dict):
        meta["environment"] = ros_environment(obj["environment"])
    return results, settings, meta


def _read_input(path: Path) -> str:
    """The text of *path* ('-': standard input), bounded: a regular file (or stdin) of at most
    MAX_INPUT_BYTES; a FIFO, a device or a folder is refused without reading."""
    too_big = ReportError(f"{path} is too big (over {MAX_INPUT_BYTES} bytes) for saved results")
    if str(path) == "-":
        data = sys.stdin.buffer.read(MAX_INPUT_BYTES + 1)
    else:
        try:
            data = read_regular(path.expanduser(), MAX_INPUT_BYTES)
        except FileRefusedError as exc:
            raise (too_big if exc.kind == "big" else
                   ReportError(f"{path} is not a regular file")) from None
        except OSError as exc:
            raise ReportError(f"cannot read {path}: {exc.strerror or exc}") from None
    if len(data) > MAX_INPUT_BYTES:
        raise too_big
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise ReportError(f"{path} is not UTF-8 text") from None


# --------------------------------------------------------------------------- settings, no secrets
def _scrub(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _scrub(v) for k, v in value.items() if not _SECRET_KEY.search(str(k))}
    if isinstance(value, list):
        return [_scrub(v) for v in value]
    return value


def public_settings(settings: Settings) -> dict[str, Any]:
    """The settings as a dict for a report: every key that could hold a secret left out."""
    d = dataclasses.asdict(settings)
    d.pop("saved_at", None)          # the file's time, not a setting
    out = {"this": d.pop("this"), "peer": d.pop("peers")}
    out.update(d)
    return _scrub(out)


def settings_from_dict(d: dict[str, Any]) -> Settings:
    """Settings back from :func:`public_settings` (unknown keys ignored). Raises ReportError
    for a value of the wrong type or one the settings file would refuse."""
    def pick(cls: type, raw: Any, section: str) -> Any:
        if not isinstance(raw, dict):
            return cls() if cls is not Peer else None
        fields = {f.name: f for f in dataclasses.fields(cls)}
        kept = {}
        for k, v in raw.items():
            if k not in fields:
                continue
            proto = cls.__annotations__.get(k, "")
            want: tuple[type, ...] = {"str": (str,), "int": (int,), "float": (int, float),
                                      "list[str]": (list,), "bool": (bool,)
                                      }.get(str(proto), (object,))
            if (isinstance(v, bool) and want != (bool,)) or not isinstance(v, want) or (
                    want == (list,) and not all(isinstance(x, str) for x in v)):
                raise ReportError(f"settings: {section}.{k} has the wrong type")
            kept[k] = v
        try:
            return cls(**kept)
        except TypeError:
            return None

    raw_peers = d.get("peer") or d.get("peers") or []
    if not isinstance(raw_peers, list):
        raise ReportError("settings: peer must be a list")
    peers = [pick(Peer, p, "peer") for p in raw_peers]
    s = Settings(this=pick(ThisComponent, d.get("this"), "this"),
                 peers=[p for p in peers if p is not None],
                 ros=pick(RosSettings, d.get("ros"), "ros"),
                 probe=pick(ProbeSettings, d.get("probe"), "probe"),
                 checks=pick(CheckSettings, d.get("checks"), "checks"),
                 rosbridge=pick(RosbridgeSettings, d.get("rosbridge"), "rosbridge"))
    # incomplete is fine (the advice then knows fewer names); wrong is not
    for key, why in s.errors(allow=(Gap.BLANK, Gap.NO_ADDRESS)):
        raise ReportError(f"settings: {key}: {why}")
    return s


def ros_environment(environ: dict[str, Any] | os._Environ) -> dict[str, str]:
    """Only the ``ROS_*`` variables of *environ*."""
    return {k: str(v) for k, v in sorted(environ.items()) if k.startswith("ROS_")}


# --------------------------------------------------------------------------- the document
def build_report(results: Iterable[CheckResult], settings: Settings, *, source: str,
                 steps: list[str] | None = None, environment: dict[str, str] | None = None,
                 now: dt.datetime | None = None) -> dict[str, Any]:
    """The report as a JSON-ready dict; :func:`render_markdown` prints the same content."""
    results = list(results)
    findings = advise(results, settings)
    by_check = advice_by_check(findings)
    counts = {s.value: 0 for s in Status}
    for r in results:
        counts[Status(r.status).value] += 1
    now = now or dt.datetime.now(dt.timezone.utc)
    t = settings.this
    checks = []
    for r in results:
        entry = r.to_json()
        entry["advice"] = [f.to_json() for f in by_check.get(r.id, [])]
        checks.append(entry)
    return {
        "report": {"tool": "rosnet-tui", "version": __version__,
                   "generated": now.astimezone(dt.timezone.utc).isoformat(timespec="seconds"),
                   "component": t.name, "role": t.role, "connection": t.connection,
                   "profile": t.profile, "source": source,
                   "steps": steps or list(STEP_IDS)},
        "summary": counts,
        "findings": [f.to_dict() for f in findings],
        "checks": checks,
        "settings": public_settings(settings),
        "environment": dict(environment or {}),
    }


def render_json(doc: dict[str, Any]) -> str:
    return json.dumps(doc, indent=2, ensure_ascii=False) + "\n"


def _wrap(text: str, indent: str = "", first: str | None = None) -> list[str]:
    first = indent if first is None else first
    return textwrap.wrap(text, WIDTH, initial_indent=first, subsequent_indent=indent,
                         break_long_words=False, break_on_hyphens=False) or [first.rstrip()]


def _finding_md(n: int, f: dict[str, Any]) -> list[str]:
    head = f"{n}. [{f['severity'].upper()}] "
    pad = " " * len(f"{n}. ")
    lines = _wrap(f["meaning"], pad, head)
    lines.append(f"{pad}What to do:")
    for a in f["actions"]:
        lines += _wrap(a, pad + "  ", pad + "- ")
    tail = []
    if f.get("goto_step"):
        tail.append(f"Go to: {step_title(f['goto_step'])}.")
    if f.get("check_ids"):
        tail.append("Explains: " + ", ".join(f["check_ids"]) + ".")
    tail.append(f"Rule: {f['rule']}.")
    lines += _wrap(" ".join(tail), pad)
    return lines


def render_markdown(doc: dict[str, Any]) -> str:
    """The report in Markdown that reads as plain text (lines up to ~100 columns)."""
    h, counts = doc["report"], doc["summary"]
    name = h.get("component") or "(unnamed component)"
    out = [f"# rosnet-tui report: {name}", ""]
    out.append(f"- Generated: {h['generated']} (UTC), by rosnet-tui {h['version']}")
    if h.get("role"):
        out.append(f"- Component: {name} - ROS {h['role']}, {h.get('connection')} connection, "
                   f"{h.get('profile')} network profile")
    else:
        out.append(f"- Component: {name} (no settings)")
    out.append(f"- Results: {h['source']}")
    out.append(f"- Steps: {', '.join(STEP_TITLES.get(s, s) for s in h['steps'])}")
    verdict = ", ".join(f"{counts[k]} {w}" for k, w in
                        (("fail", "failed"), ("warn", "warned"), ("pass", "passed"),
                         ("skip", "skipped")) if counts.get(k))
    out.append(f"- Verdict: {verdict or 'no checks'}")
    out.append("")

    findings = doc["findings"]
    out += ["## Findings", ""]
    if not findings:
        out += ["The advisor has nothing to report.", ""]
    groups = (("fail", "Causes of failures (most likely first, in the order of the steps)"),
              ("warn", "Warnings"), ("security", "Security"), ("info", "For information"))
    n = 0
    number: dict[int, int] = {}      # id(finding dict) -> its number in the list
    for sev, title in groups:
        part = [f for f in findings if f["severity"] == sev]
        if not part:
            continue
        out += [f"### {title}", ""]
        for f in part:
            n += 1
            number[id(f)] = n
            out += _finding_md(n, f)
            out.append("")
    refs: dict[str, list[str]] = {}
    for f in findings:
        for cid in f.get("check_ids") or []:
            refs.setdefault(cid, []).append(f"{number.get(id(f), '?')} ({f['rule']})")

    out += ["## Results by step", ""]
    for step in STEP_IDS:
        rows = [c for c in doc["checks"] if c["step"] == step]
        if not rows:
            continue
        out += [f"### {step_title(step)[0].upper() + step_title(step)[1:]}", ""]
        for c in rows:
            st = str(c["status"]).upper()
            timing = f"{c.get('duration_s', 0):.2f} s of {c.get('timeout_s', 0):g} s"
            out += _wrap(f"{c['summary']} ({timing})", "  ", f"- {st} {c['id']}: ")
            if c.get("evidence"):
                out.append("")
                out.append("  ```")
                out += [f"  {e}" for e in c["evidence"]]
                out.append("  ```")
            if refs.get(c["id"]):
                out += _wrap("see finding " + ", ".join(refs[c["id"]]), "     ", "  -> ")
            out.append("")

    out += ["## Settings", ""]
    if doc["settings"]:
        out += ["This component's settings file, without key material or secrets:", "",
                "```toml", _toml(doc["settings"]).rstrip("\n"), "```", ""]
    else:
        out += ["No settings were available.", ""]
    env = doc.get("environment") or {}
    out += ["## ROS environment", ""]
    if env:
        out += ["```"] + [f"{k}={v}" for k, v in env.items()] + ["```", ""]
    else:
        out += ["No ROS_* variables were recorded." if "live" not in h["source"]
                else "No ROS_* variable is set in the environment the checks ran in.", ""]
    return "\n".join(out)


def _toml(settings: dict[str, Any]) -> str:
    import tomlkit

    doc = tomlkit.document()
    for key in ("this", "peer", "ros", "probe", "checks"):
        val = settings.get(key)
        if key == "peer":
            if val:
                aot = tomlkit.aot()
                for p in val:
                    aot.append({k: v for k, v in p.items() if v not in ("", None)})
                doc["peer"] = aot
        elif isinstance(val, dict):
            doc[key] = {k: v for k, v in val.items() if v not in ("", None)}
    for key, val in settings.items():
        if key not in ("this", "peer", "ros", "probe", "checks") and isinstance(val, dict):
            doc[key] = {k: v for k, v in val.items() if v not in ("", None)}
    return tomlkit.dumps(doc)
