"""Step 4 checks: the ROS environment, the master, the nodes' addresses and live publish/subscribe.

The probes are ROS nodes of our own (:mod:`rosnet_tui.core.peer.rosproto`), advertised the way any node
started here would be, so a wrong ``ROS_IP`` or hostname shows up exactly as it does for the user's
nodes. The peer's side runs the same module over SSH (``python3 -`` fed its source): no ROS and no
rosnet-tui are needed there.
"""

from __future__ import annotations

import asyncio
import time
from typing import Any
from urllib.parse import urlparse

from rosnet_tui.core.addresses import is_loopback
from rosnet_tui.core.checks import CheckContext, check
from rosnet_tui.core.checks.probes.agents import (
    ROS_AGENT,
    peer_program_problem,
    peer_run,
    peer_session,
    why_no_report,
)
from rosnet_tui.core.checks.probes.peers import each_peer
from rosnet_tui.core.checks.probes.ros1 import master_uri, ros1_peers
from rosnet_tui.core.config.settings_model import Peer, Settings
from rosnet_tui.core.files.hosts import own_ip
from rosnet_tui.core.net.blocking import run_blocking
from rosnet_tui.core.peer import rosproto
from rosnet_tui.core.results import Outcome, Status
from rosnet_tui.core.ssh.connection import SshResult

READY_MARK = '"rosnet_probe_ready"'
FACTOR_NODE_URIS = 3.0
FACTOR_PUBSUB = 4.0
# A check's own verdict lands this long before the runner's timeout (its budget): the probes
# stop by then, and what they saw is said (on a thin link an unregistering call may take
# seconds: it goes on in the background).
OWN_END_S = 0.25
STOP_S = 0.5                 # before that end: the probe nodes stop (unregister, close)


# --------------------------------------------------------------------------- helpers
def _budget(ctx: CheckContext, factor: float) -> float:
    return max(0.5, float(ctx.timeout_s) * factor)


def _uri_parts(uri: str) -> tuple[str, int | None]:
    p = urlparse(uri.strip())
    if p.scheme != "http" or not p.hostname:
        return "", None
    try:
        return p.hostname.lower(), p.port or 80
    except ValueError:
        return p.hostname.lower(), None


def _remote_report(res: SshResult) -> dict[str, Any] | None:
    return rosproto.parse_report_line(res.stdout)


async def _stop(node: rosproto.ProbePublisher, by: float) -> rosproto.ProbeReport:
    """Stop *node* (unregister, close), waiting for it until *by* at most: its report as it
    stands (a stop still under way on a slow link ends in the background)."""
    try:
        return await run_blocking(node.stop, timeout=max(0.05, by - time.monotonic()))
    except asyncio.TimeoutError:
        return node.report


# --------------------------------------------------------------------------- ros.env
def _expected(s: Settings) -> tuple[str, set[str], str]:
    """(expected URI, acceptable hosts, words for the rule)."""
    port = s.ros.port
    if s.is_master:
        hosts = {h.lower() for h in (s.this.name, own_ip(s, s.this.profile), s.this.local_ip) if h}
        name = s.this.name or own_ip(s, s.this.profile)
        return (f"http://{name}:{port}", hosts,
                "on the master, ROS_MASTER_URI names the master itself: its own name or its "
                "local IP")
    return (f"http://{s.master_name}:{port}", {s.master_name.lower()},
            f"on a member, ROS_MASTER_URI names the master, {s.master_name}, by its name (the "
            "hosts file maps it to the master's address)")


def _judge_uri(s: Settings, uri: str, hosts: set[str]) -> tuple[str, str | None]:
    """('ok'|'warn'|'fail', reason) for one ROS_MASTER_URI value."""
    host, port = _uri_parts(uri)
    if not host:
        return "fail", f"'{uri}' is not an http://NAME:PORT address"
    if port != s.ros.port:
        return "fail", f"port {port} differs from the master's port {s.ros.port}"
    if host in hosts:
        return "ok", None
    if s.is_master and is_loopback(host):
        return "warn", (f"{host} works only on this machine; use its name {s.this.name or ''} "
                        "(or local IP) as the procedure does")
    if s.is_master and host == (s.this.public_ip or "").lower():
        return "fail", ("this is the public IP: roscore refuses to start with it; use the "
                        "master's own name or local IP")
    peer = s.peer(s.master_name) if not s.is_master else None
    if peer and host in {peer.public_ip, peer.local_ip}:
        return "fail", (f"{host} is an address of {peer.name}; use its name so that one hosts "
                        "entry follows address changes")
    return "fail", f"{host} is not {' or '.join(sorted(hosts)) or 'the master'}"


