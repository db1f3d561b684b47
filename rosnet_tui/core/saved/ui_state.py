"""What the wizard keeps across sessions, so a dropped SSH link loses nothing.

One JSON file in the state directory (``ui.json``), rewritten atomically as things happen: the step
the user was on, the last result of every check (with when it came), the advisor's findings for
them, and the set-up forms being filled in and not saved yet (the drafts), each kept under the
settings file it belongs to. The next start reads it back; results from an earlier session are
shown as such, with their time.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from rosnet_tui.core.results import CheckResult, ResultFormatError
from rosnet_tui.core.saved.settings import atomic_write_text
from rosnet_tui.core.saved.state import read_json

UI_FILE = "ui.json"
VERSION = 3   # 3: drafts kept per settings file ("drafts"), not one per account


@dataclass
class SavedFinding:
    """A finding read back from the state file: the fields the screens show (the advisor's own
    Finding is rebuilt as soon as a new result lands)."""

    rule: str
    meaning: str
    actions: list[str]
    goto_step: str | None
    check_ids: list[str] = field(default_factory=list)
    severity: str = "fail"
    order: int = 0
    condition: str = ""
    evidence: list[str] = field(default_factory=list)

    @classmethod
    def from_dict(cls, d: dict) -> SavedFinding | None:
        try:
            return cls(rule=str(d["rule"]), meaning=str(d.get("meaning", "")),
                       actions=[str(a) for a in d.get("actions") or []],
                       goto_step=d.get("goto_step") if isinstance(d.get("goto_step"), str) else None,
                       check_ids=[str(c) for c in d.get("check_ids") or []],
                       severity=str(d.get("severity", "fail")), order=int(d.get("order", 0)),
                       condition=str(d.get("condition", "")),
                       evidence=[str(e) for e in d.get("evidence") or []])
        except (KeyError, TypeError, ValueError):
            return None

    def to_dict(self) -> dict:
        return {"rule": self.rule, "severity": self.severity, "condition": self.condition,
                "meaning": self.meaning, "actions": list(self.actions),
                "goto_step": self.goto_step, "check_ids": list(self.check_ids),
                "order": self.order, "evidence": list(self.evidence)}


def now_iso() -> str:
    return datetime.now(timezone.utc).replace(microsecond=0).isoformat()


def local_time(iso: str, today: float | None = None) -> str:
    """'14:02' for a time today, '2026-11-21 14:02' otherwise (local time); '' if unreadable."""
    try:
        t = datetime.fromisoformat(iso).timestamp()
    except (TypeError, ValueError):
        return ""
    lt, ln = time.localtime(t), time.localtime(today if today is not None else time.time())
    same_day = (lt.tm_year, lt.tm_yday) == (ln.tm_year, ln.tm_yday)
    return time.strftime("%H:%M" if same_day else "%Y-%m-%d %H:%M", lt)


class UiState:
    """The state file, read once at start and rewritten whole (atomically) on every change."""

    def __init__(self, state_dir: Path) -> None:
        self.path = state_dir / UI_FILE
        self.data: dict[str, Any] = self._load()

    def _load(self) -> dict[str, Any]:
        data = read_json(self.path)   # None when missing, damaged, too deep or not a file
        return data if isinstance(data, dict) else {}

    def save(self) -> bool:
        """Write the file; False if it could not be written (state is a convenience: the wizard
        goes on)."""
        self.data["version"] = VERSION
        try:
            atomic_write_text(self.path, json.dumps(self.data, indent=1, sort_keys=True) + "\n",
                              mode=0o600)
        except OSError:
            return False
        return True

    # ------------------------------------------------------------------ where the user was
    @property
    def last_step(self) -> str | None:
        step = self.data.get("last_step")
        return step if isinstance(step, str) else None

    def set_last_step(self, step: str) -> None:
        if self.data.get("last_step") != step:
            self.data["last_step"] = step
            self.save()

    # ------------------------------------------------------------------ results and findings
    def results(self) -> dict[str, tuple[CheckResult, str]]:
        """Check id -> (its last result, when it came as ISO time)."""
        out: dict[str, tuple[CheckResult, str]] = {}
        raw = self.data.get("results")
        for cid, rec in (raw.items() if isinstance(raw, dict) else ()):
            if isinstance(rec, dict):
                try:
                    r = CheckResult.from_json(rec.get("result"))
                except ResultFormatError:
                    r = None
                if r is not None and r.id == cid:
                    out[cid] = (r, str(rec.get("at", "")))
        return out

    def findings(self) -> list[SavedFinding]:
        raw = self.data.get("findings")
        found = [SavedFinding.from_dict(d) for d in raw if isinstance(d, dict)] \
            if isinstance(raw, list) else []
        return [f for f in found if f is not None]

    def set_result(self, result: CheckResult, findings: list, at: str | None = None) -> None:
        results = self.data.get("results")
        if not isinstance(results, dict):
            results = self.data["results"] = {}
        results[result.id] = {"at": at or now_iso(), "result": result.to_json()}
        self.data["findings"] = [f.to_dict() for f in findings]
        self.save()

    # ------------------------------------------------------------------ set-up drafts
    # One per settings file, under its resolved path: a draft typed for one file is never offered
    # (nor saved) over another. A version 2 "draft" said nothing of its file: it is not offered.
    @staticmethod
    def draft_key(config_path: Path) -> str:
        path = Path(config_path).expanduser()
        try:
            return str(path.resolve())
        except (OSError, RuntimeError):   # a symlink loop: the path as given, made absolute
            return str(path.absolute())

    def _drafts(self) -> dict[str, Any]:
        drafts = self.data.get("drafts")
        if not isinstance(drafts, dict):
            drafts = self.data["drafts"] = {}
        self.data.pop("draft", None)
        return drafts

    def draft(self, config_path: Path) -> dict[str, Any] | None:
        """The set-up being filled in for *config_path* and not saved yet, if any."""
        drafts = self.data.get("drafts")
        d = drafts.get(self.draft_key(config_path)) if isinstance(drafts, dict) else None
        return d if isinstance(d, dict) and isinstance(d.get("fields"), dict) else None

    def set_draft(self, config_path: Path, fields: dict[str, str],
                  peers: list[dict[str, str]]) -> None:
        self._drafts()[self.draft_key(config_path)] = {"at": now_iso(), "fields": fields,
                                                       "peers": peers}
        self.save()

    def clear_draft(self, config_path: Path) -> None:
        key = self.draft_key(config_path)
        if key in (self.data.get("drafts") or {}) or "draft" in self.data:
            self._drafts().pop(key, None)
            self.save()
