"""Step 4 for ROS 1: the link to each peer measured (ros.link), over TCPROS through the forwards
as the robot's real topics go.

Both ends are ROS nodes of our own speaking :mod:`rosnet_tui.core.peer.roslink` (std_msgs/String
messages through the master's registrations, requestTopic and the TCPROS handshake): ours here,
the peer's run by the round's peer agent there, alongside the pub/sub checks' probes. Per peer,
within the check's budget: the round trip (median and spread of a few pings), the throughput
each way (a burst one way, then the other, paced by the receiver's acknowledgements and ended
early once a fast link has carried enough to know its rate), and the largest message delivered
whole each way (64 kB, then 1 MB, each tried only when the rates measured say it can arrive in
the time left). On a thin link it reports what it measured in the time it had; when the nodes
cannot connect, it says so within the round's timeout.

The sum of the ``[[link.topic]]`` needs (each at its hz: ``max_hz`` is ROS 2's) is compared with
the throughput each way.
"""

from __future__ import annotations

import asyncio
import statistics
import time
from typing import Any

from rosnet_tui.core.checks import CheckContext, check
from rosnet_tui.core.checks.probes.agents import (
    ROS_AGENT,
    peer_program_problem,
    peer_session,
    stderr_tail,
)
from rosnet_tui.core.checks.probes.budget import budget
from rosnet_tui.core.checks.probes.link import (
    PeerLink,
    failed_one,
    figures_line,
    large_wait,
    link_data,
    link_outcome,
    need_of,
    unless_no_path,
)
from rosnet_tui.core.checks.probes.peers import each_peer
from rosnet_tui.core.checks.probes.ros1 import master_uri, ros1_peers
from rosnet_tui.core.config.settings_model import Peer
from rosnet_tui.core.net.blocking import run_blocking
from rosnet_tui.core.peer import rosproto
from rosnet_tui.core.peer.roslink import LinkEnd, LinkNode, link_frame, rate_bps
from rosnet_tui.core.results import Outcome, Status

FACTOR_LINK = 6.0
PINGS = 5                      # round trips measured
BURST_CAP = 512 * 1024        # bytes a burst sends at most (a fast link ends it there)
LARGE = (65536, 1 << 20)       # the large messages tried, in bytes
CONNECT_SHARE = 0.6            # of the budget: the probes connected both ways by then (a few
                               # round trips through the master: seconds on a thin link busy
                               # with the round's other probes; a fast link connects at once)
PUBSUB = ("ros.pubsub_out", "ros.pubsub_in")
READY_MARK = f'"{rosproto.READY_KEY}"'    # the peer's probe registered its topic


def _set_up(node: LinkNode, connect_by: float) -> str | None:
    """Publish our topic, subscribe to the peer's (its publisher found through the master as it
    registers) by *connect_by*: None, or what failed in words (blocking)."""
    if not node.publish():
        return f"the probe here could not publish: {node.why_not}"
    if not node.subscribe(connect_by):
        return f"this component could not subscribe to the peer's probe: {node.why_not}"
    return None


def _measure(end: LinkEnd, connect_by: float, stop_at: float) -> dict[str, Any]:
    """The figures of one peer's link by *stop_at* (blocking; we are subscribed to the peer's
    probe): wait for its subscription to ours, then measure."""
    node: LinkNode = end.node
    m: dict[str, Any] = {"rtts": [], "out": None, "in": None, "largest_out": 0,
                         "largest_in": 0, "tried_out": 0, "tried_in": 0, "notes": []}
    if not node.connected_out.wait(max(0.0, connect_by - time.monotonic())):
        m["failed"] = "the peer's probe did not subscribe to the one here in time"
        return m
    start = time.monotonic()
    for i in range(PINGS):
        if time.monotonic() > start + (stop_at - start) * 0.3:
            break
        sent = time.monotonic()
        end.put(f"p r{i}")
        end.pump(min(stop_at, sent + 1.5), lambda i=i: f"r{i}" in end.pongs)
        if f"r{i}" in end.pongs:
            m["rtts"].append((end.pongs[f"r{i}"] - sent) * 1000.0)
    if not m["rtts"]:
        m["notes"].append("no ping came back")
        return m
    rtt = statistics.median(m["rtts"]) / 1000.0
    # One way at a time, so that neither burst's acknowledgements wait behind the other's data.
    w = max(0.3, min(1.5, (stop_at - time.monotonic()) * 0.1))
    end.start_burst(w, BURST_CAP)
    end.pump(min(stop_at - 0.5, time.monotonic() + w * 1.5 + 4 * rtt + 0.3),
             lambda: not end.sending() and not end.in_flight())
    end.put(f"b {w:.2f} {BURST_CAP}")
    end.pump(min(stop_at - 0.5, time.monotonic() + w * 1.5 + 4 * rtt + 0.5),
             lambda: end.their_burst_over)
    m["out"], m["in"] = rate_bps(end.stats), rate_bps(end.received())
    _largest(end, m, rtt, stop_at)
    return m