@check("ros.env", "ros", "ROS_MASTER_URI, ROS_IP and ROS_HOSTNAME", ros=1)
async def check_env(ctx: CheckContext) -> Outcome:
    s = ctx.settings
    if not s.master_name:
        return Outcome(Status.SKIP, "skipped: no ROS master is configured in the settings "
                                    "(ros.master)", [], {"expected_uri": ""})
    expected, hosts, rule = _expected(s)
    rc_path = str(ctx.paths.bashrc_path)
    rc = rosproto.read_shell_exports(rc_path, ("ROS_MASTER_URI", "ROS_IP", "ROS_HOSTNAME"))
    env_uri = ctx.env.get("ROS_MASTER_URI")
    rc_uri_entry = rc.get("ROS_MASTER_URI")
    bashrc_uri = rc_uri_entry[0] if rc_uri_entry else None
    evidence = [f"expected {expected} ({rule})"]
    fails: list[str] = []
    warns: list[str] = []
    oks = 0
    doubtful = False   # a URI that is set but judged only a warning
    for label, uri in (("the environment", env_uri), (f"{ctx.paths.bashrc_path}", bashrc_uri)):
        if uri is None:
            evidence.append(f"{label}: ROS_MASTER_URI not set")
            continue
        where = label if label == "the environment" else \
            f"{label} line {rc_uri_entry[1] if rc_uri_entry else '?'}"
        verdict, why = _judge_uri(s, uri, hosts)
        evidence.append(f"{where}: ROS_MASTER_URI={uri}" + (f" - {why}" if why else " - ok"))
        if verdict == "ok":
            oks += 1
        elif verdict == "warn":
            doubtful = True
            warns.append(f"ROS_MASTER_URI in {label}: {why}")
        else:
            fails.append(f"ROS_MASTER_URI={uri} in {label}: {why}")
    if env_uri is None and bashrc_uri is None:
        fails.append(f"ROS_MASTER_URI is set neither in the environment nor in {ctx.paths.bashrc_path}; "
                     f"add: export ROS_MASTER_URI={expected}")
    elif bashrc_uri is None:
        warns.append(f"ROS_MASTER_URI is not in {ctx.paths.bashrc_path}: new terminals will not have "
                     f"it (add: export ROS_MASTER_URI={expected})")
    elif env_uri is None:
        warns.append(f"ROS_MASTER_URI is in {ctx.paths.bashrc_path} but not in this environment: "
                     f"open a new terminal or run: source {ctx.paths.bashrc_path}")

    overrides: dict[str, str | None] = {}
    for name in ("ROS_IP", "ROS_HOSTNAME"):
        entry = rc.get(name)
        value, where = None, ""
        if name in ctx.env:
            value, where = ctx.env[name], "the environment"
        elif entry and entry[0] is not None:
            value, where = entry[0], f"{ctx.paths.bashrc_path} line {entry[1]}"
        overrides[name] = value
        if value is None:
            continue
        evidence.append(f"{where}: {name}={value}")
        if is_loopback(value):
            warns.append(f"{name}={value} ({where}): nodes here then advertise a loopback "
                         "address that no other component can reach; remove it")
        elif s.this.profile == "remote":
            warns.append(f"{name}={value} ({where}): on a remote network it overrides the "
                         "hosts-file names, so the other side gets an address it may not reach "
                         "(nodes publish but cannot subscribe, or the reverse); remove it")
        else:
            evidence.append(f"{name} is fine on the {s.this.profile} LAN profile, but remove it "
                            "before using the remote network")

    uri_ok = not fails and oks > 0 and not doubtful
    data = {"env_uri": env_uri, "bashrc_uri": bashrc_uri, "expected_uri": expected,
            "uri_ok": uri_ok, "ros_ip": overrides["ROS_IP"],
            "ros_hostname": overrides["ROS_HOSTNAME"]}
    if fails:
        return Outcome(Status.FAIL, "; ".join(fails), evidence + [f"warning: {w}" for w in warns],
                       data)
    if warns:
        return Outcome(Status.WARN, "; ".join(warns), evidence, data)
    return Outcome(Status.PASS, f"ROS_MASTER_URI={expected} in the environment and in "
                                f"{ctx.paths.bashrc_path}; no ROS_IP or ROS_HOSTNAME", evidence, data)


