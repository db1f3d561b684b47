"""Drive the real wizard headless with Pilot on this host, and print what it showed as JSON.

Run inside a lab host (tests/test_ui_lab.py): ``python -m tests.ui_support.drive_wizard CONFIG``.
For each step it presses the step's number and `r`, waits (bounded) until no check is running,
and records every check's state and summary, the step bar's marks and the advisor's findings.
"""

from __future__ import annotations

import asyncio
import json
import sys
import time
from pathlib import Path

from rosnet_tui.core.config.paths import Paths
from rosnet_tui.core.saved.settings import load_settings
from rosnet_tui.core.wizard.session import WizardSession
from rosnet_tui.core.wizard.steps import STEPS
from rosnet_tui.ui.app import RosnetApp
from rosnet_tui.ui.widgets import CheckList

STEP_LIMIT_S = 45.0


async def drive(config: Path, state_dir: Path) -> dict:
    settings = load_settings(config)
    assert settings is not None, f"no settings at {config}"
    app = RosnetApp(WizardSession(settings, Paths(config_path=config, state_dir=state_dir)))
    out: dict = {"steps": {}, "bar": {}, "findings": []}
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.pause()
        for step in STEPS:
            await pilot.press(str(step.number), "r")
            rows = app.screen.query_one(CheckList).rows
            deadline = time.monotonic() + STEP_LIMIT_S
            while time.monotonic() < deadline:
                await pilot.pause(0.1)
                if all(r.state not in ("running", "not run") for r in rows.values()):
                    break
            out["steps"][step.id] = {cid: {"state": r.state,
                                           "summary": r.result.summary if r.result else "",
                                           "evidence": r.result.evidence if r.result else [],
                                           "data": r.result.data if r.result else {}}
                                     for cid, r in rows.items()}
        bar = app.screen.query_one("#step-bar")
        for step in STEPS:
            out["bar"][step.id] = bar._label(step.id)
        out["findings"] = [{"rule": f.rule, "severity": f.severity} for f in app.session.findings]
    return out


def main() -> int:
    config, state_dir = Path(sys.argv[1]), Path(sys.argv[2])
    print(json.dumps(asyncio.run(drive(config, state_dir))))
    return 0


if __name__ == "__main__":
    sys.exit(main())
