"""Pairing (and the sync service's certificate renewal, which pairs again) reaches a master
behind the relay through it, whoever calls it: the route comes from the settings."""

from __future__ import annotations

import asyncio
import socket

from rosnet_tui.core.config.settings_model import RelaySettings
from rosnet_tui.core.ros import fleet_tls, pairing
from tests.builders import ros2_member


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_pairing_with_no_options_goes_through_the_relay(tmp_path):
    s = ros2_member(security="mtls")
    s.relay = RelaySettings(host="localhost", ssh_user="tunnel", ssh_port=_closed_port(),
                            tunnels={"turtlebot": 2201, "sami": 2202})
    paths = fleet_tls.tls_paths(tmp_path)
    res = asyncio.run(pairing.pair_over_ssh(s, paths, None, timeout=5.0))
    assert not res.ok
    # it dialled the relay (closed here), not turtlebot's public address
    assert "relay" in res.detail and "203.0.113.2" not in res.detail, res.detail
