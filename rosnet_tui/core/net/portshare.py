"""One test port, several runs of rosnet-tui: who holds it, and sharing its listener.

Two technicians, the wizard and a script, the sync service, or a peer's chat run over SSH may
all want the same test port on one machine at once. The first to take the port's *lock* binds
the port; the others do not blame the port on it:

- The lock is an abstract unix socket, ``\\0rosnet-tui/test-port/<port>``: it lives in the
  network namespace whose port it guards, any user may take it (the wizard as a user, the sync
  service as root), and the kernel drops it when its holder ends, SIGKILL included; there is no
  file to leave stale.
- Its holder answers each run that connects with one line: ``SHARE <token> <pid>`` (our listener
  is up: use it; then one ``SEEN <json [address, line]>`` line per connection it accepts), or
  ``BUSY <pid> <seconds>`` (a peer's chat holds the port alone for at most that long: wait).
  When the holder ends, the connection ends: a waiting run tries again.
- A holder that never answers (a stranger's process squatting the name) is waited for only as
  long as the caller allows; then the caller binds the port itself, and the bind's error is the
  honest verdict.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import socket
import struct
from collections.abc import Callable
from dataclasses import dataclass

from rosnet_tui.core.jsonsafe import loads_bounded

MAX_GUESTS = 32
LINE_LIMIT = 2048


def lock_name(port: int) -> str:
    """The abstract socket name of *port*'s lock (a leading NUL: no file)."""
    return f"\0rosnet-tui/test-port/{port}"


def take_lock(port: int) -> socket.socket | None:
    """*port*'s lock, bound and listening (None: another process holds it). Raises OSError when
    this system has no abstract unix sockets (not Linux)."""
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        s.bind(lock_name(port))
        s.listen(MAX_GUESTS)
    except OSError as exc:
        s.close()
        if exc.errno == 98:             # EADDRINUSE: held
            return None
        raise
    s.setblocking(False)
    return s


def lock_held(port: int) -> bool:
    """Whether a process holds *port*'s lock now (a run of rosnet-tui, as a rule)."""
    try:
        s = take_lock(port)
    except OSError:
        return False
    if s is not None:
        s.close()
    return s is None


def peer_pid(sock: socket.socket) -> int | None:
    """The pid of the process at the other end of a unix socket (SO_PEERCRED), if known."""
    try:
        raw = sock.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED, struct.calcsize("3i"))
        pid = struct.unpack("3i", raw)[0]
    except (OSError, struct.error):
        return None
    return pid or None


class PortHost:
    """The lock holder's side: answers each run that connects ``SHARE``, then tells it every
    connection our listener accepts. Guests are bounded in number; a guest's end is noticed."""

    def __init__(self, sock: socket.socket, token: str) -> None:
        self._sock = sock
        self.token = token
        self._server: asyncio.base_events.Server | None = None
        self._guests: set[asyncio.StreamWriter] = set()
        self.idle = asyncio.Event()
        self.idle.set()

    @property
    def guests(self) -> int:
        return len(self._guests)

    async def start(self) -> None:
        self._server = await asyncio.start_unix_server(self._guest, sock=self._sock,
                                                       limit=LINE_LIMIT)

    async def _guest(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        if len(self._guests) >= MAX_GUESTS:
            writer.close()
            return
        self._guests.add(writer)
        self.idle.clear()
        try:
            writer.write(f"SHARE {self.token} {os.getpid()}\n".encode())
            await writer.drain()
            while await reader.read(256):   # a guest only ever closes
                pass
        except (OSError, asyncio.CancelledError):
            pass
        finally:
            self._guests.discard(writer)
            if not self._guests:
                self.idle.set()
            writer.close()

    def tell(self, address: str, line: str | None) -> None:
        """Pass one connection our listener accepted on to every guest."""
        msg = ("SEEN " + json.dumps([address, line]) + "\n").encode()
        for w in list(self._guests):
            if not w.is_closing() and w.transport.get_write_buffer_size() < 65536:
                w.write(msg)

    async def close(self) -> None:
        for w in list(self._guests):
            w.close()
        if self._server is not None:
            self._server.close()
            with contextlib.suppress(Exception):
                await asyncio.wait_for(self._server.wait_closed(), 1.0)
            self._server = None
        self._sock.close()
        self._guests.clear()
        self.idle.set()


@dataclass
class Holder:
    """What the lock's holder said when we connected."""

    kind: str                   # "share", "busy", "silent" (nothing said in time), "gone"
    pid: int | None = None      # its pid (SO_PEERCRED, or what it said)
    token: str = ""             # share: its listener's token
    busy_s: float = 0.0         # busy: at most this long
    reader: asyncio.StreamReader | None = None
    writer: asyncio.StreamWriter | None = None


async def ask_holder(port: int, timeout: float) -> Holder:
    """Connect to *port*'s lock and read its holder's first line (within *timeout*).

    ``share``: the connection stays open (the guest's link; close it to leave); otherwise it is
    closed, except ``busy`` and ``silent``, kept open so that the caller can wait for its end."""
    try:
        reader, writer = await asyncio.wait_for(
            asyncio.open_unix_connection(lock_name(port), limit=LINE_LIMIT), timeout)
    except (OSError, asyncio.TimeoutError):
        return Holder("gone")
    sock = writer.get_extra_info("socket")
    pid = peer_pid(sock) if sock is not None else None
    try:
        raw = await asyncio.wait_for(reader.readline(), timeout)
    except asyncio.TimeoutError:
        return Holder("silent", pid, reader=reader, writer=writer)
    except (OSError, ValueError):
        raw = b""
    words = raw.decode("ascii", "replace").split()
    if len(words) == 3 and words[0] == "SHARE":
        return Holder("share", pid, words[1], reader=reader, writer=writer)
    if len(words) == 3 and words[0] == "BUSY":
        try:
            busy = min(max(float(words[2]), 0.0), 600.0) if words[2].isascii() else 0.0
        except ValueError:
            busy = 0.0
        return Holder("busy", pid, busy_s=busy, reader=reader, writer=writer)
    writer.close()
    return Holder("gone" if not raw else "silent", pid)


async def wait_gone(holder: Holder, timeout: float) -> bool:
    """Wait (at most *timeout*) until the holder ends its connection; whether it did."""
    if holder.reader is None or holder.writer is None:
        return True
    try:
        while True:
            if not await asyncio.wait_for(holder.reader.read(256), timeout):
                return True
    except (OSError, ValueError):
        return True
    except asyncio.TimeoutError:
        return False
    finally:
        holder.writer.close()


async def follow(holder: Holder, on_seen: Callable[[str, str | None], None]) -> None:
    """Read the holder's SEEN lines into *on_seen* until it ends (then returns)."""
    assert holder.reader is not None
    with contextlib.suppress(OSError, ValueError, asyncio.IncompleteReadError):
        while line := await holder.reader.readline():
            if not line.startswith(b"SEEN "):
                continue
            try:
                address, text = loads_bounded(line[5:].decode("utf-8", "replace"))
            except (ValueError, TypeError):
                continue
            if isinstance(address, str) and (text is None or isinstance(text, str)):
                on_seen(address[:64], None if text is None else text[:512])


def process_words(pid: int | None) -> str:
    """``pid N`` and, when readable here, what it runs (for messages)."""
    if pid is None:
        return "pid unknown"
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            cmd = f.read(300).replace(b"\0", b" ").decode("utf-8", "replace").strip()
    except OSError:
        cmd = ""
    cmd = " ".join("".join(c for c in cmd if c.isprintable()).split()[:3])[:100]
    return f"pid {pid}" + (f": {cmd}" if cmd else "")
