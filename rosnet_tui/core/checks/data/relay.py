"""The relay (ROS 2 across carrier NAT): what its checks report in ``data``.

One TypedDict per check id; the comment on each key is its documentation (see
:mod:`rosnet_tui.core.checks.data`)."""

from __future__ import annotations

from typing import Literal, TypedDict

from rosnet_tui.core.checks.data.ros import Ros2RouterData


class RelayTunnelData(TypedDict, total=False):  # relay.tunnel (checks/relay_tunnel.py)
    relay: str               # the relay's name ([relay] host)
    port: int                # this component's port on the relay's loopback ([relay.tunnels])
    up: bool | None          # the port answers with this machine's sshd key (None: not known)
    failure: Literal["relay", "down", "other_host", "not_sshd", "timeout", "own_keys"] | None  # why not
    fingerprint: str | None  # SHA256:... of the key that answered at the port, when one did
    detail: str              # what happened, in words


DATA: dict[str, type] = {
    "relay.router": Ros2RouterData,   # the relay's router, as this component's router dials it
    "relay.tunnel": RelayTunnelData,
}
