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


def run_affected_checks(settings: Settings, paths: Paths,
                        ids: tuple[str, ...] = affected.SYNC) -> list[dict[str, Any]]:
    """Run the checks a hosts/ROS change affects (concurrently, each under its timeout):
    [{"id", "status", "summary"}] in *ids* order."""
    if settings.ros2:  # the ROS 2 counterparts of the ROS 1 checks a new address affects
        ids = tuple(dict.fromkeys("ros2.router" if i.startswith("ros.") else i for i in ids))
    specs = select(ids=ids)
    env = dict(os.environ)
    with contextlib.suppress(WriterSettingsError):
        env["ROS_MASTER_URI"] = master_uri(settings)
    for v in ("ROS_IP", "ROS_HOSTNAME"):
        env.pop(v, None)
    opts = RunOptions(paths=paths, env=env, upnp=False)
    got = run_now(copy.deepcopy(settings), specs, opts)
    return [{"id": r.id, "status": r.status.value, "summary": r.summary} for r in got]
