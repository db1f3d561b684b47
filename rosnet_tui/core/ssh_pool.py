"""One SSH connection per peer for a round of checks.

A round runs up to seven checks that each need the peer's side (``linux.ssh``, the chats, the
port test, the node list, both pub/sub directions). Each used to make its own connection: seven
TCP handshakes, key exchanges and logins at once, and as many ``sshd`` processes on the peer.
:class:`SshPool` makes the first one and lets the others open channels on it (SSH multiplexes
sessions over one connection, as ``ssh -o ControlMaster`` does). A failed connection is shared
too: every check waiting on an unreachable peer gets the same verdict at the same moment.

The pool lives as long as its round (:func:`rosnet_tui.core.checks.run_checks` closes it).
"""

from __future__ import annotations

import asyncio
import contextlib
from typing import TYPE_CHECKING

from rosnet_tui.core.settings import Peer

if TYPE_CHECKING:
    from rosnet_tui.core.ssh import SshOptions, SshSession, _Conn


class SshPool:
    """Shared SSH connections of one round, by (name, port, user)."""

    def __init__(self) -> None:
        self._conns: dict[tuple[str, int, str], asyncio.Future[_Conn]] = {}
        self.closed = False

    async def connect(self, opts: SshOptions | None, peer: Peer, timeout: float,
                      tcp_timeout: float | None = None) -> tuple[_Conn, bool]:
        """(the connection, shared?) to *peer*, waiting at most *timeout* for it.

        The first caller starts the connection; its budget is the longer of *timeout* and twice
        the round's timeout (the SSH check's own), its TCP phase bounded by *tcp_timeout* (else
        the round's timeout). Later callers wait on the same attempt, each for its own
        *timeout*. A connection that died is made again.
        """
        from rosnet_tui.core.ssh import _connect

        key = (peer.name, int(peer.ssh_port or 22), peer.ssh_user)
        fut = self._conns.get(key)
        if fut is not None and fut.done() and not fut.cancelled() and fut.exception() is None:
            t = fut.result().transport
            if t is not None and not t.is_active():
                fut = None
        if fut is None or self.closed:
            base = float(getattr(opts, "timeout_s", 3.0) or 3.0)
            tcp = tcp_timeout if tcp_timeout is not None else base
            fut = asyncio.ensure_future(_connect(opts, peer, max(timeout, 2 * base), tcp))
            if self.closed:   # after close(): a private connection, the caller closes it
                conn = await _wait(fut, timeout, peer)
                return conn, False
            self._conns[key] = fut
        return await _wait(fut, timeout, peer), True

    def close(self) -> None:
        """Close every connection of the round (running attempts close theirs when done)."""
        self.closed = True
        conns, self._conns = list(self._conns.values()), {}
        for fut in conns:
            if fut.done():
                with contextlib.suppress(Exception):
                    t = fut.result().transport
                    if t is not None:
                        t.close()
            else:
                fut.add_done_callback(_close_when_done)


def _close_when_done(fut: asyncio.Future) -> None:
    with contextlib.suppress(Exception):
        t = fut.result().transport
        if t is not None:
            t.close()


async def _wait(fut: asyncio.Future, timeout: float, peer: Peer) -> _Conn:
    from rosnet_tui.core.ssh import _fail

    try:
        return await asyncio.wait_for(asyncio.shield(fut), timeout + 0.5)
    except asyncio.TimeoutError:
        return _fail("timeout", f"no SSH connection to {peer.name} within {timeout:.1f} s",
                     tcp=None)


async def open_session(opts: SshOptions | None, peer: Peer, command: str, timeout: float,
                       tcp_timeout: float | None = None) -> SshSession:
    """Connect (or share the pool's connection) and start *command*; never raises.

    A shared connection that refuses one more channel (sshd's MaxSessions) makes way for a
    connection of the session's own.
    """
    from rosnet_tui.core.ssh import SshResult, SshSession, _connect, run_blocking

    pool = getattr(opts, "pool", None)
    if pool is not None:
        conn, shared = await pool.connect(opts, peer, timeout, tcp_timeout)
    else:
        conn, shared = await _connect(opts, peer, timeout, tcp_timeout), False
    session = SshSession(peer, conn, timeout, shared=shared)
    if conn.transport is None:
        return session
    try:
        await run_blocking(session._start, command, timeout=timeout + 0.5)
        return session
    except Exception as exc:  # noqa: BLE001 - paramiko's channel errors, or no answer in time
        problem = exc
    if shared:
        conn = await _connect(opts, peer, timeout, tcp_timeout)
        session = SshSession(peer, conn, timeout)
        if conn.transport is None:
            return session
        try:
            await run_blocking(session._start, command, timeout=timeout + 0.5)
            return session
        except Exception as exc:  # noqa: BLE001
            problem = exc
    session.close()
    r = conn.result
    session.result = SshResult(False, None, "", "", "sshd",
                               f"{peer.name} did not run the command: "
                               f"{problem or type(problem).__name__}",
                               r.fingerprint, r.host_key, r.address, r.tcp)
    session._chan = None
    return session