# --------------------------------------------------------------------------- ros.master
async def _resolve(host: str, timeout: float) -> tuple[str | None, str | None]:
    loop = asyncio.get_running_loop()
    try:
        infos = await asyncio.wait_for(loop.getaddrinfo(host, None, type=1), timeout)
    except asyncio.TimeoutError:
        return None, f"the resolver gave no answer for '{host}' within {timeout:.1f} s"
    except OSError as exc:
        return None, f"the name '{host}' does not resolve here ({getattr(exc, 'strerror', exc)})"
    return str(infos[0][4][0]), None


@check("ros.master", "ros", "The ROS master answers", ros=1)
async def check_master(ctx: CheckContext) -> Outcome:
    uri, why = master_uri(ctx)
    if uri is None:
        return Outcome(Status.SKIP, f"skipped: {why}", [], {"uri": "", "reachable": False,
                                                             "topics": [], "nodes": []})
    budget = _budget(ctx, 1.0)
    deadline = time.monotonic() + budget - 0.15
    data: dict[str, Any] = {"uri": uri, "reachable": False, "topics": [], "nodes": []}
    evidence = [f"master URI {uri} (from {why})"]
    env_uri = ctx.env.get("ROS_MASTER_URI")
    if env_uri and env_uri.rstrip("/") != uri.rstrip("/"):
        evidence.append(f"note: ROS_MASTER_URI here is {env_uri} (see ros.env)")
    host, port = _uri_parts(uri)
    if not host:
        return Outcome(Status.FAIL, f"'{uri}' is not a usable master URI", evidence, data)
    ip, err = await _resolve(host, max(0.1, min(budget * 0.5, deadline - time.monotonic())))
    if ip is None:
        return Outcome(Status.FAIL, f"cannot reach the master: {err}", evidence, data)
    evidence.append(f"{host} resolves to {ip}")
    call_t = max(0.1, deadline - time.monotonic())
    client = rosproto.MasterClient(uri, "/rosnet_tui_check", call_t)
    started = time.monotonic()
    try:
        state = await run_blocking(client.get_system_state, timeout=call_t + 0.1)
    except asyncio.TimeoutError:
        data["tcp"] = "timeout"
        return Outcome(Status.FAIL, f"the master at {uri} ({ip}) gave no answer within "
                                    f"{call_t:.1f} s (timed out)",
                       evidence + [f"getSystemState sent to {ip}:{port}: no answer"], data)
    except Exception as exc:
        kind, words = rosproto.describe_error(exc, call_t)
        data["tcp"] = kind if kind in ("refused", "timeout", "unreachable") else \
            "connected" if kind in ("http", "fault", "protocol", "master", "reset") else "error"
        hint = {"refused": f": is roscore running on {host}, and is port {port} forwarded?",
                "timeout": ": no reply (a firewall, no forwarding, or the wrong address)",
                "unreachable": ": no route to that address"}.get(kind, "")
        return Outcome(Status.FAIL, f"the master at {uri} ({ip}) did not answer getSystemState: "
                                    f"{words}{hint}",
                       evidence + [f"getSystemState sent to {ip}:{port}: {kind}"], data)
    took = time.monotonic() - started
    types: dict[str, str] = {}
    left = deadline - time.monotonic()
    if left > 0.05:
        try:
            types = dict(await run_blocking(client.get_topic_types, left, timeout=left + 0.1))
        except Exception:
            pass
    # The short-lived probe nodes and topics of rosnet-tui (this round's checks) are noise here.
    ours = rosproto.PROBE_PREFIX
    topics = [[t, types.get(t, "?")] for t in state.topics if not t.startswith(ours)]
    nodes = [n for n in state.nodes if not n.startswith(ours)]
    data.update(reachable=True, topics=topics, nodes=nodes, tcp="connected")
    evidence.append(f"getSystemState answered in {took:.2f} s")
    hidden = len(state.nodes) - len(nodes)
    if hidden:
        evidence.append(f"({hidden} short-lived probe node(s) of rosnet-tui not listed)")
    evidence.append(f"topics ({len(topics)}): " + (", ".join(f"{t} [{ty}]" for t, ty in topics)
                                                   or "none"))
    evidence.append(f"nodes ({len(nodes)}): " + (", ".join(nodes) or "none"))
    return Outcome(Status.PASS, f"the master at {uri} answers: {len(topics)} topic(s), "
                                f"{len(nodes)} node(s)", evidence, data)


