"""Typed results of checks: what every check returns, whatever happened on the network."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from enum import Enum
from typing import Any


class Status(str, Enum):
    PASS = "pass"
    WARN = "warn"
    FAIL = "fail"
    SKIP = "skip"

    @property
    def label(self) -> str:
        """A word that reads without colour (NO_COLOR, monochrome terminals)."""
        return self.value.upper()


@dataclass
class Outcome:
    """What a check function returns; the runner adds id, step and timings."""

    status: Status
    summary: str
    evidence: list[str] = field(default_factory=list)
    data: dict[str, Any] = field(default_factory=dict)


@dataclass
class CheckResult:
    """One check's verdict. Its JSON form is a contract (docs/COMMANDS.md: `check --json`)."""

    id: str
    step: str
    status: Status
    summary: str
    evidence: list[str] = field(default_factory=list)
    duration_s: float = 0.0
    timeout_s: float = 0.0
    data: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        out = asdict(self)
        out["status"] = self.status.value
        out["duration_s"] = round(self.duration_s, 3)
        return out

    @classmethod
    def from_json(cls, obj: Any) -> CheckResult:
        """A result from its JSON form (:meth:`to_json`, ``check --json``); the step defaults to
        the id's prefix. Raises :class:`ResultFormatError` saying what is wrong."""
        if not isinstance(obj, dict) or not isinstance(obj.get("id"), str):
            raise ResultFormatError("each check needs at least an \"id\" and a \"status\"")
        try:
            status = Status(obj.get("status"))
        except ValueError:
            raise ResultFormatError(f"unknown status {obj.get('status')!r} "
                                    "(expected pass, warn, fail or skip)") from None
        cid = obj["id"]
        evidence = obj.get("evidence") or []
        data = obj.get("data") or {}
        return cls(
            id=cid, step=str(obj.get("step") or cid.split(".")[0]), status=status,
            summary=str(obj.get("summary") or ""),
            evidence=[str(e) for e in evidence] if isinstance(evidence, list) else [str(evidence)],
            duration_s=_seconds(obj, "duration_s"), timeout_s=_seconds(obj, "timeout_s"),
            data=data if isinstance(data, dict) else {})


class ResultFormatError(ValueError):
    """A JSON record that is not a check result."""


MAX_SECONDS = 86400


def _seconds(obj: dict[str, Any], key: str) -> float:
    value = obj.get(key)
    if value is None:
        return 0.0
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not 0 <= value <= MAX_SECONDS or value != value:
        raise ResultFormatError(f"\"{key}\" must be a number of seconds (0 to {MAX_SECONDS})")
    return float(value)
