"""SSH to a peer by name (the sessions; connecting is in :mod:`.connection`): verified host keys, keys only, every step under a deadline.

Two entry points, both async and both returning results rather than raising:

- :func:`ssh_run` runs one command (optionally fed *stdin*) and returns an :class:`SshResult`.
- :func:`ssh_session` starts a command and keeps it running while the caller does something
  locally (e.g. the peer listens while we connect to it); the caller reads its output as it
  arrives, writes to its stdin, then waits for it to end.

Connecting follows what ``ssh user@name`` does, minus anything interactive: the peer's *name* is
resolved by this machine, the server's host key must already be in ``~/.ssh/known_hosts`` (or
``/etc/ssh/ssh_known_hosts``) — an unknown key stops before authentication and reports its
fingerprint, a different key is refused — and authentication uses the keys in ``~/.ssh`` and the
SSH agent, never a password. Failures are classified (network, sshd, host key, auth, ...) so the
advisor can say what to fix. paramiko is blocking; it runs in daemon threads (see
:func:`run_blocking`) and a cancelled caller closes the socket so the thread ends at once.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import time
from collections.abc import AsyncIterator
from typing import TYPE_CHECKING

from rosnet_tui.core.config.settings_model import Peer
from rosnet_tui.core.net.blocking import run_blocking
from rosnet_tui.core.ssh.connection import Conn, SshResult, connect
from rosnet_tui.core.ssh.options import SshOptions

if TYPE_CHECKING:
    import paramiko

_POLL_S = 0.02
_SEND_CHUNK = 32768     # what one SSH data packet carries (paramiko cuts to the peer's maximum)
RETRY_MIN_S = 1.0
"""A command whose shared connection broke under it runs again only with this much time left."""
EOF_GRACE_S = 1.0
"""How long after the exit status the output's end is waited for: sshd may send the status before
the last output (a process the command left behind may also hold the output open)."""


# --------------------------------------------------------------------------- sessions
class _Wake:
    """Set by paramiko's thread when output (or the channel's end) arrives: wakes the session's
    reader in its event loop at once, instead of at its next poll."""

    def __init__(self, loop: asyncio.AbstractEventLoop, event: asyncio.Event) -> None:
        self.loop, self.event = loop, event

    def set(self) -> None:
        with contextlib.suppress(RuntimeError):   # the loop is closed: nobody waits any more
            self.loop.call_soon_threadsafe(self.event.set)

    def clear(self) -> None:
        pass


class SshSession:
    """A remote command that keeps running while we work; see :func:`ssh_session`.

    ``ok`` is False when the connection failed (``result`` says why); the I/O methods are then
    no-ops. Reads never block the event loop: the channel is polled.
    """

    def __init__(self, peer: Peer, conn: Conn, timeout: float, *, shared: bool = False) -> None:
        self.peer = peer
        self.result = conn.result
        self.timeout = timeout
        self._shared = shared          # the connection belongs to a pool: close only our channel
        self._transport = conn.transport
        self._said = conn.said
        self._chan: paramiko.Channel | None = None
        self._out = bytearray()
        self._err = bytearray()
        self._exited_at: float | None = None   # when the exit status arrived
        self._arrived: asyncio.Event | None = None  # output or the end came (see _nap)
        self._input_short: tuple[int, int] | None = None   # (bytes sent, of) when write failed
        self._cut = False     # the connection died before the output's end (EOF) came

    @property
    def ok(self) -> bool:
        return self._chan is not None

    @property
    def stdout(self) -> str:
        return self._out.decode("utf-8", "replace")

    @property
    def stderr(self) -> str:
        return self._err.decode("utf-8", "replace")

    def _start(self, command: str) -> None:
        assert self._transport is not None
        chan = self._transport.open_session(timeout=self.timeout)
        chan.setblocking(False)
        chan.exec_command(command)
        self._chan = chan

    async def _nap(self) -> None:
        """Wait until output or the channel's end arrives, at most one poll interval (the exit
        status alone wakes nobody: it is seen at the next poll)."""
        chan = self._chan
        if self._arrived is None and chan is not None:
            self._arrived = asyncio.Event()
            wake = _Wake(asyncio.get_running_loop(), self._arrived)
            chan.in_buffer.set_event(wake)
            chan.in_stderr_buffer.set_event(wake)
        if self._arrived is None:
            await asyncio.sleep(_POLL_S)
            return
        with contextlib.suppress(asyncio.TimeoutError):
            await asyncio.wait_for(self._arrived.wait(), _POLL_S)
        self._arrived.clear()

    def _pump(self) -> bool:
        """Move whatever arrived into the buffers; True when the channel is finished.

        The channel's state is read before its buffers are emptied: paramiko queues data before
        it marks the end that follows it, so output that came with the end is never left behind.
        """
        chan = self._chan
        if chan is None:
            return True
        finished = self._finished(chan)
        while chan.recv_ready():
            data = chan.recv(65536)
            if not data:
                break
            self._out += data
        while chan.recv_stderr_ready():
            data = chan.recv_stderr(65536)
            if not data:
                break
            self._err += data
        return finished

    def _finished(self, chan: paramiko.Channel) -> bool:
        if chan.closed or not (self._transport and self._transport.is_active()):
            # closed with no EOF first: the connection died (paramiko closes its channels then),
            # and output may still have been coming (sshd may send the exit status before it)
            self._cut = not chan.eof_received
            return True
        if not chan.exit_status_ready() or chan.recv_ready() or chan.recv_stderr_ready():
            return False
        if chan.eof_received:           # the output ended: nothing more can come
            return True
        if self._exited_at is None:
            self._exited_at = time.monotonic()
        return time.monotonic() - self._exited_at > EOF_GRACE_S

    async def write(self, data: bytes | str) -> bool:
        """Send *data* to the command's stdin; False when it could not be sent."""
        import paramiko

        if self._chan is None:
            return False
        buf = data.encode() if isinstance(data, str) else bytes(data)
        sent, total, deadline = 0, len(buf), time.monotonic() + self.timeout
        while sent < total:
            try:
                if self._chan.send_ready():
                    # a packet's worth at a time (no copy of the rest), letting others run
                    n = self._chan.send(buf[sent:sent + _SEND_CHUNK])
                    if n <= 0:
                        break
                    sent += n
                    await asyncio.sleep(0)
                    continue
            except (OSError, EOFError, paramiko.SSHException):   # EOFError: the link died
                break
            if time.monotonic() > deadline or self._chan.closed:
                break
            await asyncio.sleep(_POLL_S)
        if sent < total:    # the result says so: a program fed on stdin may have run cut short
            self._input_short = (sent, total)
        return sent == total

    async def close_stdin(self) -> None:
        if self._chan is not None:
            with contextlib.suppress(Exception):
                self._chan.shutdown_write()

    async def read_until(self, marker: str, timeout: float | None = None) -> str | None:
        """Wait until stdout contains *marker*; the stdout so far, or None on timeout or exit."""
        if self._chan is None:
            return None
        deadline = time.monotonic() + (self.timeout if timeout is None else timeout)
        while True:
            done = self._pump()
            if marker in self.stdout:
                return self.stdout
            if done or time.monotonic() > deadline:
                return None
            await self._nap()

    async def wait(self, timeout: float | None = None) -> SshResult:
        """Wait for the command to end; its result (failure "timeout" if it did not end)."""
        if self._chan is None:
            return self.result
        deadline = time.monotonic() + (self.timeout if timeout is None else timeout)
        while not self._pump():
            if time.monotonic() > deadline:
                return SshResult(False, None, self.stdout, self.stderr, "timeout",
                                 f"the command on {self.peer.name} did not finish in time",
                                 self.result.fingerprint, self.result.host_key, self.result.address,
                                 self.result.tcp)
            await self._nap()
        # paramiko keeps -1 until an exit-status arrives (real ones are unsigned): a command a
        # signal ended, or a channel the broken connection closed, has none.
        status = self._chan.exit_status if self._chan.exit_status >= 0 else None
        if status is not None:
            detail = f"ran on {self.peer.name} as {self.peer.ssh_user}, exit status {status}"
        elif self.connection_broke:
            detail = f"the SSH connection to {self.peer.name} broke while the command ran"
        else:
            detail = (f"the command on {self.peer.name} ended without an exit status "
                      "(a signal ended it, or sshd closed the session)")
        if status is not None and self._cut:
            detail += "; the SSH connection broke before its output ended (it may be cut short)"
        if self._input_short is not None:
            detail += (f"; only {self._input_short[0]} of the {self._input_short[1]} bytes of "
                       "its input were sent (it ended first, or the link broke)")
        detail += self._said
        return SshResult(status is not None, status, self.stdout, self.stderr,
                         None if status is not None else "sshd", detail,
                         self.result.fingerprint, self.result.host_key, self.result.address,
                         self.result.tcp)

    @property
    def output_cut(self) -> bool:
        """True when the connection died before the command's output ended: what was read may
        be only a part (the exit status, which sshd may send first, can have come)."""
        return self._cut

    @property
    def connection_broke(self) -> bool:
        """True when the connection under this session is gone (it was made, then died)."""
        return self._transport is not None and not self._transport.is_active()

    def close(self) -> None:
        if self._chan is not None:
            with contextlib.suppress(Exception):
                self._chan.close()
        if self._transport is not None and not self._shared:
            with contextlib.suppress(Exception):
                self._transport.close()


