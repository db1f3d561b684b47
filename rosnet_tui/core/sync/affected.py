"""The checks a change of the sync service affects, run through the one door to run checks."""

from __future__ import annotations

import contextlib
import copy
import os
from typing import Any

from rosnet_tui.core import affected
from rosnet_tui.core.checks.runner import RunOptions, run_now, select
from rosnet_tui.core.config.paths import Paths
from rosnet_tui.core.config.settings_model import Settings
from rosnet_tui.core.files.bashrc import master_uri
from rosnet_tui.core.files.hosts import WriterSettingsError


def run_affected_checks(settings: Settings, paths: Paths) -> list[dict[str, Any]]:
    """Run the checks a peer's new address affects (:data:`affected.SYNC`, concurrently, each
    under its timeout): [{"id", "status", "summary"}] in that order."""
    specs = select(ids=affected.SYNC_ROS2 if settings.ros2 else affected.SYNC)
    env = dict(os.environ)
    with contextlib.suppress(WriterSettingsError):
        env["ROS_MASTER_URI"] = master_uri(settings)
    for v in ("ROS_IP", "ROS_HOSTNAME"):
        env.pop(v, None)
    opts = RunOptions(paths=paths, env=env, upnp=False)
    got = run_now(copy.deepcopy(settings), specs, opts)
    return [{"id": r.id, "status": r.status.value, "summary": r.summary} for r in got]