# --------------------------------------------------------------------------- ros.node_uris
def _unreachable(report: dict[str, Any], where: str, verdict: bool | None = False
                 ) -> list[dict[str, Any]]:
    """The nodes of a reachability *report* whose verdict is *verdict* (False: unreachable,
    None: undetermined), in the contract's shape plus where they were tested from."""
    return [{"node": n["node"], "uri": n["uri"], "host": n["host"], "reason": n["reason"],
             "from": where}
            for n in report.get("nodes", []) if n.get("reachable") is verdict]


def _node_lines(report: dict[str, Any], where: str) -> list[str]:
    out = []
    for n in report.get("nodes", []):
        target = f"{n['uri'] or '?'}" + (f" ({n['ip']})" if n.get("ip") else "")
        verdict = {True: "accepts a TCP connection", False: f"UNREACHABLE: {n['reason']}",
                   None: f"not checked: {n['reason']}"}[n.get("reachable")]
        out.append(f"from {where}: {n['node']} at {target} {verdict}")
    return out


async def _start_publisher(pub: rosproto.ProbePublisher, ct: float) -> bool:
    """Start *pub* (serve, register) within its call timeout; False with the reason reported."""
    try:
        return await run_blocking(pub.start, timeout=ct + 0.5)
    except asyncio.TimeoutError:
        pub.stopping.set()  # a late registration undoes itself
        pub.report.fail("registration", f"no answer from the master {pub.master_uri} within "
                                        f"{ct + 0.5:.1f} s (timed out)",
                        pub.caller_id, pub.master_uri)
        return False


def _local_nodes(uri: str, timeout: float, include: list[str]) -> dict[str, Any]:
    return rosproto.check_node_uris(uri, timeout, include=include)


