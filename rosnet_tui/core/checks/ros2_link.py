"""Step 4 for ROS 2 over rmw_zenoh: the link to each peer measured (ros2.link), through the routers
as the robot's real topics go, with this component's certificate.

Both ends are probe nodes speaking :mod:`rosnet_tui.core.peer.zenohlink` (rmw_zenoh's keys, CDR
messages, attachments): ours here, the peer's run by the round's peer agent there. Per peer, in
this order and within the check's budget: the round trip (median and spread of a few pings), the
throughput each way (a burst one way, then the other, paced by the receiver's acknowledgements and
ended as soon as its rate is steady), and the largest message delivered whole each way (64 kB,
then 1 MB, each tried only when the rates measured say it can arrive in the time left; up to three
tries when one is lost). On a thin link it reports what it measured in the time it had. The set-up
and the pings overlap the round's pub/sub checks; the bursts and large messages wait for their
end, so as not to delay them.

The sum of the ``[[link.topic]]`` needs is compared with the throughput each way.
"""

from __future__ import annotations

import asyncio
import secrets
import statistics
import time
from typing import Any

from rosnet_tui.core.checks import CheckContext, check
from rosnet_tui.core.checks.probes.agents import ZENOH_AGENT, peer_session
from rosnet_tui.core.checks.probes.budget import budget
from rosnet_tui.core.checks.probes.link import (
    failed_one,
    figures_line,
    large_wait,
    link_data,
    link_outcome,
    need_of,
    unless_no_path,
)
from rosnet_tui.core.checks.probes.peers import each_peer
from rosnet_tui.core.checks.probes.ros2 import (
    close_zenoh,
    member_arg,
    node_domain,
    node_endpoint,
    open_zenoh,
    ros2_peers,
    zenoh_peer_problem,
)
from rosnet_tui.core.config.settings_model import Peer
from rosnet_tui.core.net.blocking import run_blocking
from rosnet_tui.core.peer import zenohproto
from rosnet_tui.core.peer.zenohlink import CHUNK, LinkEnd, link_text, rate_bps
from rosnet_tui.core.results import Outcome, Status

FACTOR_LINK = 6.0
PINGS = 5                      # round trips measured
BURST_CAP = 4 * 1024 * 1024    # bytes a burst sends at most (a steady rate ends it earlier)
LARGE = (65536, 1 << 20)       # the large messages tried, in bytes
TRIES = 3                      # tries of each large message (while the time left allows)
PUBSUB = ("ros2.pubsub_out", "ros2.pubsub_in")


def _pings(end: LinkEnd, t: float) -> dict[str, Any]:
    """The round trip within *t* s (blocking; the peer's side is serving): the first ping back
    (routes exist both ways), then PINGS more. Small messages: this overlaps the pub/sub checks."""
    start = time.monotonic()
    m: dict[str, Any] = {"rtts": [], "out": None, "in": None, "largest_out": 0,
                         "largest_in": 0, "tried_out": 0, "tried_in": 0, "notes": []}
    warm_until = start + max(0.5, t * 0.75)
    n = 0
    while not end.pongs and time.monotonic() < warm_until:
        n += 1
        end.put(f"p w{n}")
        end.pump(min(warm_until, time.monotonic() + 0.25), lambda: bool(end.pongs))
    if not end.pongs:
        m["notes"].append(f"no ping came back within {warm_until - start:.1f} s")
        return m
    for i in range(PINGS):
        if time.monotonic() > start + t:
            break
        sent = time.monotonic()
        end.put(f"p r{i}")
        end.pump(min(start + t, sent + 1.0), lambda i=i: f"r{i}" in end.pongs)
        if f"r{i}" in end.pongs:
            m["rtts"].append((end.pongs[f"r{i}"] - sent) * 1000.0)
    return m


