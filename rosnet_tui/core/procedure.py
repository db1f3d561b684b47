"""The procedure's vocabulary, in one place: the four steps in order, their titles, severities.

Every layer (checks, advisor, steps text, report, UI) names steps and severities through this
module, so the order and the words cannot drift apart.
"""

from __future__ import annotations

# The four steps, in the order the procedure does them.
STEP_IDS: tuple[str, ...] = ("isp", "router", "linux", "ros")
# Short titles (the step bar, the report's headings, the advisor's "back to" column).
STEP_TITLES: dict[str, str] = {"isp": "ISP", "router": "Router/modem", "linux": "Linux",
                               "ros": "ROS"}

# How serious a finding is, most serious first (the advisor's sort order).
SEVERITIES: tuple[str, ...] = ("fail", "warn", "security", "info")
# One short word per severity that reads without colour.
SEVERITY_WORDS: dict[str, str] = {"fail": "FAIL", "warn": "WARN", "security": "SEC",
                                  "info": "INFO"}


def step_number(step: str) -> int:
    """1 for 'isp' ... 4 for 'ros'."""
    return STEP_IDS.index(step) + 1


def step_index(step: str | None) -> int:
    """The step's position (0-3), or 4 for anything else (sorts after the steps)."""
    return STEP_IDS.index(step) if step in STEP_IDS else len(STEP_IDS)


def step_title(step: str | None) -> str:
    """'step 2 (Router/modem)' for 'router'; '-' for no step."""
    if step not in STEP_TITLES:
        return "-"
    return f"step {step_number(step)} ({STEP_TITLES[step]})"


