"""How a TCP connection attempt went, in one word: the evidence the advisor ranks causes by.

- ``connected``: the handshake completed;
- ``refused``: something at the address answered with a reset: it is online and rejects the
  port (a modem that does not forward it, or a machine where nothing listens on it);
- ``timeout``: nothing answered: the packets were dropped (a modem or firewall that drops, or
  nobody at the address);
- ``unreachable``: an ICMP error came back (no route, or a router found no machine at the local
  address it forwards to);
- ``error``: anything else.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import socket

TCP_KINDS = ("connected", "refused", "timeout", "unreachable", "error")


def tcp_failure_kind(exc: BaseException) -> str:
    """The kind of a failed connect: refused, timeout, unreachable or error."""
    if isinstance(exc, ConnectionRefusedError):
        return "refused"
    if isinstance(exc, (TimeoutError, socket.timeout, asyncio.TimeoutError)):
        return "timeout"
    if isinstance(exc, OSError) and exc.errno in (errno.EHOSTUNREACH, errno.ENETUNREACH,
                                                  errno.EHOSTDOWN):
        return "unreachable"
    return "error"


def kind_from_text(text: str) -> str:
    """The kind of a failure told in words (a peer's probe output: ``str(exception)``)."""
    low = text.lower()
    if "refused" in low:
        return "refused"
    if "timed out" in low or "timeout" in low:
        return "timeout"
    if "no route" in low or "unreachable" in low or "host is down" in low:
        return "unreachable"
    return "error"


async def close_writer(writer: asyncio.StreamWriter, wait_s: float = 0.5) -> None:
    """Close a stream, waiting at most *wait_s* for the far end (one that never acknowledges
    does not hold a check); whatever the closing raises is no news."""
    writer.close()
    with contextlib.suppress(Exception):
        await asyncio.wait_for(writer.wait_closed(), wait_s)
