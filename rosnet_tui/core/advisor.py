"""The troubleshooting advisor: rules over check results -> what it means, what to do, where to go.

(Placeholder API until the advisor issue lands: ``advise`` returns no findings.)
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from rosnet_tui.core.results import CheckResult
from rosnet_tui.core.settings import Settings


@dataclass
class Finding:
    rule: str                  # stable rule id, e.g. "table1.listener_up_closed"
    meaning: str               # what it means
    actions: list[str]         # what to do, concrete
    goto_step: str | None      # "isp" | "router" | "linux" | "ros" | None
    check_ids: list[str] = field(default_factory=list)  # the checks this finding explains
    severity: str = "fail"     # "fail" | "warn" | "info" | "security"
    order: int = 0             # rank among several possible causes (0 = most likely)

    def to_json(self) -> dict:
        return {"rule": self.rule, "meaning": self.meaning, "actions": list(self.actions),
                "goto_step": self.goto_step}


def advise(results: Mapping[str, CheckResult], settings: Settings) -> list[Finding]:
    """All findings that apply to *results*, most important first."""
    return []
