"""The master's side of the round's peer agents (the program: ``core/peer/agentproto.py``).

A round's checks used to start one interpreter per check and peer over SSH (node URIs, each
direction of the exchange, the graph): with 8 members that is two dozen interpreter starts, each
compiling its piped program again, all on the peers' CPU. A :class:`PeerAgent` is one SSH
channel and one interpreter per peer and round (per kind: the stdlib one of ROS 1, the installed
rosnet-tui's of ROS 2), started by the first check that needs it and shared by the others; each
probe is a run the agent forks (:class:`AgentCall`), with its own output, exit status and
timeout, so a check reads it as it read its own SSH session. :class:`PeerAgents` keeps a round's
agents (in the CheckContext, next to the SSH pool) and closes them with the round.

A peer the round cannot reach gives the SSH pool's classified failure, as before: every call
first waits for the peer's connection (``SshPool.connect``) within its own bounds. An agent that
ends before it is ready (no python3: exit 127; no rosnet-tui installed: the prelude's report)
gives every call that very output and exit status.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import itertools
import json
import zlib
from collections.abc import AsyncIterator, Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rosnet_tui.core.config.settings_model import Peer
from rosnet_tui.core.jsonsafe import loads_bounded
from rosnet_tui.core.peer import agentproto
from rosnet_tui.core.ssh.connection import SshResult
from rosnet_tui.core.ssh.options import SshOptions
from rosnet_tui.core.ssh.session import SshSession, open_session

AGENT_SOURCE = Path(agentproto.__file__).read_bytes()   # fed on stdin after BOOT reads its size


@functools.lru_cache(maxsize=8)
def boot_payload(programs: tuple[tuple[Any, ...], ...]) -> bytes:
    """What the master writes on an agent's stdin at its start: the agent's source compressed
    (after its length, as :data:`agentproto.BOOT` reads it), then the loads of *programs* (name,
    source, entry[, base]) as one zlib frame after its ``{"loadz": LENGTH}`` line. About 20 kB
    for ROS 2's agent instead of 58: on a 64 kbit/s line, under 3 s."""
    agent = zlib.compress(AGENT_SOURCE, 9)
    loads = b"".join((json.dumps({"load": p[0], "src": p[1].decode(), "entry": p[2],
                                  **({"base": p[3]} if len(p) > 3 else {})}) + "\n").encode()
                     for p in programs)
    frame = zlib.compress(loads, 9)
    return (f"{len(agent)}\n".encode() + agent
            + (json.dumps({"loadz": len(frame)}) + "\n").encode() + frame)
_POLL_S = 0.5     # how long one read of the agent's output waits before looking again


@dataclass(frozen=True)
class AgentKind:
    """A kind of agent: how the peer starts it (``command(max_s)``, a shell command running
    :data:`agentproto.BOOT` with the agent's life bound as its argument) and the programs it
    loads, as (name, source, entry function or None: run as ``__main__``)."""

    name: str
    command: Callable[[float], str]
    programs: Sequence[tuple[str, bytes, str | None] | tuple[str, bytes, str | None, str]]
    # What a run that needs the peer's rosnet-tui answers when the agent runs without one (the
    # install finder's fallback): (output, exit status), the finder's own report.
    no_install: tuple[str, int] | None = None


