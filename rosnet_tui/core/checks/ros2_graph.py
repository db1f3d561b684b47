"""Step 4 for ROS 2 over rmw_zenoh: the graph (ros2.graph) and live publish/subscribe both ways
(ros2.pubsub_out, ros2.pubsub_in), each through the routers as a real node's data goes.

Our side is a probe node here (:class:`rosnet_tui.core.peer.zenohproto.ProbeNode`: liveliness tokens,
rmw_zenoh's data key, CDR payload, 33-byte attachment); the peer's side is the same module run
over SSH, by the round's peer agent there (core/peer/peer_agent.py). A failure names the hop where the
message was lost.
"""

from __future__ import annotations

import asyncio
import contextlib
import secrets
import time
from typing import Any

from rosnet_tui.core.addresses import is_loopback
from rosnet_tui.core.checks import CheckContext, check
from rosnet_tui.core.checks.probes.agents import ZENOH_AGENT, peer_run, peer_session
from rosnet_tui.core.checks.probes.budget import budget
from rosnet_tui.core.checks.probes.peers import each_peer
from rosnet_tui.core.checks.probes.ros2 import (
    close_zenoh,
    member_arg,
    node_domain,
    node_endpoint,
    open_zenoh,
    ros2_peers,
    router_links,
    zenoh_peer_problem,
)
from rosnet_tui.core.config.settings_model import Peer
from rosnet_tui.core.net.blocking import run_blocking
from rosnet_tui.core.peer import zenohproto
from rosnet_tui.core.results import Outcome, Status
from rosnet_tui.core.ros import ros2
from rosnet_tui.core.ssh.connection import SshResult

FACTOR_GRAPH, FACTOR_PUBSUB = 2.0, 4.0


# --------------------------------------------------------------------------- ros2.graph
def _local_zids(info: dict) -> set[str]:
    """Sessions attached to a router over loopback: that machine's own nodes."""
    out = set()
    for x in info.get("sessions") or []:
        if x.get("whatami") in ("client", "peer") and any(
                is_loopback(ln.split("/", 1)[-1].rsplit(":", 1)[0].strip("[]"))
                for ln in x.get("links") or []):
            out.add(str(x.get("zid")))
    return out


def _user_nodes(tokens: list[dict]) -> dict[tuple[str, str], bool]:
    """{(zid, /ns/name): humble} of the nodes in *tokens*, our probes left out."""
    nodes: dict[tuple[str, str], bool] = {}
    for tk in tokens:
        if tk["name"].startswith(zenohproto.PROBE_PREFIX):
            continue
        key = (tk["zid"], zenohproto.fq_name(tk["namespace"], tk["name"]))
        nodes[key] = nodes.get(key, False) or tk.get("hash") == zenohproto.HUMBLE_HASH
    return nodes


async def _unlinked(ctx: CheckContext, session: Any, how: str) -> str | None:
    """On a member whose nodes sit on its own router: why that router has no link to the
    master's (None: it has one, or this is the master, or the nodes here are clients)."""
    if ctx.settings.is_master or how != "router":
        return None
    info = await run_blocking(zenohproto.router_info, session, 0.4, timeout=0.8)
    if router_links(info):
        return None
    return (f"this machine's router has no link to the master's router "
            f"{ctx.settings.master_name} (it cannot reach {ros2.master_endpoint(ctx.settings)}"
            ", or its config does not connect there)")


def _late(peer: Peer, t: float) -> SshResult:
    """A peer's side that gave no report by the end of the check's *t* s (a thin, busy link)."""
    return SshResult(False, None, "", "", "timeout",
                     f"none by the end of the check's {t:g} s: a slow or busy link?",
                     None)


@check("ros2.graph", "ros", "The ROS 2 graph: every component's nodes are seen", FACTOR_GRAPH,
       ros=2)
