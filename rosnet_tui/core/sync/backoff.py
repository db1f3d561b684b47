"""Bounded exponential back-off: after each failure wait longer, never longer than a cap."""

from __future__ import annotations

import random
from dataclasses import dataclass, field


def backoff_cap(interval_s: float) -> float:
    """The longest wait between retries for a poll interval: twice it, 10 s to 5 min."""
    return min(300.0, max(10.0, 2.0 * float(interval_s)))


@dataclass
class Backoff:
    base_s: float = 1.0
    cap_s: float = 60.0
    factor: float = 2.0
    jitter: float = 0.1           # +-10 %: many components never retry in step
    failures: int = 0
    _rng: random.Random = field(default_factory=random.Random, repr=False)

    def fail(self) -> float:
        """Count a failure; the seconds to wait before the next try (bounded by cap_s)."""
        self.failures += 1
        delay = min(self.cap_s, self.base_s * self.factor ** (self.failures - 1))
        if self.jitter:
            delay *= 1 + self._rng.uniform(-self.jitter, self.jitter)
        return max(0.0, min(delay, self.cap_s))

    def succeed(self) -> bool:
        """Reset after a success; True when this ended a run of failures (a recovery)."""
        recovered = self.failures > 0
        self.failures = 0
        return recovered

    @property
    def failing(self) -> bool:
        return self.failures > 0
