"""The relay (ROS 2 across carrier NAT): what its checks report in ``data``.

One TypedDict per check id; the comment on each key is its documentation (see
:mod:`rosnet_tui.core.checks.data`)."""

from __future__ import annotations

from typing import Literal, TypedDict

from rosnet_tui.core.checks.data.ros import Ros2RouterData


class RelayTunnelPeerData(TypedDict, total=False):  # relay.tunnel, one peer's side
    up: bool | None          # the peer reached this machine's sshd through the relay (None: its side did not run)
    failure: Literal["relay", "down", "other_host", "not_sshd", "timeout"] | None  # why not
    fingerprint: str | None  # SHA256:... of the key the peer found at the port, when one answered
    detail: str              # what happened, in words


class RelayTunnelData(TypedDict, total=False):  # relay.tunnel (checks/relay_tunnel.py)
    relay: str               # the relay's name ([relay] host)
    port: int                # this component's port on the relay's loopback ([relay.tunnels])
    up: bool | None          # the port answers with this machine's sshd key, asked from here (None: not known)
    failure: Literal["relay", "down", "other_host", "not_sshd", "timeout", "own_keys", "peer"] | None  # why not ("peer": up, but a peer cannot reach it)
    fingerprint: str | None  # SHA256:... of the key that answered at the port, when one did
    detail: str              # what happened, in words
    peers: dict[str, RelayTunnelPeerData]  # by peer name: what each peer with an SSH user gets there, from its side


DATA: dict[str, type] = {
    "relay.router": Ros2RouterData,   # the relay's router, as this component's router dials it
    "relay.tunnel": RelayTunnelData,
}