async def check_graph(ctx: CheckContext) -> Outcome:
    s, dom = ctx.settings, node_domain(ctx)
    t = budget(ctx, "ros2.graph")
    end = time.monotonic() + t - 0.15      # our own verdict by then (the runner's at t)
    deadline = end - 0.25                  # then the probe node and the session close (what
                                           # they have not done by the end: in the background)
    data: dict[str, Any] = {"nodes": [], "topics": [], "seen_from": [], "missing": [],
                            "probe_seen": {}, "ours_seen": {}, "mixed_hashes": False}
    endpoint, how = node_endpoint(ctx)
    session, why = await open_zenoh(endpoint, min(2.0, t * 0.3))
    if session is None:
        who = "this machine's router" if how == "router" else f"the master's router ({how} mode)"
        return Outcome(Status.FAIL, f"cannot read the graph: {who} does not answer at {endpoint} "
                                    f"({why})", [], data)
    unlinked = await _unlinked(ctx, session, how)
    if unlinked:
        await close_zenoh(session)
        return Outcome(Status.FAIL, f"only this component's part of the graph is visible: "
                                    f"{unlinked} (see ros2.router)", [], data)
    ours = zenohproto.probe_name()
    node = await run_blocking(zenohproto.ProbeNode, session, dom, ours, "rosnet_tui/graph",
                              timeout=2.0)
    peers = ros2_peers(ctx)
    theirs = {p.name: zenohproto.probe_name() for p in peers}
    remote_t = max(0.5, t * 0.55)
    # One task for every peer's side (probes.peers.each_peer: bounded, one SSH connection per peer).
    tasks = [asyncio.ensure_future(each_peer(peers, lambda p: peer_run(
        ctx, p, ZENOH_AGENT, "zenoh", ["graph", "--expect", ours, "--name", theirs[p.name],
                                       "--timeout", f"{remote_t:.1f}", *member_arg(ctx, p)],
        timeout=max(0.5, deadline - time.monotonic()),
        connect_timeout=max(0.5, ctx.timeout_s * 0.6), needs_install=True)))]
    # Every token seen during the check, not only at the last look: a peer drops its probe node
    # once acknowledged, so with several peers the first one's is gone from a later look while
    # we still wait for another's (issue 21: "the probe node ... not seen", from a member).
    seen: dict[tuple, dict] = {}
    info: dict = {}
    acked: set[str] = set()

    def ack() -> None:  # again on every round: an ack sent before the peer's subscription
        for n in acked:  # has reached our router is lost, and the peer would wait its timeout
            session.put(f"rosnet_tui/ack/{n}", b"seen")

    try:
        while True:
            left = deadline - time.monotonic()
            try:
                look = await run_blocking(zenohproto.graph, session, dom,
                                          max(0.1, min(0.5, left)),
                                          timeout=max(0.3, min(1.5, left + 0.5)))
            except asyncio.TimeoutError:    # a slow answer: the next look, or what we have
                look = []
            seen.update((tuple(sorted(tk.items())), tk) for tk in look)
            acked |= {n for n in theirs.values() if any(tk["name"] == n for tk in look)}
            ack()  # the peers whose probe node we saw may drop it now
            if len(acked) == len(theirs) or left < t * 0.25 or all(x.done() for x in tasks):
                break
            await asyncio.sleep(0.15)
        left = deadline - time.monotonic()
        with contextlib.suppress(asyncio.TimeoutError):     # its account as far as it came
            info = await run_blocking(zenohproto.router_info, session,
                                      max(0.05, min(0.5, left - 0.1)),
                                      timeout=max(0.05, min(1.0, left)))
        while acked and not all(x.done() for x in tasks) and time.monotonic() < deadline:
            await asyncio.wait(tasks, timeout=0.1)
            ack()
        await asyncio.wait(tasks, timeout=max(0.05, deadline - time.monotonic()))
        results = tasks[0].result() if tasks[0].done() else [_late(p, t) for p in peers]
    finally:
        for task in tasks:
            task.cancel()
        with contextlib.suppress(asyncio.TimeoutError):     # the rest in the background
            await run_blocking(node.close, timeout=max(0.05, min(1.0, end - time.monotonic())))
        await close_zenoh(session, end - time.monotonic())
    ev: list[str] = []
    tokens = list(seen.values())
    names = {tk["name"] for tk in tokens}
    here = _user_nodes(tokens)
    comp_of: dict[str, str] = {z: s.this.name for z in _local_zids(info)} if how == "router" else {}
    data["seen_from"].append("here")
    problems: list[str] = []
    uninstalled: list[str] = []    # peers with no rosnet-tui to run the other side
    missing: dict[str, list[str]] = {}
    dead: list[str] = []
    domains: list[str] = []
    for p, res in zip(peers, results, strict=True):
        rep = zenohproto.parse_report(res.stdout)
        why_not = zenoh_peer_problem(res, p, rep)
        if not why_not and rep is not None and rep.get("error") in ("open", "no_link"):
            dead.append(f"on {p.name}, {rep.get('detail')}")
            continue
        if why_not or rep is None or rep.get("error"):
            if rep is not None and rep.get("error") == "no_install":
                uninstalled.append(p.name)
            problems.append(why_not or f"on {p.name}: {rep.get('detail') if rep else '?'}")
            continue
        data["seen_from"].append(p.name)
        data["probe_seen"][p.name] = theirs[p.name] in names
        data["ours_seen"][p.name] = any(tk["name"] == ours for tk in rep.get("tokens") or [])
        pz = _local_zids(rep.get("router") or {}) if rep.get("how") == "router" else \
            {str(rep.get("own_zid"))}
        comp_of.update({z: p.name for z in pz})
        theirs_nodes = _user_nodes(rep.get("tokens") or [])
        gone = sorted(n for (z, n) in theirs_nodes if z in pz and (z, n) not in here)
        if not data["probe_seen"][p.name]:
            gone.insert(0, f"(the probe node {theirs[p.name]})")
        if gone:
            missing[p.name] = gone
        if str(rep.get("domain")) != str(dom):
            domains.append(f"{p.name}'s nodes use ROS_DOMAIN_ID {rep.get('domain')}, ours {dom}")
        ev.append(f"from {p.name}: {len(theirs_nodes)} node(s); our probe node "
                  f"{'seen' if data['ours_seen'][p.name] else 'NOT seen'} there")
    for (z, n), humble in sorted(here.items(), key=lambda kv: kv[0][1]):
        data["nodes"].append({"name": n, "zid": z, "component": comp_of.get(z), "humble": humble})
    data["topics"] = sorted({(tk["topic"], tk["type"]) for tk in tokens if tk["kind"] in ("MP", "MS")
                             and not tk["topic"].startswith(("/rosnet_tui", "rosnet_tui"))})
    data["topics"] = [list(x) for x in data["topics"]]
    flags = {n["humble"] for n in data["nodes"] if any(
        tk["zid"] == n["zid"] and tk["kind"] in ("MP", "MS") for tk in tokens)}
    data["mixed_hashes"] = flags == {True, False}
    data["missing"] = sorted(missing)
    by_comp: dict[str, list[str]] = {}
    for n in data["nodes"]:
        by_comp.setdefault(n["component"] or "elsewhere", []).append(n["name"])
    ev.append("nodes seen from here: " + ("; ".join(f"{c}: {', '.join(v)}" for c, v in
                                                     by_comp.items()) or "none but our probes"))
    ev.append(f"topics: {', '.join(f'{a} [{b}]' for a, b in data['topics']) or 'none'}")
    ev += [f"not checked from a peer: {p}" for p in problems]
    not_there = [p for p, seen in data["ours_seen"].items() if not seen]
    if dead:
        data["missing"] = sorted(set(data["missing"]) | {p.name for p in peers
                                                         if any(d.startswith(f"on {p.name},")
                                                                for d in dead)})
        return Outcome(Status.FAIL, "the other side of the graph cannot be reached: "
                                    + "; ".join(dead), ev, data)
    if missing or not_there:
        parts = [f"{c}'s nodes are not seen from here: {', '.join(v)}" for c, v in missing.items()]
        parts += [f"our probe node is not seen on {p}" for p in not_there]
        cause = "; ".join(domains) or "the routers are not linked (see ros2.router)"
        return Outcome(Status.FAIL, "; ".join(parts) + f": {cause}", ev + domains, data)
    if data["mixed_hashes"]:
        return Outcome(Status.FAIL, "Humble nodes (TypeHashNotSupported) and Jazzy-or-later nodes "
                                    "share this graph: they see each other but every message "
                                    "between them is dropped; use one distro everywhere", ev, data)
    n = len(data["nodes"])
    if problems and len(data["seen_from"]) == 1 and len(uninstalled) == len(problems):
        return Outcome(Status.SKIP, f"{n} node(s) seen from here, but the other side could not "
                                    f"run: {problems[0]}", ev, data)
    if problems:
        return Outcome(Status.WARN, f"{n} node(s) seen from here, but not checked from the peer: "
                                    f"{problems[0]}", ev, data)
    seats = " and ".join(data["seen_from"])
    return Outcome(Status.PASS, f"{n} node(s) on {len(by_comp)} component(s) seen; probe nodes "
                                f"seen both ways (from {seats})" if peers else
                   f"{n} node(s) seen from here (no peer with an SSH user: one side only)",
                   ev, data)