@check("ros.node_uris", "ros", "Every node's address is reachable", FACTOR_NODE_URIS, ros=1)
async def check_node_uris(ctx: CheckContext) -> Outcome:
    uri, why = master_uri(ctx)
    data: dict[str, Any] = {"unreachable": [], "checked": 0, "from": []}
    if uri is None:
        return Outcome(Status.SKIP, f"skipped: {why}", [], data)
    budget = _budget(ctx, FACTOR_NODE_URIS)
    end = time.monotonic() + budget - OWN_END_S        # our verdict by then, the runner's after
    deadline = end - STOP_S
    ct = max(0.3, min(2.0, ctx.timeout_s * 0.8))
    evidence: list[str] = []
    # A probe node of ours, advertised like any node started here: the peers test it too.
    me = rosproto.ProbePublisher(uri, f"{rosproto.PROBE_PREFIX}/{rosproto.new_probe_id()}/uris",
                                 env=ctx.env, bashrc=str(ctx.paths.bashrc_path), call_timeout=ct)
    registered = await _start_publisher(me, ct)
    if registered:
        evidence.append(f"probe node {me.caller_id} registered, advertising {me.uri} "
                        f"(host from {me.host_from}), as any node started here would")
    else:
        evidence.extend(me.report.evidence("here"))
        if me.master_error in ("refused", "timeout", "unreachable", "resolve"):
            await _stop(me, end)
            return Outcome(Status.FAIL, f"cannot list the nodes: the master does not answer "
                                        f"({me.report.hops[-1].detail})", evidence, data)
    peers = ros1_peers(ctx.settings)
    local_t = max(0.3, min(budget * 0.5, deadline - time.monotonic()))
    remote_t = max(0.5, budget * 0.45)
    include = ["--include", me.caller_id] if registered else []
    argv = ["nodes", "--master", uri, "--timeout", f"{remote_t:.1f}", *include]
    ssh_t = max(0.5, deadline - time.monotonic())
    remote_tasks = [asyncio.ensure_future(each_peer(
        peers, lambda p: peer_run(ctx, p, ROS_AGENT, "ros", argv, timeout=ssh_t,
                                  tcp_timeout=ctx.timeout_s), return_exceptions=True))]
    local_wait = max(0.1, min(local_t + 1.0, deadline - time.monotonic()))
    remote_results: list[Any] = []
    try:
        try:
            local: Any = await run_blocking(_local_nodes, uri, local_t,
                                            [me.caller_id] if registered else [],
                                            timeout=local_wait)
        except asyncio.TimeoutError as exc:
            local = exc
        if isinstance(local, dict) and not local.get("error"):
            # the peers' view, as far as it came by the deadline (a thin link: the agent late)
            done, _ = await asyncio.wait(remote_tasks,
                                         timeout=max(0.05, deadline - time.monotonic()))
            remote_results = remote_tasks[0].result() if done else \
                [asyncio.TimeoutError()] * len(peers)
    finally:
        for t in remote_tasks:
            t.cancel()
        await asyncio.gather(*remote_tasks, return_exceptions=True)
        await _stop(me, end)

    if isinstance(local, BaseException):
        return Outcome(Status.FAIL, f"the probe here listed no nodes within {local_wait:.1f} s "
                                    "(the master or the link too slow to answer)",
                       evidence, data)
    if local.get("error"):
        return Outcome(Status.FAIL, f"cannot list the nodes: {local['error']}",
                       evidence, data)
    unreachable = _unreachable(local, "here")
    unknown = _unreachable(local, "here", None)
    evidence.extend(_node_lines(local, "here"))
    data["from"].append("here")
    checked = {n["node"] for n in local["nodes"]}
    if local.get("excluded"):
        evidence.append(f"left out {len(local['excluded'])} short-lived probe node(s) of "
                        "rosnet-tui")
    problems: list[str] = []
    if not peers:
        evidence.append("no peer with an SSH user in the settings: checked from here only")
    for peer, res in zip(peers, remote_results, strict=True):
        if isinstance(res, asyncio.TimeoutError):
            problems.append(f"{peer.name}: its probe gave no report within the check's "
                            f"{budget:g} s")
            continue
        if isinstance(res, BaseException):
            problems.append(f"{peer.name}: {type(res).__name__}")
            continue
        why_not = peer_program_problem(res, peer)
        rep = _remote_report(res) if why_not is None else None
        if rep is None:
            problems.append(why_not or f"the probe on {peer.name} gave no report "
                                       f"({why_no_report(res)})")
            continue
        if rep.get("error"):
            problems.append(f"on {peer.name}: {rep['error']}")
            continue
        data["from"].append(peer.name)
        unreachable += _unreachable(rep, peer.name)
        unknown += _unreachable(rep, peer.name, None)
        evidence.extend(_node_lines(rep, peer.name))
        checked |= {n["node"] for n in rep.get("nodes", [])}
    # The user's own nodes first: they are what the user recognises.
    unreachable.sort(key=lambda u: (u["node"].startswith(rosproto.PROBE_PREFIX), u["node"]))
    data["unreachable"] = unreachable
    data["checked"] = len(checked)
    evidence.extend(f"could not check from a peer: {p}" for p in problems)
    if unreachable:
        first = unreachable[0]
        mine = " (the probe node of this check, advertised like any node started here)" \
            if first["node"] == me.caller_id else ""
        where = "this component" if first["from"] == "here" else first["from"]
        more = f" (+{len(unreachable) - 1} more)" if len(unreachable) > 1 else ""
        ours = any(u["node"] == me.caller_id for u in unreachable)
        cause = f" Nodes started here take their address from {me.host_from}." if ours else ""
        return Outcome(Status.FAIL,
                       f"node {first['node']}{mine} advertises {first['uri']}, which {where} "
                       f"cannot reach: {first['reason']}{more}. Topics are listed, but no data "
                       f"will flow to or from it.{cause}", evidence, data)
    if unknown:
        first = unknown[0]
        where = "here" if first["from"] == "here" else f"from {first['from']}"
        return Outcome(Status.WARN, f"no node found unreachable, but {len(unknown)} could not be "
                                    f"checked: {first['node']} {where}: {first['reason']}",
                       evidence, data)
    if problems:
        return Outcome(Status.WARN, f"all {len(checked)} node(s) are reachable from here, but "
                                    f"not checked from the peer: {problems[0]}", evidence, data)
    seats = " and ".join(["here"] + [p for p in data["from"] if p != "here"])
    real = len(checked - {me.caller_id})
    probe = ", and a probe node started here," if registered else ""
    return Outcome(Status.PASS, f"all {real} node(s) the master knows{probe} are reachable "
                                f"(checked from {seats})", evidence, data)