async def open_session(opts: SshOptions | None, peer: Peer, command: str, timeout: float,
                       tcp_timeout: float | None = None) -> SshSession:
    """Connect (or share the pool's connection) and start *command*; never raises.

    A shared connection that refuses one more channel (sshd's MaxSessions) makes way for a
    connection of the session's own.
    """
    pool = getattr(opts, "pool", None)
    if pool is not None:
        conn, shared = await pool.connect(opts, peer, timeout, tcp_timeout)
    else:
        conn, shared = await connect(opts, peer, timeout, tcp_timeout), False
    session = SshSession(peer, conn, timeout, shared=shared)
    if conn.transport is None:
        return session
    try:
        await run_blocking(session._start, command, timeout=timeout + 0.5)
        return session
    except Exception as exc:  # noqa: BLE001 - paramiko's channel errors, or no answer in time
        problem = exc
    if shared:
        conn = await connect(opts, peer, timeout, tcp_timeout)
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


@contextlib.asynccontextmanager
async def ssh_session(opts: SshOptions | None, peer: Peer, command: str, *,
                      timeout: float | None = None,
                      tcp_timeout: float | None = None) -> AsyncIterator[SshSession]:
    """Start *command* on *peer* and keep it running for the ``async with`` body.

    ``timeout`` bounds the connection (and is the default for reads/waits), ``tcp_timeout`` its
    TCP part (only a peer that answered may use the rest); with a pool in *opts* the session is a
    channel on the round's connection to *peer*. On leaving the block
    the channel and connection are closed; the remote command must bound itself (sshd does not
    kill a command without a terminal when the channel closes). Usage::

        async with ssh_session(opts, peer, "python3 -c ...") as s:
            if not s.ok:
                return s.result            # failure says why (network, host key, auth, ...)
            await s.read_until("LISTENING")
            ...                            # act locally while the peer listens
            res = await s.wait(5)
    """
    t = float(timeout if timeout is not None else (getattr(opts, "timeout_s", 3.0) or 3.0))
    session = await open_session(opts, peer, command, t, tcp_timeout)
    try:
        yield session
    finally:
        session.close()