# --------------------------------------------------------------------------- pub/sub
def _pdata(peer: str, ok: bool, hop: str | None = None, seen: bool | None = None,
           detail: str | None = None) -> dict[str, Any]:
    return {"peer": peer, "ok": ok, "failed_hop": hop, "graph_seen": seen, "detail": detail}


_HOPS = {"our_router": "our router", "master_router": "the master's router",
         "peer_router": "the peer's router", "peer_subscriber": "the peer's subscriber",
         "our_subscriber": "our subscriber", "data_dropped": "graph seen, data dropped"}


def _quiet_hop(ctx: CheckContext, ours: dict, rep: dict, receiver_here: bool) -> tuple[str, str]:
    """Where a message that nobody saw went missing, from both routers' links."""
    s = ctx.settings
    if str(rep.get("domain")) != str(node_domain(ctx)):
        return ("our_subscriber" if receiver_here else "peer_subscriber",
                f"the peer's nodes use ROS_DOMAIN_ID {rep.get('domain')}, ours {node_domain(ctx)}")
    if not s.is_master and node_endpoint(ctx)[1] == "router" and not router_links(ours):
        return "master_router", "this machine's router has no link to the master's router"
    prouter = rep.get("router") or {}
    if s.is_master and rep.get("how") == "router" and not router_links(prouter):
        return "peer_router", "the peer's router has no link to this router (the master's)"
    return ("our_subscriber" if receiver_here else "peer_subscriber",
            "both routers are linked, yet the subscriber saw neither the publisher nor its data")


