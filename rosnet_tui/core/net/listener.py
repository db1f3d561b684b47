"""Our own test-port listener: the ``nc -l PORT`` of the procedure, for the length of a check.

A :class:`TestListener` accepts TCP connections on a port, greets each with one line
(``ROSNET-TUI HELLO <token> <port>``), reads at most one line back (a chat message), echoes it
and hangs up. It only ever answers: it never connects anywhere. Connections are bounded in number,
size and time, and what was seen (source address, the line) is kept for evidence.

Checks that need a listener at the same time (``router.listener``, ``router.port_open``,
``linux.chat_in``) share them through a :class:`ListenerPool`: ``async with pool.hold(port)``
binds on first use and closes when the last holder leaves, so nothing stays open after a round.
"""

from __future__ import annotations

import asyncio
import contextlib
import random
import secrets
import time
from collections import deque
from collections.abc import AsyncIterator, Iterable
from dataclasses import dataclass

from rosnet_tui.core.config.settings_model import PORT_MAX, PORT_MIN
from rosnet_tui.core.net.connect import close_writer

GREETING = "ROSNET-TUI HELLO"
ECHO = "ROSNET-TUI ECHO"
MAX_LINE = 512
MAX_CONNECTIONS = 16
LINE_WAIT_S = 3.0


@dataclass(frozen=True)
class Seen:
    """One connection our listener accepted."""

    address: str
    line: str | None   # the line the caller sent, if any
    at: float          # time.monotonic()


class TestListener:
    """A listener on one port (all IPv4 addresses, like ``nc -l``)."""

    __test__ = False  # not a pytest test class

    def __init__(self, port: int, token: str, host: str = "0.0.0.0") -> None:
        self.port = port
        self.token = token
        self.host = host
        self.seen: deque[Seen] = deque(maxlen=64)
        self._server: asyncio.base_events.Server | None = None
        self._changed = asyncio.Event()
        self._slots = asyncio.Semaphore(MAX_CONNECTIONS)
        self._tasks: set[asyncio.Task] = set()

    @property
    def greeting(self) -> str:
        return f"{GREETING} {self.token} {self.port}"

    @property
    def listening(self) -> bool:
        return self._server is not None and self._server.is_serving()

    async def start(self) -> None:
        """Bind and listen; raises OSError (e.g. EADDRINUSE) when the port cannot be had."""
        self._server = await asyncio.start_server(self._handle, self.host, self.port,
                                                  reuse_address=True, backlog=16)

    async def close(self) -> None:
        if self._server is not None:
            self._server.close()
            with contextlib.suppress(Exception):
                await asyncio.wait_for(self._server.wait_closed(), 1.0)
            self._server = None
        for t in list(self._tasks):
            t.cancel()
        if self._tasks:
            await asyncio.gather(*self._tasks, return_exceptions=True)

    async def _handle(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        if task is not None:
            self._tasks.add(task)
        peer = writer.get_extra_info("peername") or ("?", 0)
        line: str | None = None
        try:
            if self._slots.locked():
                return
            async with self._slots:
                writer.write((self.greeting + "\n").encode())
                await asyncio.wait_for(writer.drain(), LINE_WAIT_S)
                try:
                    raw = await asyncio.wait_for(reader.readline(), LINE_WAIT_S)
                except (asyncio.TimeoutError, ValueError):
                    raw = b""
                raw = raw[:MAX_LINE]
                if raw.strip():
                    line = raw.decode("utf-8", "replace").strip()
                    line = "".join(c for c in line if c.isprintable())
                    writer.write(f"{ECHO} {line}\n".encode())
                    with contextlib.suppress(Exception):
                        await asyncio.wait_for(writer.drain(), LINE_WAIT_S)
        except (OSError, asyncio.TimeoutError):
            pass
        finally:
            self.seen.append(Seen(str(peer[0]), line, time.monotonic()))
            self._changed.set()
            await close_writer(writer, 1.0)
            if task is not None:
                self._tasks.discard(task)

    async def wait_for_line(self, needle: str, timeout: float) -> Seen | None:
        """The first connection whose line contains *needle*, waiting up to *timeout* s."""
        deadline = time.monotonic() + timeout
        while True:
            for s in self.seen:
                if s.line and needle in s.line:
                    return s
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            self._changed.clear()
            with contextlib.suppress(asyncio.TimeoutError):
                await asyncio.wait_for(self._changed.wait(), left)


SPARE_TRIES = 12
"""Random ports of the range tried for a spare listener: one can be taken (a service, or the local
end of one of this machine's own connections, which Linux draws from the same numbers)."""


def random_ports(n: int, avoid: Iterable[int] = ()) -> list[int]:
    """*n* distinct random ports of the forwarded range, none of them in *avoid*."""
    rng, avoid = random.SystemRandom(), set(avoid)
    out: list[int] = []
    while len(out) < n:
        p = rng.randint(PORT_MIN, PORT_MAX)
        if p not in avoid and p not in out:
            out.append(p)
    return out


class ListenerPool:
    """Reference-counted listeners shared by the checks of a round (one per port)."""

    def __init__(self) -> None:
        self.token = secrets.token_hex(6)
        self._listeners: dict[int, TestListener] = {}
        self._refs: dict[int, int] = {}
        self._lock: asyncio.Lock | None = None
        self._lock_loop: asyncio.AbstractEventLoop | None = None

    def _get_lock(self) -> asyncio.Lock:
        loop = asyncio.get_running_loop()
        if self._lock is None or self._lock_loop is not loop:
            self._lock, self._lock_loop = asyncio.Lock(), loop
        return self._lock

    def holds(self, port: int) -> bool:
        return port in self._listeners

    def get(self, port: int) -> TestListener | None:
        return self._listeners.get(port)

    @contextlib.asynccontextmanager
    async def hold_spare(self, avoid: Iterable[int] = ()) -> AsyncIterator[TestListener]:
        """Our listener on a random port of the range that is free, for the ``async with`` body
        (raises the last OSError when none of :data:`SPARE_TRIES` ports could be bound)."""
        avoid = set(avoid) | set(self._listeners)
        problem: OSError | None = None
        for port in random_ports(SPARE_TRIES, avoid):
            try:
                cm = self.hold(port)
                lst = await cm.__aenter__()
            except OSError as exc:
                problem = exc
                continue
            async with contextlib.AsyncExitStack() as stack:
                stack.push_async_exit(cm)       # released as ``hold`` releases it
                yield lst
            return
        raise problem or OSError("no spare port")

    @contextlib.asynccontextmanager
    async def hold(self, port: int) -> AsyncIterator[TestListener]:
        """Our listener on *port* for the ``async with`` body (raises OSError if it cannot bind)."""
        async with self._get_lock():
            lst = self._listeners.get(port)
            if lst is None:
                lst = TestListener(port, self.token)
                await lst.start()
                self._listeners[port] = lst
                self._refs[port] = 0
            self._refs[port] += 1
        try:
            yield lst
        finally:
            async with self._get_lock():
                self._refs[port] -= 1
                if self._refs[port] <= 0:
                    del self._refs[port]
                    del self._listeners[port]
                    await lst.close()