# --------------------------------------------------------------------------- pub/sub
def _pubsub_data(peer: str, ok: bool, hop: str | None = None, node: str | None = None,
                 uri: str | None = None) -> dict[str, Any]:
    return {"peer": peer, "ok": ok, "failed_hop": hop, "node": node, "uri": uri}


_HOP_WORDS = {
    "registration": "registering with the master",
    "xmlrpc_callback": "the XML-RPC call (requestTopic) to the publisher's advertised address",
    "tcpros": "the TCPROS connection to the publisher",
    "no_message": "waiting for a message",
}


def _failure_summary(direction: str, sub_where: str, pub_where: str,
                     rep: rosproto.ProbeReport, pub_from: str) -> str:
    hop = rep.failed_hop or "no_message"
    last = next((h.detail for h in reversed(rep.hops) if h.hop == hop and not h.ok), "")
    node = f" {rep.node}" if rep.node else ""
    if hop == "registration":
        return f"{direction}: the subscriber on {sub_where} failed at {_HOP_WORDS[hop]}: {last}"
    if hop in ("xmlrpc_callback", "tcpros"):
        return (f"{direction}: {sub_where} cannot reach the publisher node{node} on {pub_where} "
                f"at {rep.uri} ({_HOP_WORDS[hop]}): {last}. That node's address comes from "
                f"{pub_from}")
    return f"{direction}: {sub_where} connected to the publisher on {pub_where} but {last}"


async def _pubsub_out_one(ctx: CheckContext, peer: Peer, uri: str, end: float,
                          seen: dict[str, Any]) -> tuple[Status, str, list[str], dict[str, Any]]:
    """We publish, *peer* subscribes (over SSH), by *end*; *seen* says how far it got."""
    deadline = end - STOP_S
    budget = deadline - time.monotonic()
    ct = max(0.3, min(2.0, ctx.timeout_s * 0.8))
    topic = f"{rosproto.PROBE_PREFIX}/{rosproto.new_probe_id()}"
    pub = rosproto.ProbePublisher(uri, topic, env=ctx.env, bashrc=str(ctx.paths.bashrc_path),
                                  call_timeout=ct)
    evidence: list[str] = []
    res: SshResult | None = None
    seen.update(node=pub, stage="registering the publisher here with the master")
    try:
        started = await _start_publisher(pub, ct)
        if started:
            seen["stage"] = (f"starting the subscriber on {peer.name} (its probe, over SSH) "
                             "and waiting for its message")
            remote_t = max(1.0, budget * 0.55)
            argv = ["sub", "--master", uri, "--topic", topic, "--timeout", f"{remote_t:.1f}"]
            res = await peer_run(ctx, peer, ROS_AGENT, "ros", argv,
                                 timeout=max(0.5, deadline - time.monotonic()),
                                 tcp_timeout=ctx.timeout_s)
    finally:
        local = await _stop(pub, end)
    evidence.extend(local.evidence("here (publisher)"))
    if local.failed_hop == "registration":
        return (Status.FAIL, f"publishing here failed: {local.hops[-1].detail}", evidence,
                _pubsub_data(peer.name, False, "registration", local.caller_id, uri))
    assert res is not None
    why_not = peer_program_problem(res, peer)
    rdata = _remote_report(res) if why_not is None else None
    if rdata is None:
        why = why_not or (f"the probe on {peer.name} gave no report "
                          f"({why_no_report(res)})")
        return (Status.SKIP, f"skipped: could not run the subscriber on {peer.name}: {why}",
                evidence, _pubsub_data(peer.name, False))
    rep = rosproto.ProbeReport.from_json(rdata)
    evidence.extend(rep.evidence(f"{peer.name} (subscriber)"))
    if rep.ok:
        return (Status.PASS, f"a message published here reached a subscriber on {peer.name} "
                             f"({rep.received!r})", evidence, _pubsub_data(peer.name, True))
    if not rep.node and rep.uri and rosproto.same_uri(rep.uri, local.advertised_uri):
        rep.node = local.caller_id
    node = rep.node
    summary = _failure_summary(f"here -> {peer.name}", peer.name, "this component", rep,
                               pub.host_from)
    return (Status.FAIL, summary, evidence,
            _pubsub_data(peer.name, False, rep.failed_hop or "no_message", node,
                         rep.uri or (uri if rep.failed_hop == "registration" else None)))