class AgentCall:
    """One probe run by a peer's agent: read like an SSH session (``ok``, ``result``,
    ``stdout``, ``read_until``, ``wait``, ``close``)."""

    def __init__(self, peer: Peer, result: SshResult, timeout: float,
                 agent: PeerAgent | None = None, rid: int | None = None) -> None:
        self.peer = peer
        self.result = result
        self.timeout = timeout
        self.agent, self.rid = agent, rid
        self.out: list[str] = []
        self.err: list[str] = []
        self.exit_status: int | None = None
        self.lost = False               # the agent's channel ended while this ran
        self.ended_detail = ""          # the agent ended before it was ready: how
        self.changed = asyncio.Event()

    @property
    def ok(self) -> bool:
        return self.result.failure is None

    @property
    def done(self) -> bool:
        return self.exit_status is not None or self.lost or not self.ok

    @property
    def stdout(self) -> str:
        return "".join(self.out)

    @property
    def stderr(self) -> str:
        return "".join(self.err)

    def feed(self, msg: dict[str, Any]) -> None:
        if "o" in msg:
            self.out.append(str(msg["o"]))
        if "e" in msg:
            self.err.append(str(msg["e"]))
        if "x" in msg:
            self.exit_status = int(msg["x"]) if isinstance(msg["x"], int) else 1
        self.changed.set()

    def end(self, result: SshResult | None = None) -> None:
        """The run is over without its exit status: the agent's channel ended (or, with
        *result*, the agent ended before it ran anything: its output and status are the run's)."""
        if result is not None:
            self.out, self.err = [result.stdout], [result.stderr]
            self.exit_status = result.exit_status
            self.lost = result.exit_status is None
            self.ended_detail = result.detail
        else:
            self.lost = True
        self.changed.set()

    async def _until(self, pred: Callable[[], bool], timeout: float) -> bool:
        loop = asyncio.get_running_loop()
        end = loop.time() + timeout
        while not pred():
            left = end - loop.time()
            if left <= 0:
                return False
            self.changed.clear()
            with contextlib.suppress(asyncio.TimeoutError):
                await asyncio.wait_for(self.changed.wait(), left)
        return True

    async def read_until(self, marker: str, timeout: float | None = None) -> str | None:
        """Wait until stdout contains *marker*; the stdout so far, or None on timeout or end."""
        if not self.ok:
            return None
        t = self.timeout if timeout is None else timeout
        await self._until(lambda: marker in self.stdout or self.done, t)
        return self.stdout if marker in self.stdout else None

    async def wait(self, timeout: float | None = None) -> SshResult:
        """Wait for the run to end; its result (failure "timeout" if it did not end)."""
        if not self.ok:
            return self.result
        r = self.result
        t = self.timeout if timeout is None else timeout
        if not await self._until(lambda: self.done, t):
            return SshResult(False, None, self.stdout, self.stderr, "timeout",
                             f"the command on {self.peer.name} did not finish in time",
                             r.fingerprint, r.host_key, r.address, r.tcp)
        if self.exit_status is None:
            return SshResult(False, None, self.stdout, self.stderr, "sshd",
                             f"the session with {self.peer.name} closed", r.fingerprint,
                             r.host_key, r.address, r.tcp)
        detail = (f"ran on {self.peer.name} as {self.peer.ssh_user} (the round's peer agent), "
                  f"exit status {self.exit_status}")
        if self.ended_detail:
            detail = f"the probe program on {self.peer.name} ended before it was ready: " \
                     f"{self.ended_detail}"
        return SshResult(True, self.exit_status, self.stdout, self.stderr, None, detail,
                         r.fingerprint, r.host_key, r.address, r.tcp)

    def close(self) -> None:
        """Stop the run if it still runs (the agent kills it)."""
        if self.agent is not None and self.rid is not None:
            self.agent.forget(self.rid, kill=not self.done)
            self.agent = None


