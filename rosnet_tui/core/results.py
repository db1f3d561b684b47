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
    """One check's verdict. Its JSON form is a contract (see README, "rosnet-tui check")."""

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