async def _pubsub_in_one(ctx: CheckContext, peer: Peer, uri: str, end: float,
                         seen: dict[str, Any]) -> tuple[Status, str, list[str], dict[str, Any]]:
    """*peer* publishes (over SSH), we subscribe, by *end*; *seen* says how far it got."""
    deadline = end - STOP_S
    budget = deadline - time.monotonic()
    topic = f"{rosproto.PROBE_PREFIX}/{rosproto.new_probe_id()}"
    remote_t = max(1.5, budget * 0.7)
    argv = ["pub", "--master", uri, "--topic", topic, "--timeout", f"{remote_t:.1f}"]
    evidence: list[str] = []
    local: rosproto.ProbeReport | None = None
    seen["stage"] = f"starting the publisher on {peer.name} (its probe, over SSH)"
    async with peer_session(ctx, peer, ROS_AGENT, "ros", argv, timeout=max(0.5, budget * 0.4),
                            tcp_timeout=ctx.timeout_s) as s:
        if not s.ok:
            return (Status.SKIP, f"skipped: could not run the publisher on {peer.name}: "
                                 f"SSH failed ({s.result.failure}): {s.result.detail}",
                    evidence, _pubsub_data(peer.name, False))
        ready = await s.read_until(READY_MARK, timeout=max(0.3, budget * 0.4))
        if ready is not None:
            seen["stage"] = (f"the publisher on {peer.name} registered; subscribing here and "
                             "waiting for its message")
            sub_t = max(0.5, deadline - time.monotonic() - 0.8)
            wait_t = max(0.3, min(sub_t + 1.5, end - time.monotonic() - 0.3))
            try:
                local = await run_blocking(_run_sub, uri, topic, sub_t, ctx, timeout=wait_t)
            except asyncio.TimeoutError:  # run_subscriber bounds itself; this is a safety net
                local = rosproto.ProbeReport("sub", topic, uri)
                local.fail("no_message", f"the subscriber here gave no verdict within "
                                         f"{wait_t:.1f} s")
        # A served publisher ends at once; an unserved one would run to its own timeout (it is
        # bounded and unregisters itself), so after a failure we only wait briefly for its report.
        wait_t = deadline - time.monotonic() if local is None or local.ok else 0.5
        res = await s.wait(max(0.1, min(wait_t, end - time.monotonic() - 0.1)))
    why_not = peer_program_problem(res, peer) if res.failure != "timeout" else None
    rdata = _remote_report(res)
    remote = rosproto.ProbeReport.from_json(rdata) if rdata else None
    if remote is not None:
        evidence.extend(remote.evidence(f"{peer.name} (publisher)"))
    if local is None:
        if remote is not None and remote.failed_hop == "registration":
            last = remote.hops[-1].detail if remote.hops else ""
            return (Status.FAIL, f"{peer.name} -> here: the publisher on {peer.name} failed at "
                                 f"registering with the master: {last}", evidence,
                    _pubsub_data(peer.name, False, "registration", remote.caller_id, uri))
        why = why_not or (f"the probe on {peer.name} did not start "
                          f"({why_no_report(res)})")
        return (Status.SKIP, f"skipped: could not run the publisher on {peer.name}: {why}",
                evidence, _pubsub_data(peer.name, False))
    evidence.extend(local.evidence("here (subscriber)"))
    if local.ok:
        return (Status.PASS, f"a message published on {peer.name} reached a subscriber here "
                             f"({local.received!r})", evidence, _pubsub_data(peer.name, True))
    if remote is not None and not local.node and local.uri and \
            rosproto.same_uri(local.uri, remote.advertised_uri):
        local.node = remote.caller_id
    pub_from = (f"{remote.advertised_from} on {peer.name}" if remote is not None
                else f"the settings of {peer.name}")
    summary = _failure_summary(f"{peer.name} -> here", "this component", peer.name, local,
                               pub_from)
    return (Status.FAIL, summary, evidence,
            _pubsub_data(peer.name, False, local.failed_hop or "no_message", local.node,
                         local.uri))