class PeerAgent:
    """One peer's agent of one kind for a round."""

    def __init__(self, peer: Peer, kind: AgentKind) -> None:
        self.peer, self.kind = peer, kind
        self.session: SshSession | None = None
        self.started: asyncio.Task | None = None
        self.ended: SshResult | None = None    # it ended before it was ready: its result
        self.calls: dict[int, AgentCall] = {}
        self.ids = itertools.count(1)
        self.seq = 1                           # the number of the next line to read
        self.offset = 0                        # where in its stdout that line starts
        self.reader: asyncio.Task | None = None
        self.send_lock = asyncio.Lock()
        self.closed = False
        self.loaded: dict[str, bytes] = {}     # programs loaded after the start (call's source)
        self.ready_by = 0.0                    # loop time: the most patient caller's wait

    def start(self, opts: SshOptions | None, timeout: float, tcp_timeout: float | None,
              max_s: float, ready_s: float) -> asyncio.Task:
        """The start, shared by the round's callers: it waits for the agent as long as the most
        patient of them (*ready_s* from now, for this one) and no longer. A thin link takes
        seconds to carry the programs; a check with little time gives up, one that measures the
        link keeps the start going for itself."""
        self.ready_by = max(self.ready_by, asyncio.get_running_loop().time() + ready_s)
        if self.started is None:
            self.started = asyncio.ensure_future(self._start(opts, timeout, tcp_timeout, max_s))
        return self.started

    async def _wait_ready(self, s: SshSession) -> str | None:
        """The agent's output up to its ready line; None when it ended or nobody waits longer."""
        loop = asyncio.get_running_loop()
        while True:
            ready = await s.read_until(self._marker(), timeout=max(self.ready_by - loop.time(),
                                                                   0.0))
            if ready is not None or loop.time() >= self.ready_by:
                return ready
            if (await s.wait(0.0)).failure != "timeout":       # it ended
                return None

    async def _start(self, opts: SshOptions | None, timeout: float, tcp_timeout: float | None,
                     max_s: float) -> SshResult:
        payload = boot_payload(tuple(tuple(p) for p in self.kind.programs))
        for attempt in (1, 2):
            s = await open_session(opts, self.peer, self.kind.command(max_s), timeout,
                                   tcp_timeout)
            self.session = s
            if not s.ok:
                return s.result
            await s.write(payload)
            self.ready_by = max(self.ready_by, asyncio.get_running_loop().time()
                                + max(timeout, 2.0) * 2)      # the least any start is given
            ready = await self._wait_ready(s)
            if ready is not None and f'"{agentproto.READY}"' in ready:
                self._take_lines()
                self.reader = asyncio.ensure_future(self._read())
                return s.result
            res = await s.wait(0.0)
            if res.failure == "timeout":       # still running but silent: give up on it
                s.close()
                r = s.result
                return SshResult(False, None, res.stdout, res.stderr, "timeout",
                                 f"the probe program on {self.peer.name} did not start in time",
                                 r.fingerprint, r.host_key, r.address, r.tcp)
            s.close()
            # A channel closed under it without a word (no exit status, no output): once more.
            if attempt == 1 and res.exit_status is None and not (res.stdout or res.stderr):
                continue
            self.ended = res      # it ended: every run gets its output and exit status
            return s.result
        raise AssertionError("unreachable")

    def _marker(self) -> str:
        return f"#{self.seq}\n"

    def _take_lines(self) -> None:
        """Dispatch every whole line of the agent's output not yet taken."""
        assert self.session is not None
        text = self.session.stdout
        end = text.rfind("\n") + 1
        for line in text[self.offset:end].splitlines():
            body, _, seq = line.rpartition("#")
            if seq.isascii() and seq.isdigit():   # ASCII: int() refuses '¹'
                self.seq = int(seq) + 1
            try:
                msg = loads_bounded(body, unique_keys=False)
            except ValueError:      # JsonInputError: not a line of ours (or of a sane peer)
                continue
            call = self.calls.get(msg.get("id")) if isinstance(msg, dict) else None
            if call is not None:
                call.feed(msg)
        self.offset = max(self.offset, end)

    async def _read(self) -> None:
        s = self.session
        assert s is not None
        try:
            while not self.closed:
                got = await s.read_until(self._marker(), timeout=_POLL_S)
                self._take_lines()
                if got is None:
                    res = await s.wait(0.0)
                    if res.failure != "timeout":    # the channel ended
                        break
        finally:
            self.closed = True
            for call in list(self.calls.values()):
                call.end()
            self.calls.clear()

    async def send(self, *msgs: dict[str, Any]) -> bool:
        """Send *msgs* in this order, none of another sender's in between."""
        if self.session is None or self.closed:
            return False
        async with self.send_lock:
            return await self._write(msgs)

    async def _write(self, msgs: Sequence[dict[str, Any]]) -> bool:
        assert self.session is not None
        return await self.session.write("".join(json.dumps(m) + "\n" for m in msgs))

    async def call(self, program: str, argv: Sequence[str], timeout: float,
                   needs_install: bool = False, source: bytes | None = None,
                   send_within: float | None = None) -> AgentCall:
        """Start a run of *program*; with *source*, a program the agent's kind does not load
        at its start (run as ``__main__``): loaded first, once per agent (and again if its
        source changed). *send_within*: how long the request may wait for the channel, which
        another run's request holds while it is sent (a program's source takes seconds at
        64 kbit/s); then the run fails "timeout", nothing of it sent."""
        assert self.session is not None
        rid = next(self.ids)
        call = AgentCall(self.peer, self.session.result, timeout, self, rid)
        if self.ended is not None:
            call.end(self.ended)
            return call
        if self.closed:
            call.end()
            return call
        try:
            await asyncio.wait_for(self.send_lock.acquire(), send_within)
        except asyncio.TimeoutError:
            r = self.session.result
            return _failed(self.peer, SshResult(
                False, None, "", "", "timeout", f"the request to {self.peer.name} was not sent "
                f"in time: the line was busy with the round's other requests", r.fingerprint,
                r.host_key, r.address, r.tcp), timeout)
        try:
            self.calls[rid] = call
            msg: dict[str, Any] = {"run": program, "id": rid, "argv": list(argv)}
            if needs_install and self.kind.no_install is not None:
                msg["ni"] = list(self.kind.no_install)
            msgs = [msg]
            if source is not None and self.loaded.get(program) != source:
                self.loaded[program] = source
                msgs.insert(0, {"load": program, "src": source.decode(), "entry": None})
            sent = not self.closed and await self._write(msgs)
        finally:
            self.send_lock.release()
        if not sent:
            self.calls.pop(rid, None)
            call.end()
        return call

    def forget(self, rid: int, kill: bool) -> None:
        self.calls.pop(rid, None)
        if kill and not self.closed:
            with contextlib.suppress(RuntimeError):       # no event loop: the round is over
                asyncio.ensure_future(self.send({"kill": rid}))

    def close(self) -> None:
        self.closed = True
        for task in (self.started, self.reader):
            if task is not None and not task.done():
                task.cancel()
        if self.session is not None:
            self.session.close()     # the agent sees its stdin end and stops every run


