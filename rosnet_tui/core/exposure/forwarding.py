"""Which ports this component's modem must forward, for its ROS version and role: one answer for
the Router step's text, the router card, the port checks and anything that maps ports itself.

ROS 1 needs every port (nodes pick random ports); ROS 2 over rmw_zenoh needs one TCP port on the
master's modem only, and nothing at all on a member's (its router connects out).
"""

from __future__ import annotations

from dataclasses import dataclass

from rosnet_tui.core.config.settings_model import PORT_MAX, PORT_MIN, Settings
from rosnet_tui.core.ros.rosbridge import forward_needed


@dataclass(frozen=True)
class ForwardPort:
    protocol: str        # "TCP" | "UDP"
    first: int           # first external port
    last: int            # last external port (== first for one port)
    required: bool       # the ROS network does not work without it
    why: str             # what uses it, in a few words

    @property
    def ports(self) -> str:
        """'7447' or '1024-65000'."""
        return str(self.first) if self.first == self.last else f"{self.first}-{self.last}"


def ports_to_forward(settings: Settings) -> list[ForwardPort]:
    """The forwards this component's modem needs (required ones first), each to its local IP.

    ROS 1: TCP 1024-65000 (UDP optional), TCP 22 for SSH (optional). ROS 2 master: TCP
    ``zenoh_port`` only (and 22 for SSH, optional). ROS 2 member, and every component under a
    relay ([relay] host: every router dials out to it): nothing is required. The
    component running rosbridge ([rosbridge] enabled) forwards its port too, under ROS 2 (and
    under ROS 1 when the port is outside the range).
    """
    ssh = ForwardPort("TCP", 22, 22, False, "SSH from the peers (keys only)")
    # [rosbridge] on this component: its port too, unless ROS 1's range already covers it.
    bp = settings.rosbridge.port
    bridge = ([ForwardPort("TCP", bp, bp, True, "rosbridge: web clients (Robot Web Tools)")]
              if forward_needed(settings) else [])
    if not settings.ros2:
        return [ForwardPort("TCP", PORT_MIN, PORT_MAX, True, "ROS (master, nodes) and the test "
                                                               "port"),
                *bridge,
                ForwardPort("UDP", PORT_MIN, PORT_MAX, False,
                            "only for UDP transports; ROS 1 topics use TCP"),
                ssh]
    if settings.is_master and not settings.relayed:
        port = settings.ros.zenoh_port
        return [ForwardPort("TCP", port, port, True, "the Zenoh router of the ROS 2 master "
                                                     "(rmw_zenohd); every member connects here"),
                *bridge, ssh]
    return [*bridge, ssh]


def required_ports(settings: Settings) -> list[ForwardPort]:
    """Only the forwards without which the ROS network cannot work (empty: none needed)."""
    return [p for p in ports_to_forward(settings) if p.required]
