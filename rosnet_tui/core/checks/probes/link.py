"""What ros2.link and ros.link share: one peer's figures as declared data, the verdict on them
(large messages dropped, the ``[[link.topic]]`` need against the rates measured) and the check's
outcome over every peer."""

from __future__ import annotations

import asyncio
import statistics
import time
from collections.abc import Awaitable, Iterable
from typing import Any

from rosnet_tui.core.checks import CheckContext
from rosnet_tui.core.config.settings_model import Peer
from rosnet_tui.core.results import Outcome, Status
from rosnet_tui.core.words import kb, mbit

PeerLink = tuple[Status, str, list[str], dict[str, Any]]   # (status, words, evidence, its data)


def link_data(m: dict[str, Any]) -> dict[str, Any]:
    """One peer's ``data.peers`` entry from what was measured (*m*: rtts, out, in, largest_*,
    tried_*; an empty *m*: nothing measured)."""
    rtts = m.get("rtts") or []
    return {"rtt_ms": round(statistics.median(rtts), 1) if rtts else None,
            "rtt_spread_ms": round(max(rtts) - min(rtts), 1) if rtts else None,
            "out_bps": round(m["out"]) if m.get("out") else None,
            "in_bps": round(m["in"]) if m.get("in") else None,
            "largest_out": m.get("largest_out", 0), "largest_in": m.get("largest_in", 0),
            "tried_out": m.get("tried_out", 0), "tried_in": m.get("tried_in", 0)}


def rtt_words(d: dict[str, Any]) -> str:
    if d["rtt_ms"] is None:
        return "not measured"
    return f"{d['rtt_ms']:.0f} ms (spread {d['rtt_spread_ms']:.0f} ms)"


def figures_line(name: str, d: dict[str, Any]) -> str:
    """The evidence line of one peer's figures."""
    return (f"{name}: round trip {rtt_words(d)}; up (here -> {name}) {mbit(d['out_bps'])}, "
            f"down {mbit(d['in_bps'])}; largest delivered whole: up {kb(d['largest_out'])} "
            f"(tried {kb(d['tried_out'])}), down {kb(d['largest_in'])} "
            f"(tried {kb(d['tried_in'])})")


def large_wait(m: dict[str, Any], way: str, size: int, rtt: float, left: float) -> float | None:
    """How long a *size*-byte message takes *way* ("out", "in") at the rate measured in *m*, with
    room for the round trip, when that fits in the *left* seconds; else None, with a note in *m*
    saying why it is not tried."""
    rate = m[way]
    need = size * 8 / rate * 1.5 + 2 * rtt + 0.2 if rate else None
    if need is not None and need < left:
        return need
    m["notes"].append(f"{kb(size)} {'up' if way == 'out' else 'down'} not tried: "
                      + (f"about {size * 8 / rate:.0f} s at the rate measured, "
                         f"{max(0.0, left):.1f} s were left" if rate else "no rate measured"))
    return None


def need_of(ctx: CheckContext) -> float:
    """Bits per second the ``[[link.topic]]`` tables need each way: at ``max_hz`` under ROS 2
    (the router cuts the topic down to it), at ``hz`` under ROS 1 (nothing cuts it down)."""
    return ctx.settings.link.need_bps(downsampled=ctx.settings.ros2)


def judge(ctx: CheckContext, name: str, d: dict[str, Any]) -> tuple[Status, list[str]]:
    """The verdict on one measured peer: large messages dropped, and the need against the rates."""
    warns: list[str] = []
    fail = False
    for way, words in (("out", "up"), ("in", "down")):
        tried, got = d[f"tried_{way}"], d[f"largest_{way}"]
        if tried and got < tried:
            warns.append(f"small messages pass {words} but {kb(tried)} ones are dropped (largest "
                         f"delivered whole: {kb(got) if got else 'none of the large ones'})")
            big = [tp.name for tp in ctx.settings.link.topics if tp.bytes > got]
            if big:
                fail = True
                warns[-1] += f"; {', '.join(big)} need larger messages"
    need = need_of(ctx)
    if need:
        for way, words in (("out", "up"), ("in", "down")):
            got = d[f"{way}_bps"]
            if got is not None and got < need:
                warns.append(f"needs {need / 1e6:.1f} Mbit/s {words}, measured "
                             f"{got / 1e6:.1f} (short by {(need - got) / 1e6:.1f} Mbit/s)")
    if not warns:
        return Status.PASS, []
    return (Status.FAIL if fail else Status.WARN), [f"to {name}: {w}" for w in warns]


