"""Our own test-port listener: the ``nc -l PORT`` of the procedure, for the length of a check.

A :class:`TestListener` accepts TCP connections on a port, greets each with one line
(``ROSNET-TUI HELLO <token> <port>``), reads at most one line back (a chat message), echoes it
and hangs up. It only ever answers: it never connects anywhere. Connections are bounded in number,
size and time, and what was seen (source address, the line) is kept for evidence.

Checks that need a listener at the same time (``router.listener``, ``router.port_open``,
``linux.chat_in``) share them through a :class:`ListenerPool`: ``async with pool.hold(port)``
binds on first use and closes when the last holder leaves, so nothing stays open after a round.

Other runs of rosnet-tui on this machine (another technician, a script, the sync service, a
peer's chat over SSH) may want the same port at once: the pool takes the port's lock first
(:mod:`rosnet_tui.core.net.portshare`). The holder shares its listener (a :class:`SharedListener`
here: its token, and what it saw), or a peer's chat has the port for a moment and the pool waits
(bounded) for it; only a port held by something else fails to bind. A pool whose listener others
share keeps it open until they leave (at most :data:`LINGER_MAX_S`, awaited by :meth:`aclose`).
"""

from __future__ import annotations

import asyncio
import contextlib
import random
import secrets
import socket
import time
from collections import deque
from collections.abc import AsyncIterator, Callable, Iterable
from dataclasses import dataclass

from rosnet_tui.core.config.settings_model import PORT_MAX, PORT_MIN
from rosnet_tui.core.net.connect import close_writer
from rosnet_tui.core.net.portshare import (
    Holder,
    PortHost,
    ask_holder,
    follow,
    lock_held,
    process_words,
    take_lock,
    wait_gone,
)

GREETING = "ROSNET-TUI HELLO"
ECHO = "ROSNET-TUI ECHO"
MAX_LINE = 512
MAX_CONNECTIONS = 16
LINE_WAIT_S = 3.0
SHARE_WAIT_S = 1.0
"""How long a hold waits by default for another run of rosnet-tui to let go of the port."""
LINGER_MAX_S = 30.0
"""How long a pool keeps its listener open for the other runs that share it, after its own end."""


@dataclass(frozen=True)
class Seen:
    """One connection our listener accepted."""

    address: str
    line: str | None   # the line the caller sent, if any
    at: float          # time.monotonic()


class PortListener:
    """A listener on a test port as the checks see it (ours, or another run's shared with us):
    its port, the token its greeting carries, what it saw, and waiting for a line in it."""

    sharing: PortHost | None = None     # the port's lock and the runs sharing it, when ours

    def __init__(self, port: int, token: str) -> None:
        self.port = port
        self.token = token
        self.seen: deque[Seen] = deque(maxlen=64)
        self._changed = asyncio.Event()
        # How this run came by the port, when another run had it (evidence for the checks).
        self.note = ""

    @property
    def greeting(self) -> str:
        return f"{GREETING} {self.token} {self.port}"

    @property
    def listening(self) -> bool:
        raise NotImplementedError

    async def close(self) -> None:
        raise NotImplementedError

    def saw(self, address: str, line: str | None) -> None:
        self.seen.append(Seen(address, line, time.monotonic()))
        self._changed.set()

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


class TestListener(PortListener):
    """A listener on one port (all IPv4 addresses, like ``nc -l``)."""

    __test__ = False  # not a pytest test class

    def __init__(self, port: int, token: str, host: str = "0.0.0.0") -> None:
        super().__init__(port, token)
        self.host = host
        self._server: asyncio.base_events.Server | None = None
        self._slots = asyncio.Semaphore(MAX_CONNECTIONS)
        self._tasks: set[asyncio.Task] = set()
        self.sharing = None
        self.on_seen: Callable[[str, str | None], None] | None = None

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
        if self.sharing is not None:        # the lock goes last: no other run binds in between
            await self.sharing.close()
            self.sharing = None

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
            self.saw(str(peer[0]), line)
            if self.on_seen is not None:
                self.on_seen(str(peer[0]), line)
            await close_writer(writer, 1.0)
            if task is not None:
                self._tasks.discard(task)