def _largest(end: LinkEnd, m: dict[str, Any], rtt: float, stop_at: float) -> None:
    """Try 64 kB then 1 MB each way at once, each only when the rate measured brings it in the
    time left (TCP loses nothing: one try each). A link fast enough for all of them gets them in
    one go."""
    left = stop_at - time.monotonic() - 0.3
    wire = max((sum(LARGE) * 8 / m[w] if m[w] else left) for w in ("out", "in"))
    if wire * 1.5 + 2 * rtt + 0.2 < left:
        for size in LARGE:
            end.put(f"s {size}")
            end.node.put_frame(link_frame("L", size))
        m["tried_in"] = m["tried_out"] = LARGE[-1]
        end.pump(time.monotonic() + wire * 1.5 + 2 * rtt + 0.2,
                 lambda: set(LARGE) <= end.delivered and set(LARGE) <= end.arrived)
        m["largest_out"] = max((s for s in LARGE if s in end.delivered), default=0)
        m["largest_in"] = max((s for s in LARGE if s in end.arrived), default=0)
        return
    for size in LARGE:
        left = stop_at - time.monotonic() - 0.3
        go: dict[str, float] = {}
        for way in ("out", "in"):
            if size > 65536 and m[f"largest_{way}"] < 65536:
                continue        # the smaller one did not arrive: the larger will not either
            need = large_wait(m, way, size, rtt, left)
            if need is not None:
                go[way] = need
        if not go:
            return
        if "in" in go:
            end.put(f"s {size}")
            m["tried_in"] = size
        if "out" in go:
            end.node.put_frame(link_frame("L", size))
            m["tried_out"] = size
        end.pump(time.monotonic() + max(go.values()),
                 lambda go=go, size=size: ("out" not in go or size in end.delivered)
                 and ("in" not in go or end.largest_in >= size))
        if "out" in go and size in end.delivered:
            m["largest_out"] = size
        if "in" in go and end.largest_in >= size:
            m["largest_in"] = size


async def _nudge(sess: Any, node: LinkNode, until: float) -> None:
    """When the peer's probe says it registered, our node asks the master for it at once (the
    master's own publisherUpdate can come later than our next look); when it ended without, our
    node stops waiting for it."""
    if await sess.read_until(READY_MARK, timeout=max(0.1, until - time.monotonic())):
        node.updates.set()
    elif sess.done:
        node.stopping.set()
        node.updates.set()