async def _seen_by_client(endpoint: str, dom: int, topic: str) -> bool | None:
    """Whether the graph, read as `ros2 node list` reads it (a client), has a publisher on
    *topic* (None: no session to ask)."""
    viewer, _ = await open_zenoh(endpoint, 0.5)
    if viewer is None:
        return None
    try:
        return await run_blocking(zenohproto.sees, viewer, dom, "MP", topic, 0.3, timeout=1.0)
    finally:
        await close_zenoh(viewer)


async def _exchange(ctx: CheckContext, peer: Peer, out: bool, budget_s: float
                    ) -> tuple[Status, str, list[str], dict[str, Any]]:
    deadline = time.monotonic() + budget_s
    arrow = f"here -> {peer.name}" if out else f"{peer.name} -> here"
    endpoint, how = node_endpoint(ctx)
    session, why = await open_zenoh(endpoint, min(2.0, budget_s * 0.2), how)
    if session is None:
        hop = "our_router" if how == "router" else "master_router"
        return (Status.FAIL, f"{arrow}: {_HOPS[hop]} does not answer at {endpoint} ({why})", [],
                _pdata(peer.name, False, hop, None, why))
    unlinked = await _unlinked(ctx, session, how)
    if unlinked:
        await close_zenoh(session)
        return (Status.FAIL, f"{arrow}: no message can pass: {unlinked}", [],
                _pdata(peer.name, False, "master_router", None, unlinked))
    tag = secrets.token_hex(4)
    topic, text, dom = f"rosnet_tui/probe_{tag}", f"rosnet-tui {tag}", node_domain(ctx)
    node = await run_blocking(zenohproto.ProbeNode, session, dom, zenohproto.probe_name(), topic,
                              timeout=2.0)
    await run_blocking(node.publisher if out else node.subscription, timeout=2.0)
    remote_t = max(1.0, min(budget_s * 0.6, ctx.timeout_s * 2))
    deadline = min(deadline, time.monotonic() + remote_t + max(1.0, ctx.timeout_s))
    args = (["sub", "--expect", text] if out else ["pub", "--text", text, "--ack", tag])
    argv = [*args, "--topic", topic, "--timeout", f"{remote_t:.1f}", *member_arg(ctx, peer)]
    got: tuple[str | None, bool | None, int] = (None, None, 0)
    seen_pub: bool | None = None
    ev: list[str] = []
    info: dict = {}
    try:
        async with peer_session(ctx, peer, ZENOH_AGENT, "zenoh", argv,
                                timeout=max(0.5, min(budget_s * 0.3, ctx.timeout_s * 0.6)),
                                needs_install=True) as sess:
            if not sess.ok:
                return (Status.SKIP, f"skipped: could not run the other side on {peer.name}: SSH "
                                     f"failed ({sess.result.failure}): {sess.result.detail}", [],
                        _pdata(peer.name, False))
            ready = await sess.read_until(zenohproto.READY_MARK, timeout=max(0.3, budget_s * 0.4))
            if ready is not None and out:
                while time.monotonic() < deadline - 0.5:
                    node.publish(text)
                    if await sess.read_until(zenohproto.REPORT_MARK, timeout=0.1) is not None:
                        break
            elif ready is not None:
                window = max(0.2, min(deadline - time.monotonic() - 0.8, remote_t - 1.0))
                got = await run_blocking(zenohproto.wait_message, node, window, text,
                                         timeout=window + 1.0)
                if got[0] is not None:  # the peer publishes until acked: ack until it reports
                    ack_until = min(deadline - 0.3, time.monotonic() + max(1.0, ctx.timeout_s))
                    session.put(f"rosnet_tui/ack/{tag}", b"ok")
                    while time.monotonic() < ack_until and await sess.read_until(
                            zenohproto.REPORT_MARK, timeout=0.1) is None:
                        session.put(f"rosnet_tui/ack/{tag}", b"ok")  # one may have been lost
                        await asyncio.sleep(0.02)
                else:  # while the peer still publishes: is its publisher in the graph?
                    seen_pub = await _seen_by_client(endpoint, dom, topic)
            with contextlib.suppress(asyncio.TimeoutError):     # a slow answer: none
                info = await run_blocking(zenohproto.router_info, session, 0.4, timeout=0.8)
            res = await sess.wait(max(0.3, deadline - time.monotonic()))
    finally:
        with contextlib.suppress(asyncio.TimeoutError):         # the rest in the background
            await run_blocking(node.close, timeout=1.0)
        await close_zenoh(session)
    rep = zenohproto.parse_report(res.stdout)
    why_not = zenoh_peer_problem(res, peer, rep)
    if why_not:
        return (Status.SKIP, f"skipped: could not run the other side on {peer.name}: {why_not}",
                ev, _pdata(peer.name, False))
    assert rep is not None
    ev.append(f"{peer.name}: {rep.get('how')} session on {rep.get('endpoint')}"
              + (f", router {rep['router'].get('zid')}" if rep.get("router") else "")
              + (f" (run by {rep['python']})" if rep.get("python") else ""))
    if rep.get("error"):
        return (Status.FAIL, f"{arrow}: on {peer.name}, {rep.get('detail')}",
                ev, _pdata(peer.name, False, "peer_router", None, rep.get("detail")))
    if out:
        received, att_ok, seen = rep.get("received"), rep.get("attachment_ok"), rep.get("saw_publisher")
    else:
        received, att_ok, _n = got
        seen = seen_pub
    ev.append(f"{arrow}: " + (f"received {received!r} (rmw_zenoh attachment: {att_ok})"
                              if received else f"nothing received; publisher token "
                                               f"{'seen' if seen else 'not seen'} by the receiver"))
    if received and att_ok:
        return (Status.PASS, f"{arrow}: a message in rmw_zenoh's format went through the routers "
                             f"({received!r})", ev, _pdata(peer.name, True, None, True))
    if seen:
        return (Status.FAIL, f"{arrow}: graph seen, data dropped: the receiver sees the publisher "
                             "but no message arrives (a lone node in peer mode, or mixed distros "
                             "or rmw_zenoh versions)", ev,
                _pdata(peer.name, False, "data_dropped", True))
    hop, detail = _quiet_hop(ctx, info, rep, not out)
    return (Status.FAIL, f"{arrow}: no message, failed at {_HOPS[hop]}: {detail}", ev,
            _pdata(peer.name, False, hop, False, detail))