async def own_port(port: int, token: str, lock: socket.socket) -> TestListener:
    """Our listener on *port* (greeting with *token*), shared through its *lock* (ours now)."""
    lst = TestListener(port, token)
    try:
        await lst.start()
        lst.sharing = PortHost(lock, token)
        await lst.sharing.start()
    except BaseException:
        lock.close()
        await lst.close()
        raise
    lst.on_seen = lst.sharing.tell
    return lst


class SharedListener(PortListener):
    """Another run's listener on the port, shared with us: its token, and what it tells us it
    saw. Should that run end first (even SIGKILLed), we take the port over with the same token,
    so that a peer's test under way still reaches a listener that greets as it expects."""

    def __init__(self, port: int, holder: Holder) -> None:
        super().__init__(port, holder.token)
        self.pid = holder.pid
        self._holder = holder
        self._own: TestListener | None = None   # after a take-over
        self._closed = False
        self._follow = asyncio.ensure_future(self._follow_holder())

    @property
    def listening(self) -> bool:
        return self._own.listening if self._own is not None else not self._follow.done()

    @property
    def sharing(self) -> PortHost | None:
        return self._own.sharing if self._own is not None else None

    async def _follow_holder(self) -> None:
        loop = asyncio.get_running_loop()
        while True:
            await follow(self._holder, self.saw)
            # The holder is gone: the port is ours now, or a newer holder's to share. Its lock
            # may outlive its link to us by a moment (a process ends fd by fd): a few tries.
            deadline = loop.time() + SHARE_WAIT_S
            while not self._closed and loop.time() < deadline:
                try:
                    lock = take_lock(self.port)
                except OSError:
                    return
                if lock is not None:
                    with contextlib.suppress(OSError):
                        self._own = await own_port(self.port, self.token, lock)
                        self._own.on_seen = self._took_over_saw
                    return
                holder = await ask_holder(self.port, max(deadline - loop.time(), 0.05))
                if holder.kind == "share":
                    self._holder, self.token, self.pid = holder, holder.token, holder.pid
                    break
                if holder.writer is not None:
                    holder.writer.close()
                await asyncio.sleep(0.02)
            else:
                return

    def _took_over_saw(self, address: str, line: str | None) -> None:
        self.saw(address, line)
        if self.sharing is not None:
            self.sharing.tell(address, line)

    async def close(self) -> None:
        self._closed = True
        if self._holder.writer is not None:
            self._holder.writer.close()
        self._follow.cancel()
        await asyncio.gather(self._follow, return_exceptions=True)
        if self._own is not None:
            await self._own.close()


