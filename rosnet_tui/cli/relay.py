"""`rosnet-tui relay`: the relay a fleet behind carrier NAT meets at (ROS 2, issue 30)."""

from __future__ import annotations

import argparse

from rosnet_tui.cli import relay_tunnel


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "relay",
        help="ROS 2 across carrier NAT: the relay's Zenoh router every component dials out to",
        description="When no site can forward a port (both behind carrier-grade NAT), every "
                    "component's Zenoh router dials out to a relay: a small public server you "
                    "own. The settings' [relay] section names it (docs/SETTINGS.md).")
    cmds = p.add_subparsers(dest="relay_command", metavar="COMMAND", required=True)
    relay_tunnel.register(cmds)