def _key(peer: Peer, kind: AgentKind) -> tuple[str, int, str, str]:
    return peer.name, int(peer.ssh_port or 22), peer.ssh_user, kind.name


class PeerAgents:
    """The peer agents of one round, by (peer, kind)."""

    def __init__(self) -> None:
        self.agents: dict[tuple[str, int, str, str], PeerAgent] = {}
        self.closed = False

    def get(self, peer: Peer, kind: AgentKind) -> PeerAgent:
        key = _key(peer, kind)
        agent = self.agents.get(key)
        if agent is None or (agent.closed and agent.ended is None and not self.closed):
            agent = self.agents[key] = PeerAgent(peer, kind)
        return agent

    def close(self) -> None:
        self.closed = True
        agents, self.agents = list(self.agents.values()), {}
        for a in agents:
            a.close()


def _failed(peer: Peer, result: SshResult, timeout: float) -> AgentCall:
    return AgentCall(peer, result, timeout)


async def agent_call(agents: PeerAgents, opts: SshOptions | None, peer: Peer, kind: AgentKind,
                     program: str, argv: Sequence[str], *, timeout: float,
                     tcp_timeout: float | None = None, max_s: float = 120.0,
                     needs_install: bool = False, start_timeout: float | None = None,
                     source: bytes | None = None) -> AgentCall:
    """Start *program* with *argv* on *peer*'s agent of *kind*; never raises. *timeout* bounds
    reaching the peer (and is the default for reads and waits), *tcp_timeout* its TCP part, as
    for an SSH session; *max_s* bounds the agent's life if this call starts it; *needs_install*:
    the run needs the peer's rosnet-tui (see AgentKind.no_install); *start_timeout* bounds the
    wait for the agent to be ready and the request sent, from this call on (default: twice the
    longer of *timeout* and the round's);
    *source*: a program *kind* does not load at the start (see :meth:`PeerAgent.call`)."""
    loop = asyncio.get_running_loop()
    base = float(getattr(opts, "timeout_s", 3.0) or 3.0)
    if start_timeout is None:
        start_timeout = max(timeout, base) * 2 + 0.5
    end = loop.time() + max(start_timeout, 0.05)     # from now: the connection's wait included
    pool = getattr(opts, "pool", None)
    if pool is not None:       # the peer's connection first: its failures, within our bounds
        conn, _shared = await pool.connect(opts, peer, timeout, tcp_timeout)
        if conn.transport is None:
            return _failed(peer, conn.result, timeout)
    agent = agents.get(peer, kind)
    task = agent.start(opts, timeout, tcp_timeout, max_s, max(end - loop.time(), 0.05))
    try:
        started = await asyncio.wait_for(asyncio.shield(task), max(end - loop.time(), 0.05))
    except asyncio.TimeoutError:
        return _failed(peer, SshResult(False, None, "", "", "timeout",
                                       f"the probe program on {peer.name} did not start in time",
                                       None, None, None, "connected"), timeout)
    except asyncio.CancelledError:
        if task.cancelled():      # the round closed the agent meanwhile
            return _failed(peer, SshResult(False, None, "", "", "sshd",
                                           f"the session with {peer.name} closed", None),
                           timeout)
        raise
    if started.failure is not None:
        return _failed(peer, started, timeout)
    return await agent.call(program, argv, timeout, needs_install, source,
                            send_within=max(end - loop.time(), 0.05))