async def _pubsub(ctx: CheckContext, out: bool, cid: str) -> Outcome:
    peers = ros2_peers(ctx)
    if not ctx.settings.master_name:
        return Outcome(Status.SKIP, "skipped: no master is named in the settings (ros.master)",
                       [], _pdata("", False))
    if not peers:
        return Outcome(Status.SKIP, "skipped: no peer with an SSH user in the settings, so the "
                                    "other side of the exchange cannot be run from here", [],
                       _pdata("", False))
    b = budget(ctx, cid) - 0.5
    outcomes = await each_peer(peers, lambda p: _exchange(ctx, p, out, b))
    rank = {Status.FAIL: 0, Status.SKIP: 1, Status.WARN: 2, Status.PASS: 3}
    worst = min(range(len(peers)), key=lambda i: rank[outcomes[i][0]])
    status, summary, _, data = outcomes[worst]
    data = dict(data)
    data["peers"] = {p.name: o[3] for p, o in zip(peers, outcomes, strict=True)}
    ev = [line for o in outcomes for line in o[2]]
    if len(peers) > 1:
        summary += f" ({sum(o[0] == Status.PASS for o in outcomes)} of {len(peers)} peers passed)"
    return Outcome(status, summary, ev, data)


@check("ros2.pubsub_out", "ros", "A ROS 2 message published here reaches the peer",
       FACTOR_PUBSUB, ros=2)
async def check_pubsub_out(ctx: CheckContext) -> Outcome:
    return await _pubsub(ctx, True, "ros2.pubsub_out")


@check("ros2.pubsub_in", "ros", "A ROS 2 message published on the peer reaches us",
       FACTOR_PUBSUB, ros=2)
async def check_pubsub_in(ctx: CheckContext) -> Outcome:
    return await _pubsub(ctx, False, "ros2.pubsub_in")
