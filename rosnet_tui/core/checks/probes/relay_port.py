"""router.port_open under a relay (issue 30): the relay's zenoh_port tested from this component.

No modem of the fleet forwards anything under a relay (every router dials it, the master's too),
so the port to test from outside is the relay's: one TCP connect to it by its name from here,
which is outside the relay's network."""

from __future__ import annotations

import asyncio
import time
from typing import Any

from rosnet_tui.core.checks import CheckContext
from rosnet_tui.core.net.connect import close_writer, tcp_failure_kind
from rosnet_tui.core.results import Outcome, Status
from rosnet_tui.core.ssh.connection import resolve_ipv4

PORT_WORDS = {"refused": "the connection was refused: nothing listens there (is `rosnet-tui "
                         "relay serve` running on it?)",
              "timeout": "no answer (dropped): is TCP {port} open in the relay's firewall and "
                         "its provider's?",
              "unreachable": "no route to it",
              "error": "the connection failed"}


async def relay_port_open(ctx: CheckContext, timeout: float) -> Outcome:
    """router.port_open's verdict under a relay, within *timeout*."""
    s = ctx.settings
    name, port = s.relay.host, s.relay.zenoh_port
    data: dict[str, Any] = {"ports": [], "test_port": s.probe.port, "public_ip": None,
                            "zenoh_port": port, "zenoh_port_open": None}
    deadline = time.monotonic() + timeout
    addrs, err = await resolve_ipv4(name, min(1.0, timeout * 0.25))
    if not addrs:
        return Outcome(Status.FAIL, f"the relay's name {name} does not resolve here ({err}), so "
                                    f"its TCP {port} cannot be tested", [], data)
    data["public_ip"] = addrs[0]
    kind = "connected"
    try:
        _reader, writer = await asyncio.wait_for(asyncio.open_connection(addrs[0], port),
                                                 max(deadline - time.monotonic(), 0.2))
        await close_writer(writer)
    except (OSError, asyncio.TimeoutError) as exc:
        kind = tcp_failure_kind(exc)
    is_open = True if kind == "connected" else (False if kind in ("refused", "timeout") else None)
    data["zenoh_port_open"] = is_open
    data["ports"] = [{"port": port, "reachable": is_open, "listener": False, "via": "here"}]
    ev = [f"{name} resolves to {addrs[0]}; TCP {port} there from {s.this.name or 'here'}: {kind}"]
    modems = "no modem of the fleet forwards anything (every router dials the relay)"
    if is_open:
        return Outcome(Status.PASS, f"the relay's TCP {port} ({name}, {addrs[0]}) is open from "
                                    f"here; {modems}", ev, data)
    return Outcome(Status.FAIL, f"the relay's TCP {port} ({name}, {addrs[0]}) is not open from "
                                f"here: {PORT_WORDS[kind].format(port=port)}; {modems}", ev, data)