async def ssh_run(opts: SshOptions | None, peer: Peer, command: str, *,
                  stdin: bytes | str | None = None, timeout: float | None = None,
                  connect_timeout: float | None = None,
                  tcp_timeout: float | None = None) -> SshResult:
    """Run *command* on *peer* (by name, as ``peer.ssh_user``) within *timeout* seconds overall.

    *connect_timeout* (default: *timeout*) bounds reaching and logging in to the peer, so a
    caller can keep time for something else when the peer is unreachable; *tcp_timeout* bounds
    the TCP connection within it (see :func:`ssh_session`).
    """
    t = float(timeout if timeout is not None else (getattr(opts, "timeout_s", 3.0) or 3.0))
    deadline = time.monotonic() + t
    ct = min(float(connect_timeout), t) if connect_timeout is not None else t
    for attempt in (1, 2):
        async with ssh_session(opts, peer, command, timeout=min(ct, deadline - time.monotonic()),
                               tcp_timeout=tcp_timeout) as s:
            if not s.ok:
                return s.result
            if stdin:
                await s.write(stdin)
            await s.close_stdin()
            res = await s.wait(max(deadline - time.monotonic(), 0.05))
            broke = s._shared and s.connection_broke and (res.exit_status is None or s.output_cut)
        if attempt == 2:
            return dataclasses.replace(res, detail=res.detail + " (ran again: the round's "
                                                                "connection broke under the first run)")
        # The round's shared connection died under the command (a dropped mobile link, sshd's
        # process for it gone): the pool makes a new one, and the command runs once more.
        if not broke or deadline - time.monotonic() < RETRY_MIN_S:
            return res
    raise AssertionError("unreachable")