def _bursts(end: LinkEnd, m: dict[str, Any], t: float) -> dict[str, Any]:
    """The rate each way, then the largest message each way, within *t* s (blocking)."""
    stop_at = time.monotonic() + t
    rtt = statistics.median(m["rtts"]) / 1000.0 if m["rtts"] else 0.3
    # One way at a time, so that neither burst's acknowledgements wait behind the other's data.
    # Each ends as soon as its rate is steady (after its least time), or at its time or cap.
    w = max(0.3, min(2.5, (stop_at - time.monotonic()) * 0.15))
    stall, least = max(0.3, 4 * rtt), max(0.02, 10 * rtt)
    end.start_burst(w, BURST_CAP, stall, least)
    end.pump(min(stop_at - 0.5, time.monotonic() + w * 1.5 + 4 * rtt + 0.3),
             lambda: not end.sending() and not end.in_flight())
    ask_until = min(stop_at - 0.3, time.monotonic() + max(1.0, 4 * rtt))
    while end.stats is None and time.monotonic() < ask_until:
        end.put("f")
        end.pump(min(ask_until, time.monotonic() + max(0.2, 2 * rtt)),
                 lambda: end.stats is not None)
    end.put(f"b {w:.2f} {BURST_CAP} {stall:.3f} {least:.3f}")
    end.pump(min(stop_at - 0.5, time.monotonic() + w * 1.5 + 4 * rtt + 0.5),
             lambda: end.their_burst_over)
    m["out"], m["in"] = rate_bps(end.stats), rate_bps(end.received())
    if end.stats and end.stats.get("n"):
        m["largest_out"] = CHUNK
    if end.got["n"]:
        m["largest_in"] = CHUNK
    _largest(end, m, rtt, stop_at)
    return m


def _largest(end: LinkEnd, m: dict[str, Any], rtt: float, stop_at: float) -> None:
    """Try 64 kB then 1 MB each way, each only when the rate measured brings it in the time left."""
    ways = {"out": True, "in": True}
    for size in LARGE:
        left = stop_at - time.monotonic() - 0.3
        go: dict[str, float] = {}
        for way in ways:
            if not ways[way]:
                continue
            need = large_wait(m, way, size, rtt, left)
            if need is not None:
                go[way] = need
            else:
                ways[way] = False
        if not go:
            return
        for attempt in range(TRIES):    # more tries: one loss is not the link's verdict
            if attempt and max(go.values()) + 0.2 > stop_at - time.monotonic() - 0.3:
                break
            if attempt:     # what held the last one up may pass meanwhile (answering)
                end.pump(time.monotonic() + min(0.2, max(0.05, 4 * rtt)))
            if "in" in go:
                end.put(f"s {size}")
                m["tried_in"] = size
            if "out" in go:
                end.put(link_text("L", size), control=False)
                m["tried_out"] = size
            end.pump(time.monotonic() + max(go.values()),
                     lambda go=go, size=size: ("out" not in go or size in end.delivered)
                     and ("in" not in go or end.largest_in >= size))
            if "out" in go and size in end.delivered:
                m["largest_out"] = size
                del go["out"]
            if "in" in go and end.largest_in >= size:
                m["largest_in"] = size
                del go["in"]
            if not go:
                break
        for way in go:              # not delivered in any try: no larger one either
            ways[way] = False