def _ran_out(peer: Peer, direction: str, budget: float, seen: dict[str, Any]
             ) -> tuple[Status, str, list[str], dict[str, Any]]:
    """The verdict of an exchange with *peer* that was still under way when the check's time
    ran out: how far it got (*seen*), and what the probe here saw by then."""
    way = f"here -> {peer.name}" if direction == "out" else f"{peer.name} -> here"
    node = seen.get("node")
    evidence = node.report.evidence("here (publisher)") if node is not None else []
    evidence.append(f"{way}: the check's {budget:g} s ran out while {seen['stage']}")
    return (Status.FAIL, f"{way}: no message within the check's {budget:g} s; it got as far as "
                         f"{seen['stage']} (a slow or busy link: see the evidence)",
            evidence, _pubsub_data(peer.name, False, "no_message"))


def _run_sub(uri: str, topic: str, timeout: float, ctx: CheckContext) -> rosproto.ProbeReport:
    ct = max(0.3, min(2.0, ctx.timeout_s * 0.8))
    return rosproto.run_subscriber(uri, topic, timeout, env=ctx.env, bashrc=str(ctx.paths.bashrc_path),
                                   call_timeout=ct)


async def _pubsub(ctx: CheckContext, direction: str) -> Outcome:
    uri, why = master_uri(ctx)
    if uri is None:
        return Outcome(Status.SKIP, f"skipped: {why}", [], _pubsub_data("", False))
    peers = ros1_peers(ctx.settings)
    if not peers:
        return Outcome(Status.SKIP, "skipped: no peer with an SSH user in the settings, so the "
                                    "other side of the exchange cannot be run from here",
                       [], _pubsub_data("", False))
    budget = _budget(ctx, FACTOR_PUBSUB)
    end = time.monotonic() + budget - OWN_END_S
    one = _pubsub_out_one if direction == "out" else _pubsub_in_one

    async def bounded(p: Peer) -> tuple[Status, str, list[str], dict[str, Any]]:
        seen: dict[str, Any] = {"stage": "starting", "node": None}
        try:
            return await asyncio.wait_for(one(ctx, p, uri, end, seen),
                                          max(0.05, end - time.monotonic()))
        except asyncio.TimeoutError:
            return _ran_out(p, direction, budget, seen)

    outcomes = await each_peer(peers, bounded)
    rank = {Status.FAIL: 0, Status.SKIP: 1, Status.WARN: 2, Status.PASS: 3}
    worst = min(range(len(peers)), key=lambda i: rank[outcomes[i][0]])
    status, summary, _, data = outcomes[worst]
    evidence: list[str] = []
    for _, _, ev, _ in outcomes:
        evidence.extend(ev)
    data = dict(data)
    data["peers"] = {p.name: o[3] for p, o in zip(peers, outcomes, strict=True)}
    if len(peers) > 1:
        passed = sum(1 for o in outcomes if o[0] == Status.PASS)
        summary += f" ({passed} of {len(peers)} peers passed)"
    return Outcome(status, summary, evidence, data)


@check("ros.pubsub_out", "ros", "A message published here reaches the peer", FACTOR_PUBSUB,
       ros=1)
async def check_pubsub_out(ctx: CheckContext) -> Outcome:
    return await _pubsub(ctx, "out")


@check("ros.pubsub_in", "ros", "A message published on the peer reaches us", FACTOR_PUBSUB,
       ros=1)
async def check_pubsub_in(ctx: CheckContext) -> Outcome:
    return await _pubsub(ctx, "in")
