"""Checks of one round that go after another (CheckContext.after): the bare TCP probes of the
master's Zenoh port wait for security.outsider's attempts (probes/ros2.py), as ros2.link waits
for the pub/sub checks. Each wait is bounded, and none happens where it buys nothing."""

from __future__ import annotations

import asyncio
import time

from rosnet_tui.core.checks import CheckContext
from rosnet_tui.core.checks.probes.ros2 import after_outsider_attempts
from rosnet_tui.core.config.settings_model import RelaySettings
from tests.builders import laptop_settings, result, ros2_master

ROUND = frozenset({"security.outsider", "linux.chat_in", "router.port_open"})


async def test_a_bare_probe_of_the_tls_port_goes_after_the_outsiders_attempts():
    """Zenoh's TLS listener sleeps 100 ms after each handshake it refuses and takes none
    meanwhile: the outsider's insider waited 120-160 ms behind the master's bare probes."""
    ctx = CheckContext(settings=ros2_master(), round_ids=ROUND)
    t0 = time.monotonic()
    waiter = asyncio.ensure_future(after_outsider_attempts(ctx, 5.0))
    await asyncio.sleep(0.3)
    assert not waiter.done()
    ctx.results["security.outsider"] = result("security.outsider")
    await asyncio.wait_for(waiter, 1.0)
    assert 0.3 <= time.monotonic() - t0 < 0.6


async def test_the_wait_is_bounded():
    ctx = CheckContext(settings=ros2_master(), round_ids=ROUND)
    t0 = time.monotonic()
    await asyncio.wait_for(after_outsider_attempts(ctx, 0.2), 2.0)
    assert 0.2 <= time.monotonic() - t0 < 0.5


async def test_no_wait_where_no_tls_handshake_is_refused_or_no_outsider_runs():
    relayed = ros2_master()
    relayed.relay = RelaySettings(host="relay.example.net")
    cases = [ros2_master(security="none"),    # a plain router takes the probes without a pause
             laptop_settings(),               # ROS 1: no Zenoh port
             relayed]                         # the relay's port: not the master's
    for settings in cases:
        ctx = CheckContext(settings=settings, round_ids=ROUND)
        t0 = time.monotonic()
        await after_outsider_attempts(ctx, 5.0)
        assert time.monotonic() - t0 < 0.1, settings
    ctx = CheckContext(settings=ros2_master(), round_ids=frozenset({"linux.chat_in"}))
    t0 = time.monotonic()
    await after_outsider_attempts(ctx, 5.0)     # the outsider is not in this round
    assert time.monotonic() - t0 < 0.1