@contextlib.asynccontextmanager
async def agent_session(agents: PeerAgents, opts: SshOptions | None, peer: Peer,
                        kind: AgentKind, program: str, argv: Sequence[str], *, timeout: float,
                        tcp_timeout: float | None = None, max_s: float = 120.0,
                        needs_install: bool = False, start_timeout: float | None = None,
                        source: bytes | None = None) -> AsyncIterator[AgentCall]:
    """:func:`agent_call` for an ``async with`` block; the run is stopped on leaving it."""
    call = await agent_call(agents, opts, peer, kind, program, argv, timeout=timeout,
                            tcp_timeout=tcp_timeout, max_s=max_s, needs_install=needs_install,
                            start_timeout=start_timeout, source=source)
    try:
        yield call
    finally:
        call.close()


async def agent_run(agents: PeerAgents, opts: SshOptions | None, peer: Peer, kind: AgentKind,
                    program: str, argv: Sequence[str], *, timeout: float,
                    connect_timeout: float | None = None, tcp_timeout: float | None = None,
                    max_s: float = 120.0, needs_install: bool = False,
                    source: bytes | None = None) -> SshResult:
    """Run *program* on *peer*'s agent within *timeout* overall, as ``ssh_run`` runs a command
    (*connect_timeout*: reaching the peer; *tcp_timeout*: its TCP part; *source*: see
    :meth:`PeerAgent.call`)."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    ct = min(float(connect_timeout), timeout) if connect_timeout is not None else timeout
    async with agent_session(agents, opts, peer, kind, program, argv, timeout=ct,
                             tcp_timeout=tcp_timeout, max_s=max_s, needs_install=needs_install,
                             start_timeout=deadline - loop.time(), source=source) as call:
        if not call.ok:
            return call.result
        return await call.wait(max(deadline - loop.time(), 0.05))
