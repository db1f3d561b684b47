"""What a benchmark row produces: lines of the table, with their samples, and the run's options."""

from __future__ import annotations

import statistics
from dataclasses import asdict, dataclass, field
from typing import Any


class BenchError(Exception):
    """A measurement could not be made (the program did not start, a marker never showed...)."""


@dataclass
class Options:
    reps: int = 5
    quick: bool = False
    # Derived from quick unless given: seconds of silence that end a frame, of idle watching, the
    # cap of a standard tool in row 3.
    quiet_s: float = 0.5
    idle_s: float = 5.0
    tool_cap_s: float = 60.0

    @classmethod
    def make(cls, reps: int | None, quick: bool) -> Options:
        if quick:
            return cls(reps=reps or 1, quick=True, quiet_s=0.3, idle_s=1.0, tool_cap_s=2.0)
        return cls(reps=reps or 5, quick=False)


def median(xs: list[float]) -> float | None:
    xs = [x for x in xs if x is not None]
    return statistics.median(xs) if xs else None


@dataclass
class Line:
    """One line of the results table: a median for rosnet-tui against a median for its baseline."""

    row: int
    measure: str
    unit: str                       # "s", "ms", "B", "B/s", "MB"
    app: list[float] = field(default_factory=list)
    base: list[float] = field(default_factory=list)
    baseline: str = ""              # what the baseline is
    goal: str = ""                  # in words, e.g. "<= 1.2x"
    met: bool | None = None         # None: no goal, or not measured
    note: str = ""
    status: str = "measured"        # "measured" | "skipped" | "not available yet" | "error"

    @property
    def app_median(self) -> float | None:
        return median(self.app)

    @property
    def base_median(self) -> float | None:
        return median(self.base)

    @property
    def ratio(self) -> float | None:
        a, b = self.app_median, self.base_median
        if a is None or b is None or b == 0:
            return None
        return a / b

    def to_json(self) -> dict[str, Any]:
        d = asdict(self)
        d.update(app_median=self.app_median, base_median=self.base_median, ratio=self.ratio)
        return d


@dataclass
class RowResult:
    row: int
    title: str
    lines: list[Line] = field(default_factory=list)
    status: str = "measured"        # "measured" | "skipped" | "not available yet" | "error"
    reason: str = ""
    details: dict[str, Any] = field(default_factory=dict)
    seconds: float = 0.0

    def to_json(self) -> dict[str, Any]:
        return {"row": self.row, "title": self.title, "status": self.status, "reason": self.reason,
                "seconds": round(self.seconds, 2), "lines": [ln.to_json() for ln in self.lines],
                "details": self.details}


def goal_ratio(line: Line, limit: float) -> None:
    """Set line.met from its ratio against *limit* (ratio <= limit)."""
    r = line.ratio
    line.met = None if r is None else r <= limit
