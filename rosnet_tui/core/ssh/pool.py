"""One SSH connection per peer for a round of checks.

A round runs up to seven checks that each need the peer's side (``linux.ssh``, the chats, the
port test, the node list, both pub/sub directions). Each used to make its own connection: seven
TCP handshakes, key exchanges and logins at once, and as many ``sshd`` processes on the peer.
:class:`SshPool` makes the first one and lets the others open channels on it (SSH multiplexes
sessions over one connection, as ``ssh -o ControlMaster`` does). A failed connection is shared
too: every check waiting on an unreachable peer gets the same verdict at the same moment.

Connections are made in threads (paramiko blocks), so a pool can start them before the event
loop runs: :meth:`SshPool.prestart` lets ``rosnet-tui check`` connect while it still imports the
checks. The pool lives as long as its round (:func:`rosnet_tui.core.checks.run_checks` closes
it).
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import threading
import time
from collections.abc import Iterable
from typing import Any

from rosnet_tui.core.config.settings_model import Peer
from rosnet_tui.core.ssh.connection import Conn, Holder, connect_blocking, failed
from rosnet_tui.core.ssh.options import SshOptions


def _key(opts: SshOptions | None, peer: Peer) -> tuple[object, ...]:
    """A connection's identity: the peer, and the way to it (directly, or through the relay
    to a tunnel port), so that a connection made one way is never handed out for the other."""
    route = getattr(opts, "relay", None)
    port = route.tunnel_port(peer.name) if route is not None else None
    via = (route.host, route.port, route.user, port) if route is not None and port else None
    return peer.name, int(peer.ssh_port or 22), peer.ssh_user, via


class SshPool:
    """Shared SSH connections of one round, by (name, port, user, the way to it)."""

    def __init__(self) -> None:
        self._conns: dict[tuple[object, ...], tuple[concurrent.futures.Future, Any]] = {}
        self._lock = threading.Lock()
        self.closed = False

    def start(self, opts: SshOptions | None, peer: Peer, timeout: float | None = None,
              tcp_timeout: float | None = None) -> concurrent.futures.Future:
        """The connection attempt to *peer* (a running or finished one is reused, unless its
        connection died). *timeout* bounds it (default: twice the round's timeout, the SSH
        check's own budget), *tcp_timeout* its TCP part (default: the round's timeout)."""
        base = float(getattr(opts, "timeout_s", 3.0) or 3.0)
        with self._lock:
            old = self._conns.get(_key(opts, peer))
            if old is not None:
                fut = old[0]
                if not fut.done():
                    return fut
                if not fut.cancelled():
                    t = fut.result().transport
                    if t is None or t.is_active():
                        return fut
            fut = concurrent.futures.Future()
            holder = Holder()
            now = time.monotonic()
            total = max(timeout or 0.0, 2 * base)
            deadline, tcp_deadline = now + total, now + min(tcp_timeout or base, total)

            def connect() -> None:
                try:
                    conn = connect_blocking(opts, peer, deadline, holder, tcp_deadline)
                except Exception as exc:  # noqa: BLE001 - a failure is a result
                    conn = failed("sshd", f"the SSH connection to {peer.name} broke: "
                                         f"{type(exc).__name__}: {exc}", tcp=None)
                try:
                    fut.set_result(conn)
                except concurrent.futures.InvalidStateError:
                    pass                          # cancelled: the round ended meanwhile
                if fut.cancelled() and conn.transport is not None:
                    conn.transport.close()

            if not self.closed:
                self._conns[_key(opts, peer)] = (fut, holder)
            threading.Thread(target=connect, daemon=True, name=f"rosnet-ssh-{peer.name}").start()
            return fut

    def prestart(self, opts: SshOptions | None, peers: Iterable[Peer]) -> None:
        """Start connecting to *peers* now (before the checks that will use them run)."""
        for p in peers:
            if p.ssh_user:
                self.start(opts, p)

    async def connect(self, opts: SshOptions | None, peer: Peer, timeout: float,
                      tcp_timeout: float | None = None) -> tuple[Conn, bool]:
        """(the connection, shared?) to *peer*, waiting at most *timeout* for it.

        The first caller starts the attempt (see :meth:`start`). *tcp_timeout* bounds this
        caller's wait for the TCP connection: once that is made (the peer answered), the caller
        may wait the rest of *timeout* for the SSH handshake.
        """
        fut = self.start(opts, peer, timeout)
        holder = self._conns.get(_key(opts, peer), (None, None))[1]
        loop = asyncio.get_running_loop()
        end = loop.time() + timeout
        first = min(timeout, tcp_timeout) if tcp_timeout is not None else timeout
        try:
            conn = await asyncio.wait_for(asyncio.shield(asyncio.wrap_future(fut)), first + 0.05)
        except asyncio.TimeoutError:
            connected = holder is not None and getattr(holder, "sock", None) is not None
            try:
                if not connected:
                    raise
                conn = await asyncio.wait_for(asyncio.shield(asyncio.wrap_future(fut)),
                                              max(end - loop.time(), 0.05))
            except asyncio.TimeoutError:
                return failed("timeout", f"no SSH connection to {peer.name} within "
                                        f"{first if not connected else timeout:.1f} s",
                             tcp="connected" if connected else None), False
        return conn, not self.closed

    def close(self) -> None:
        """Close every connection of the round (running attempts close theirs when done)."""
        with self._lock:
            self.closed = True
            conns, self._conns = list(self._conns.values()), {}
        for fut, holder in conns:
            if fut.done():
                with contextlib.suppress(Exception):
                    t = fut.result().transport
                    if t is not None:
                        t.close()
            else:     # its waiters are told now, while their event loop still runs
                holder.close()
                fut.cancel()
