"""Drive the real wizard headless with Pilot on a lab member and pair it: the ROS step (4),
`w`, `y` (write the ROS 2 files, then pair with the master over SSH), in one flow. Prints JSON:
seconds from `y` to the member's certificate installed (the write screen closes after pairing).

Run inside a lab host (tests/test_pairing_lab.py):
``python -m tests.ui_support.drive_pair CONFIG STATE_DIR BASHRC``.
"""

from __future__ import annotations

import asyncio
import json
import sys
import time
from pathlib import Path

from rosnet_tui.core.config.paths import Paths, default_config_dir
from rosnet_tui.core.ros import fleet_tls
from rosnet_tui.core.saved.settings import load_settings
from rosnet_tui.core.wizard.session import WizardSession
from rosnet_tui.ui.app import RosnetApp
from rosnet_tui.ui.widgets import CheckList

LIMIT_S = 15.0


async def drive(config: Path, state_dir: Path, bashrc: Path) -> dict:
    settings = load_settings(config)
    assert settings is not None, f"no settings at {config}"
    paths = Paths(config_path=config, state_dir=state_dir, bashrc_path=bashrc)
    app = RosnetApp(WizardSession(settings, paths))
    crt = fleet_tls.tls_paths(default_config_dir()).node_crt
    out: dict = {"paired_s": None}
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.pause()
        await pilot.press("4")
        await pilot.pause()
        await pilot.press("w")
        await pilot.pause(0.5)
        out["screen"] = type(app.screen).__name__
        t0 = time.monotonic()
        await pilot.press("y")
        while time.monotonic() - t0 < LIMIT_S and type(app.screen).__name__ == "WriteScreen":
            await pilot.pause(0.05)
        if crt.exists():
            out["paired_s"] = round(time.monotonic() - t0, 2)
        # the checks re-run after the write (ros2.env, ros2.router): let them finish, bounded,
        # so no Zenoh session is left open while the interpreter exits
        rows = app.screen.query_one(CheckList).rows
        deadline = time.monotonic() + LIMIT_S
        while time.monotonic() < deadline and any(r.state == "running" for r in rows.values()):
            await pilot.pause(0.1)
        out["after"] = {cid: r.state for cid, r in rows.items() if cid in ("ros2.env",
                                                                           "ros2.router")}
    return out


def main() -> int:
    config, state_dir, bashrc = Path(sys.argv[1]), Path(sys.argv[2]), Path(sys.argv[3])
    print(json.dumps(asyncio.run(drive(config, state_dir, bashrc))))
    return 0


if __name__ == "__main__":
    sys.exit(main())