class PortHeld(OSError):
    """The port is held by another run of rosnet-tui for longer than we could wait."""

    def __init__(self, port: int, pid: int | None, waited: float) -> None:
        super().__init__(98, f"another run of rosnet-tui ({process_words(pid)}) holds port "
                             f"{port} (waited {waited:.1f} s)")
        self.pid = pid


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
        self._listeners: dict[int, PortListener] = {}
        self._refs: dict[int, int] = {}
        self._lingering: dict[int, asyncio.Task] = {}
        self._lock: asyncio.Lock | None = None
        self._lock_loop: asyncio.AbstractEventLoop | None = None

    def _get_lock(self) -> asyncio.Lock:
        loop = asyncio.get_running_loop()
        if self._lock is None or self._lock_loop is not loop:
            self._lock, self._lock_loop = asyncio.Lock(), loop
        return self._lock

    def holds(self, port: int) -> bool:
        return port in self._listeners

    def get(self, port: int) -> PortListener | None:
        return self._listeners.get(port)

    def rosnet_listens(self, port: int) -> bool:
        """Whether a listener of rosnet-tui has *port*: ours, or another run's (a listener found
        on the port is then no service of the user's, and ``hold`` shares it)."""
        return port in self._listeners or lock_held(port)

    @contextlib.asynccontextmanager
    async def hold_spare(self, avoid: Iterable[int] = ()
                         ) -> AsyncIterator[PortListener]:
        """Our listener on a random port of the range that is free, for the ``async with`` body
        (raises the last OSError when none of :data:`SPARE_TRIES` ports could be bound)."""
        avoid = set(avoid) | set(self._listeners)
        problem: OSError | None = None
        for port in random_ports(SPARE_TRIES, avoid):
            try:
                cm = self.hold(port, wait_s=0.0)
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
    async def hold(self, port: int, wait_s: float = SHARE_WAIT_S
                   ) -> AsyncIterator[PortListener]:
        """A listener on *port* for the ``async with`` body: ours, or another run's shared with
        us; waits at most *wait_s* for a run that has the port alone (raises OSError if it cannot
        bind, PortHeld when another run of rosnet-tui still has it)."""
        async with self._get_lock():
            lst = self._listeners.get(port)
            if lst is None:
                lst = await self._open(port, wait_s)
                self._listeners[port] = lst
                self._refs[port] = 0
            linger = self._lingering.pop(port, None)
            if linger is not None:
                linger.cancel()
            self._refs[port] += 1
        try:
            yield lst
        finally:
            async with self._get_lock():
                self._refs[port] -= 1
                if self._refs[port] <= 0:
                    if lst.sharing is not None and lst.sharing.guests:
                        self._lingering[port] = asyncio.ensure_future(self._linger(port, lst))
                    else:
                        await self._drop(port, lst)

    async def _open(self, port: int, wait_s: float) -> PortListener:
        """Take *port*: its lock and a listener, or a share of another run's (see the module)."""
        loop = asyncio.get_running_loop()
        start = loop.time()
        deadline = start + max(wait_s, 0.0)
        last: Holder | None = None
        while True:
            try:
                sock = take_lock(port)
            except OSError:                 # no abstract sockets here: the port alone
                break
            if sock is not None:
                lst = await own_port(port, self.token, sock)
                if last is not None:
                    lst.note = (f"another check run had the test port ({process_words(last.pid)}):"
                                f" waited {loop.time() - start:.1f} s")
                return lst
            holder = await ask_holder(port, min(max(deadline - loop.time(), 0.05), 1.0))
            if holder.kind == "share":
                shared = SharedListener(port, holder)
                shared.note = (f"the test port's listener is shared with another check run of "
                               f"rosnet-tui ({process_words(holder.pid)})")
                return shared
            if holder.kind != "gone":
                last = holder
            left = deadline - loop.time()
            if left <= 0:
                if holder.writer is not None:
                    holder.writer.close()
                break
            if holder.kind == "gone":       # it just left, or is starting: try again
                await asyncio.sleep(min(0.02, left))
            else:                           # busy, or silent: wait for its end
                await wait_gone(holder, min(left, holder.busy_s + 0.5)
                                if holder.kind == "busy" else left)
        lst = TestListener(port, self.token)   # the wait is over: the port decides
        try:
            await lst.start()
        except OSError:
            if last is not None and last.kind == "busy":
                raise PortHeld(port, last.pid, loop.time() - start) from None
            raise
        return lst

    async def _linger(self, port: int, lst: PortListener) -> None:
        """Keep *lst* open while other runs share it (bounded), then close it."""
        assert lst.sharing is not None
        with contextlib.suppress(asyncio.TimeoutError):
            await asyncio.wait_for(lst.sharing.idle.wait(), LINGER_MAX_S)
        async with self._get_lock():
            if self._refs.get(port) == 0 and self._listeners.get(port) is lst:
                await self._drop(port, lst)

    async def _drop(self, port: int, lst: PortListener) -> None:
        """Close *lst*, then forget it: while it still listens, :meth:`rosnet_listens` says so
        (a check looking at the port meanwhile must not take it for a service of the user's)."""
        try:
            await lst.close()
        finally:
            if self._listeners.get(port) is lst:
                del self._listeners[port]
                self._refs.pop(port, None)
            self._lingering.pop(port, None)

    async def aclose(self) -> None:
        """The end of the round: wait for the runs that share our listeners (each at most
        :data:`LINGER_MAX_S`), then close whatever is still open."""
        tasks = list(self._lingering.values())
        try:
            if tasks:
                await asyncio.gather(*tasks, return_exceptions=True)
        finally:                            # cancelled too: nothing stays open
            for t in tasks:
                t.cancel()
            for port, lst in list(self._listeners.items()):
                if self._refs.get(port, 0) <= 0:
                    await asyncio.shield(self._drop(port, lst))
