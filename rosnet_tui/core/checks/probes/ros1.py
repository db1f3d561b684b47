"""What the ROS 1 checks share: the master's URI every component should use, and the peers whose
side of an exchange can be run from here."""

from __future__ import annotations

from rosnet_tui.core.checks import CheckContext
from rosnet_tui.core.checks.probes.peers import ssh_peers
from rosnet_tui.core.config.settings_model import Peer, Settings


def master_uri(ctx: CheckContext) -> tuple[str | None, str]:
    """(URI of the master every component should use, where it came from) or (None, why not)."""
    s = ctx.settings
    if s.master_name:
        return f"http://{s.master_name}:{s.ros.port}", "the settings"
    env = ctx.env.get("ROS_MASTER_URI")
    if env and s.is_master:
        return env, "ROS_MASTER_URI"
    return None, ("no ROS master is configured: set the master's name (ros.master) in the "
                  "settings")


def ros1_peers(s: Settings) -> list[Peer]:
    """Peers we can reach over SSH; the master first (it is usually the robot)."""
    return sorted(ssh_peers(s), key=lambda p: p.name != s.ros.master)