async def _peer_link(ctx: CheckContext, peer: Peer, deadline: float, gate: asyncio.Future
                     ) -> tuple[Status, str, list[str], dict[str, Any]]:
    """Measure the link to *peer*: (status, words, evidence, its data.peers entry). The set-up
    and the pings go at once; the bursts and large messages wait for *gate* (the pub/sub checks'
    end), and go only when those found messages passing."""
    empty = link_data({})
    endpoint, how = node_endpoint(ctx)
    session, why = await open_zenoh(endpoint, max(0.3, min(2.0, (deadline - time.monotonic())
                                                         * 0.2)), how)
    if session is None:
        return (Status.FAIL, f"{peer.name}: no session on this machine's router at {endpoint} "
                             f"({why})", [], empty)
    tag = secrets.token_hex(4)
    topic, dom = f"rosnet_tui/link_{tag}", node_domain(ctx)
    rx = tx = None
    ev: list[str] = []
    m: dict[str, Any] = {}
    try:
        rx = await run_blocking(zenohproto.ProbeNode, session, dom, zenohproto.probe_name(),
                                topic + "/in", timeout=2.0)
        await run_blocking(rx.subscription, timeout=2.0)
        tx = await run_blocking(zenohproto.ProbeNode, session, dom, zenohproto.probe_name(),
                                topic + "/out", timeout=2.0)
        await run_blocking(tx.publisher, timeout=2.0)
        remote_t = max(1.0, deadline - time.monotonic() - 0.2)
        argv = ["link", "--topic", topic, "--timeout", f"{remote_t:.1f}", *member_arg(ctx, peer)]
        async with peer_session(ctx, peer, ZENOH_AGENT, "zlink", argv,
                                timeout=max(0.5, min(remote_t * 0.3, ctx.timeout_s * 0.6)),
                                needs_install=True,    # a thin link takes seconds to start it
                                start_timeout=max(0.5, remote_t * 0.5)) as sess:
            if not sess.ok:
                return (Status.SKIP, f"{peer.name}: could not run the other side: SSH failed "
                                     f"({sess.result.failure}): {sess.result.detail}", [], empty)
            ready = await sess.read_until(zenohproto.READY_MARK,
                                          timeout=max(0.3, (deadline - time.monotonic()) * 0.4))
            if ready is not None:
                end = LinkEnd(rx, tx)
                t = max(0.3, deadline - time.monotonic() - 0.4) * 0.4
                m = await run_blocking(_pings, end, t, timeout=t + 1.5)
                await asyncio.shield(gate)
                if m["rtts"] and not failed_one(ctx, PUBSUB):
                    t = max(0.3, deadline - time.monotonic() - 0.4)
                    m = await run_blocking(_bursts, end, m, t, timeout=t + 1.0)
                end.put("e")
            res = await sess.wait(max(0.3, deadline - time.monotonic()))
    finally:
        await asyncio.gather(*(run_blocking(node.close, timeout=1.0)
                               for node in (rx, tx) if node is not None))
        await close_zenoh(session)
    rep = zenohproto.parse_report(res.stdout)
    why_not = zenoh_peer_problem(res, peer, rep) if not m else None
    if why_not:
        return Status.SKIP, f"{peer.name}: could not run the other side: {why_not}", ev, empty
    if rep is not None and rep.get("error"):
        return (Status.FAIL, f"{peer.name}: nothing measured: on {peer.name}, "
                             f"{rep.get('detail')}", ev, empty)
    d = link_data(m)
    if d["out_bps"] is None and rep is not None:   # their account came on stdout only
        out = rate_bps(rep.get("link") or {})
        d["out_bps"] = round(out) if out else None
    ev.append(figures_line(peer.name, d))
    ev += [f"{peer.name}: {n}" for n in m.get("notes") or []]
    if d["rtt_ms"] is None:
        return (Status.FAIL, f"{peer.name}: no small message came back through the routers "
                             "(see ros2.pubsub_out and ros2.pubsub_in)", ev, d)
    return Status.PASS, "", ev, d


@check("ros2.link", "ros", "The link to each peer measured: round trip, throughput, large "
       "messages", FACTOR_LINK, ros=2)
async def check_link(ctx: CheckContext) -> Outcome:
    s = ctx.settings
    t = budget(ctx, "ros2.link")
    start = time.monotonic()
    data: dict[str, Any] = {"peers": {}, "need_bps": need_of(ctx)}
    if not s.master_name:
        return Outcome(Status.SKIP, "skipped: no master is named in the settings (ros.master)",
                       [], data)
    peers = ros2_peers(ctx)
    if not peers:
        return Outcome(Status.SKIP, "skipped: no peer with an SSH user in the settings, so the "
                                    "other end of the link cannot be run from here", [], data)
    deadline = start + t - 0.4
    gate = asyncio.ensure_future(ctx.after(PUBSUB, start + t * 0.4))
    try:
        outcomes, broken = await unless_no_path(
            ctx, PUBSUB, each_peer(peers, lambda p: _peer_link(ctx, p, deadline, gate)),
            deadline, also=("ros2.router", "ros2.graph"))
        if broken is None:
            await gate
    finally:
        gate.cancel()
    broken = broken or failed_one(ctx, PUBSUB)
    if broken:
        return Outcome(Status.SKIP, f"skipped: {broken} found no message passing, so there is no "
                                    "link to measure (see its advice)", [], data)
    return link_outcome(ctx, peers, outcomes, data)