def link_outcome(ctx: CheckContext, peers: list[Peer], outcomes: list[PeerLink],
                 data: dict[str, Any]) -> Outcome:
    """The check's outcome from every peer's (status, words, evidence, data), each measured one
    judged; *data* gets ``peers``."""
    ev = [line for o in outcomes for line in o[2]]
    need = need_of(ctx)
    if need:
        topics = ctx.settings.link.topics
        ev.append(f"[[link.topic]] needs {need / 1e6:.1f} Mbit/s each way: " + ", ".join(
            f"{tp.name} {(tp.bps if ctx.settings.ros2 else tp.full_bps) / 1e6:.2f}"
            for tp in topics))
        if not ctx.settings.ros2 and any(tp.max_hz is not None for tp in topics):
            ev.append("max_hz is for ROS 2 (a Zenoh router cuts the topic down to it); under "
                      "ROS 1 nothing does, so each topic counts at its hz")
    rank = {Status.FAIL: 0, Status.WARN: 1, Status.SKIP: 2, Status.PASS: 3}
    worst, words = Status.PASS, []
    for p, (status, summary, _ev, d) in zip(peers, outcomes, strict=True):
        data["peers"][p.name] = d
        if status == Status.PASS:
            status, more = judge(ctx, p.name, d)
            words += more
        else:
            words.append(summary)
        worst = min(worst, status, key=lambda x: rank[x])
    if worst == Status.PASS:
        return Outcome(Status.PASS, "; ".join(
            f"to {p.name}: round trip {rtt_words(d)}, up {mbit(d['out_bps'])}, down "
            f"{mbit(d['in_bps'])}, {kb(min(d['largest_out'], d['largest_in']))} whole both ways"
            for p in peers for d in [data["peers"][p.name]]), ev, data)
    if worst == Status.SKIP and all(o[0] == Status.SKIP for o in outcomes):
        return Outcome(Status.SKIP, "skipped: " + "; ".join(words), ev, data)
    return Outcome(worst, "; ".join(words), ev, data)


def failed_one(ctx: CheckContext, ids: Iterable[str]) -> str | None:
    """The first of *ids* (pub/sub checks) that has failed in this round so far: no message
    passes, so there is no link to measure (None: none has)."""
    for c in ids:
        r = ctx.results.get(c)
        if r is not None and r.status == Status.FAIL:
            return c
    return None


async def _first_failed(ctx: CheckContext, ids: Iterable[str], until: float) -> str | None:
    """The first of *ids* (those this round runs) that fails, as soon as it does; None once
    they have all passed, or at *until*."""
    wanted = [c for c in ids if c in ctx.round_ids]
    while time.monotonic() < until:
        if (failed := failed_one(ctx, wanted)) is not None:
            return failed
        if all(c in ctx.results for c in wanted):
            return None
        await asyncio.sleep(0.01)     # (a look costs nothing: 10 ms late at most)
    return None


async def unless_no_path(ctx: CheckContext, pubsub: Iterable[str], measure: Awaitable[Any],
                         until: float, also: Iterable[str] = ()) -> tuple[Any, str | None]:
    """(what *measure* gave, None), or (None, the pub/sub check's id) when one of *pubsub*
    finds no message passing first: the measurement then stops, since its bursts would wait
    out the budget for acknowledgements that cannot come. It stops once the round's checks of
    *pubsub* and *also* have ended (at *until* at the latest): stopping our probes (the peer's
    killed, ours unregistering) must not load the master or router while they still ask it."""
    ids = [*pubsub, *also]
    task = asyncio.ensure_future(measure)
    watch = asyncio.ensure_future(_first_failed(ctx, pubsub, until))
    settled: asyncio.Future | None = None
    try:
        await asyncio.wait({task, watch}, return_when=asyncio.FIRST_COMPLETED)
        if not task.done() and watch.result() is not None:
            settled = asyncio.ensure_future(ctx.after(ids, until))
            await asyncio.wait({task, settled}, return_when=asyncio.FIRST_COMPLETED)
            if not task.done():
                return None, watch.result()
        return await task, None
    finally:
        for f in (watch, settled):
            if f is not None:
                f.cancel()
        if not task.done():
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)