async def _peer_link(ctx: CheckContext, peer: Peer, uri: str, deadline: float) -> PeerLink:
    """Measure the link to *peer*: (status, words, evidence, its data.peers entry). The probes
    connect within CONNECT_SHARE of the budget once the peer's side runs (a thin link may take
    seconds to start it); then the measure has the rest of it."""
    connect_s = budget(ctx, "ros.link") * CONNECT_SHARE
    empty = link_data({})
    base = f"{rosproto.PROBE_PREFIX}/link_{rosproto.new_probe_id()}"
    ct = max(0.3, min(2.0, ctx.timeout_s * 0.6))
    node = LinkNode(uri, base + "/out", base + "/in", env=ctx.env,
                    bashrc=str(ctx.paths.bashrc_path), call_timeout=ct)
    # Our node registers and subscribes while the peer's program starts: it finds the peer's
    # publisher as soon as that registers (the master's publisherUpdate).
    late = time.monotonic() + (deadline - time.monotonic()) * 0.7    # no later than this
    setup = asyncio.ensure_future(run_blocking(_set_up, node, late,
                                               timeout=late - time.monotonic() + 1.0))
    m: dict[str, Any] = {}
    res = None
    closing: asyncio.Future | None = None
    nudge: asyncio.Future | None = None
    try:
        remote_t = max(1.0, deadline - time.monotonic() - 0.2)
        argv = ["link", "--master", uri, "--topic", base, "--timeout", f"{remote_t:.2f}",
                "--connect", f"{connect_s:.2f}"]
        async with peer_session(ctx, peer, ROS_AGENT, "rlink", argv,
                                timeout=max(0.5, (deadline - time.monotonic()) * 0.4),
                                tcp_timeout=ctx.timeout_s) as sess:
            if not sess.ok:
                return (Status.SKIP, f"{peer.name}: could not run the other side: SSH failed "
                                     f"({sess.result.failure}): {sess.result.detail}", [], empty)
            connect_by = time.monotonic() + connect_s
            nudge = asyncio.ensure_future(_nudge(sess, node, connect_by))
            try:
                failed = await asyncio.wait_for(asyncio.shield(setup),
                                                max(0.1, connect_by - time.monotonic()))
            except asyncio.TimeoutError:
                node.stopping.set()     # its subscribe loop ends; a late registration undoes
                failed = node.why_not or (f"no connection to the peer's probe within "
                                          f"{connect_s:.1f} s")
                if not node.registered:
                    failed = f"no answer from the master {uri} in time (timed out)"
            if failed and not node.registered:
                return Status.FAIL, f"{peer.name}: nothing measured: {failed}", [], empty
            m["failed"] = failed
            if not failed:
                end = LinkEnd(node)
                t = max(0.3, deadline - time.monotonic() - 0.2)
                m = await run_blocking(_measure, end, connect_by, time.monotonic() + t,
                                       timeout=t + 1.0)
                node.put("e")
            # Our node closes (unregisters) while the peer's ends and reports.
            closing = asyncio.ensure_future(run_blocking(node.close, 0.3 if m.get("rtts") else
                                                         0.0, timeout=2.0))
            wait = deadline - time.monotonic() if m.get("rtts") else 0.3
            res = await sess.wait(max(0.1, wait))
    finally:
        setup.cancel()
        if nudge is not None:
            nudge.cancel()
        await (closing if closing is not None else run_blocking(node.close, 0.0, timeout=2.0))
    rep = rosproto.parse_report_line(res.stdout) if res is not None else None
    if not m.get("rtts"):
        return _no_figures(ctx, peer, res, rep, m, empty)
    d = link_data(m)
    if d["out_bps"] is None and rep is not None:   # their account came on stdout only
        out = rate_bps(rep.get("link") if isinstance(rep.get("link"), dict) else None)
        d["out_bps"] = round(out) if out else None
    ev = [figures_line(peer.name, d)] + [f"{peer.name}: {n}" for n in m.get("notes") or []]
    return Status.PASS, "", ev, d


def _no_figures(ctx: CheckContext, peer: Peer, res: Any, rep: dict[str, Any] | None,
                m: dict[str, Any], empty: dict[str, Any]) -> PeerLink:
    """Why nothing was measured: the peer's program did not run, or no path both ways."""
    ran = res is not None and (rep is not None or res.failure == "timeout" or m.get("failed"))
    why_not = peer_program_problem(res, peer) if res is not None and not ran else None
    if why_not:
        return Status.SKIP, f"{peer.name}: could not run the other side: {why_not}", [], empty
    theirs = rep.get("error") if rep is not None else None
    ev = [f"{peer.name}: {w}" for w in (m.get("failed"), *(m.get("notes") or []),
                                        f"on {peer.name}: {theirs}" if theirs else None,
                                        f"on {peer.name}, stderr: {stderr_tail(res)}"
                                        if rep is None and res is not None and stderr_tail(res)
                                        else None) if w]
    broken = failed_one(ctx, PUBSUB)
    if broken:
        return (Status.SKIP, f"{peer.name}: {broken} found no message passing, so there is no "
                             "link to measure (see its advice)", ev, empty)
    words = (f"on {peer.name}: {theirs}" if theirs else m.get("failed")
             or "no small message came back")
    return (Status.FAIL, f"{peer.name}: nothing measured: {words} (see ros.pubsub_out and "
                         "ros.pubsub_in)", ev, empty)


@check("ros.link", "ros", "The link to each peer measured: round trip, throughput, large "
       "messages", FACTOR_LINK, ros=1)
async def check_link(ctx: CheckContext) -> Outcome:
    start = time.monotonic()
    t = budget(ctx, "ros.link")
    data: dict[str, Any] = {"peers": {}, "need_bps": need_of(ctx)}
    uri, why = master_uri(ctx)
    if uri is None:
        return Outcome(Status.SKIP, f"skipped: {why}", [], data)
    peers = ros1_peers(ctx.settings)
    if not peers:
        return Outcome(Status.SKIP, "skipped: no peer with an SSH user in the settings, so the "
                                    "other end of the link cannot be run from here", [], data)
    deadline = start + t - 0.4
    outcomes, broken = await unless_no_path(
        ctx, PUBSUB, each_peer(peers, lambda p: _peer_link(ctx, p, uri, deadline)), deadline,
        also=("ros.master", "ros.node_uris"))
    if broken:
        return Outcome(Status.SKIP, f"skipped: {broken} found no message passing, so there is no "
                                    "link to measure (see its advice)", [], data)
    return link_outcome(ctx, peers, outcomes, data)
