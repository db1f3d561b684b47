"""Step 4 for ROS 2 over rmw_zenoh: the environment (ros2.env) and the master's router
(ros2.router). The graph and live publish/subscribe are in :mod:`.ros2_graph`.

Every probe is a real Zenoh session (eclipse-zenoh) that behaves as an rmw_zenoh node does on the
wire (:mod:`rosnet_tui.core.peer.zenohproto`). Questions to a peer run the same module over SSH, on
the interpreter of the rosnet-tui installed there, by the round's peer agent (probes.agents.ZENOH_AGENT).
"""

from __future__ import annotations

import asyncio
import time
from pathlib import Path
from typing import Any

from rosnet_tui.core.addresses import is_loopback
from rosnet_tui.core.checks import CheckContext, check
from rosnet_tui.core.checks.probes.agents import ZENOH_AGENT, peer_run
from rosnet_tui.core.checks.probes.budget import budget
from rosnet_tui.core.checks.probes.listening import services_listening
from rosnet_tui.core.checks.probes.peers import each_peer
from rosnet_tui.core.checks.probes.ros2 import (
    close_zenoh,
    dial_router,
    node_endpoint,
    open_zenoh,
    ros2_peers,
    router_links,
    zenoh_env,
    zenoh_peer_problem,
)
from rosnet_tui.core.config.paths import default_config_dir
from rosnet_tui.core.config.settings_model import Peer, Settings
from rosnet_tui.core.files.managed_text import ManagedFileError
from rosnet_tui.core.files.managed_write import read_text
from rosnet_tui.core.net.blocking import run_blocking
from rosnet_tui.core.peer import zenohproto
from rosnet_tui.core.printable import printable
from rosnet_tui.core.results import Outcome, Status
from rosnet_tui.core.ros import fleet_tls, ros2, tls_handshake
from rosnet_tui.core.ssh.connection import resolve_ipv4

FACTOR_ROUTER = 1.0
DDS_VARS = ("CYCLONEDDS_URI", "FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE",
            "ROS_STATIC_PEERS", "RMW_CONNEXT_INITIAL_PEERS")


# --------------------------------------------------------------------------- ros2.env
def _read_router_config(path: str) -> tuple[dict | None, str | None]:
    p = Path(path.removeprefix("file://"))
    try:
        # rosnet-tui writes this file (ros apply): through the managed-file reader, which
        # completes a write of ours cut short and refuses a FIFO or a device.
        text = read_text(p, errors="replace", wait_s=1.0)
    except ManagedFileError as exc:
        return None, str(exc)
    if text is None:
        return None, f"cannot read {p}: No such file or directory"
    text = text[:256 * 1024]
    try:
        data = ros2.loads_json5(text)
    except ValueError as exc:
        return None, f"{p} is not valid JSON5: {exc}"
    return (data, None) if isinstance(data, dict) else (None, f"{p} is not a JSON5 object")


async def _peer_infos(ctx: CheckContext, t: float) -> dict[str, dict | str]:
    peers = ros2_peers(ctx)
    got = await each_peer(peers, lambda p: peer_run(ctx, p, ZENOH_AGENT, "zenoh", ["info"],
                                                    timeout=t))
    out: dict[str, dict | str] = {}
    for p, res in zip(peers, got, strict=True):
        rep = zenohproto.parse_report(res.stdout)
        out[p.name] = rep if rep is not None else (zenoh_peer_problem(res, p, None) or "no report")
    return out


@check("ros2.env", "ros", "RMW_IMPLEMENTATION, ROS_DOMAIN_ID, ROS_DISTRO and Zenoh config", 1.0,
       ros=2)
async def check_env(ctx: CheckContext) -> Outcome:
    s = ctx.settings
    env = zenoh_env(ctx)
    rc = zenohproto.read_exports(str(ctx.paths.bashrc_path))
    infos_task = asyncio.ensure_future(_peer_infos(ctx, max(0.5, budget(ctx, "ros2.env") * 0.8)))
    fails: list[str] = []
    warns: list[str] = []
    ev: list[str] = []
    codes: list[str] = []
    rmw, rc_rmw = ctx.env.get("RMW_IMPLEMENTATION"), rc.get("RMW_IMPLEMENTATION")
    ev.append(f"RMW_IMPLEMENTATION: environment {rmw or 'not set'}, {ctx.paths.bashrc_path} "
              f"{rc_rmw or 'not set'}")
    used = rmw or rc_rmw
    dds = used != ros2.RMW_ZENOH
    if not used:
        fails.append("RMW_IMPLEMENTATION is not set, so ROS 2 uses DDS, whose discovery and data "
                     "do not cross the modems; export RMW_IMPLEMENTATION=rmw_zenoh_cpp")
    elif used != ros2.RMW_ZENOH:
        fails.append(f"RMW_IMPLEMENTATION={used} (DDS): its discovery and data do not cross the "
                     "modems; use rmw_zenoh_cpp")
    elif rmw != rc_rmw:
        where = f"not in {ctx.paths.bashrc_path}" if not rc_rmw else "not in this shell"
        warns.append(f"RMW_IMPLEMENTATION=rmw_zenoh_cpp is {where}: new shells (or this one) "
                     "will differ; `rosnet-tui ros apply` writes it, `source ~/.bashrc` loads it")
    dom = env.get("ROS_DOMAIN_ID")
    domain_ok = (dom or "0").strip() == str(s.ros.domain_id)
    ev.append(f"ROS_DOMAIN_ID={dom if dom is not None else 'not set (0)'}; the settings say "
              f"{s.ros.domain_id}")
    if not domain_ok:
        fails.append(f"ROS_DOMAIN_ID is {dom or '0 (not set)'}, the settings say "
                     f"{s.ros.domain_id}: nodes in different domains never see each other")
    distro = env.get("ROS_DISTRO")
    ev.append(f"ROS_DISTRO={distro or 'not set'}")
    client = False
    override = env.get("ZENOH_CONFIG_OVERRIDE")
    problems: list[str] = []
    if override:
        values, bad = ros2.parse_override(override)
        ev.append(f"ZENOH_CONFIG_OVERRIDE={override}")
        problems += [f"ZENOH_CONFIG_OVERRIDE: {b}" for b in bad]
        client = values.get("mode") in ("client", "peer") and bool(values.get("connect/endpoints"))
        problems += ros2.override_problems(s, values)
        if client and (distro or "").lower() in ros2.DISTROS_WITHOUT_OVERRIDE:
            warns.append("on Humble, ZENOH_CONFIG_OVERRIDE works only from rmw_zenoh 0.1.2: "
                         "use ZENOH_SESSION_CONFIG_URI with a config file if nodes ignore it")
    rc_path = env.get("ZENOH_ROUTER_CONFIG_URI")
    listen: list[str] = []
    connect: list[str] = []
    if rc_path:
        cfg, why = _read_router_config(rc_path)
        if cfg is None:
            problems.append(f"ZENOH_ROUTER_CONFIG_URI: {why}")
        else:
            listen = ros2.endpoints_of(ros2.config_value(cfg, "listen/endpoints"), "router")
            connect = ros2.endpoints_of(ros2.config_value(cfg, "connect/endpoints"), "router")
            ev.append(f"router config {rc_path}: listen {listen or 'default'}, connect "
                      f"{connect or 'nothing'}")
    elif not client:
        listen = list(ros2.UPSTREAM_LISTEN)
        ev.append("ZENOH_ROUTER_CONFIG_URI not set: rmw_zenohd uses its defaults (listen "
                  "tcp/[::]:7447, connect nothing)")
    if not client:
        problems += ros2.router_config_problems(s, listen, connect, ros2.ipv6_available())
    for name, code, why in (("ROS_LOCALHOST_ONLY", "localhost_only", "keeps nodes on this machine"),
                            ("ROS_AUTOMATIC_DISCOVERY_RANGE", "discovery_localhost",
                             "limits discovery to this machine")):
        value = ctx.env.get(name) or rc.get(name)
        if value and value.upper() in ("1", "LOCALHOST", "TRUE"):
            codes.append(code)
            warns.append(f"{name}={value} {why}; remove it")
    leftovers = [v for v in DDS_VARS if ctx.env.get(v) or rc.get(v)]
    if leftovers:
        codes.append("dds_settings")
        warns.append(f"DDS settings ({', '.join(leftovers)}) do nothing under rmw_zenoh; remove "
                     "them to avoid confusion")
    infos = await infos_task
    peer_distros: dict[str, str | None] = {}
    mismatch: list[str] = []
    for name, info in infos.items():
        if isinstance(info, str):
            peer_distros[name] = None
            ev.append(f"{name}: not asked ({info})")
            continue
        pd = (info.get("env") or {}).get("ROS_DISTRO")
        peer_distros[name] = pd
        ev.append(f"{name}: ROS_DISTRO={pd or 'not set'}, RMW_IMPLEMENTATION="
                  f"{(info.get('env') or {}).get('RMW_IMPLEMENTATION') or 'not set'}")
        if pd and distro and pd.lower() != distro.lower():
            mismatch.append(name)
    if mismatch:
        pairs = ", ".join(f"{n} runs {peer_distros[n]}" for n in mismatch)
        fails.append(f"ROS_DISTRO differs: here {distro}, {pairs}. Mixed distros (Humble next to "
                     "Jazzy or later) discover each other but drop every message")
    if not distro:
        warns.append("ROS_DISTRO is not set: no ROS 2 is sourced here (source "
                     "/opt/ros/<distro>/setup.bash in ~/.bashrc)")
    fails += problems
    data = {"rmw": rmw, "bashrc_rmw": rc_rmw, "rmw_ok": rmw == rc_rmw == ros2.RMW_ZENOH,
            "dds": dds, "domain_id": dom, "expected_domain_id": s.ros.domain_id,
            "domain_ok": domain_ok, "distro": distro, "peer_distros": peer_distros,
            "distro_mismatch": mismatch, "client_mode": client, "override": override,
            "router_config": rc_path, "router_listen": listen, "router_connect": connect,
            "config_problems": problems, "warnings": codes}
    if fails:
        return Outcome(Status.FAIL, "; ".join(fails), ev + [f"warning: {w}" for w in warns], data)
    if warns:
        return Outcome(Status.WARN, "; ".join(warns), ev, data)
    mode = "client mode to the master's router" if client else "a router on this component"
    return Outcome(Status.PASS, f"rmw_zenoh_cpp, domain {s.ros.domain_id}, {distro}, {mode}",
                   ev, data)


# --------------------------------------------------------------------------- ros2.router
def _remote_peers(info: dict, local: set[str]) -> list[str]:
    """Addresses of other machines with sessions attached in peer mode ("N from ADDRESS")."""
    count: dict[str, int] = {}
    for x in info.get("sessions") or []:
        if x.get("whatami") != "peer":
            continue
        hosts = [ln.split("/", 1)[-1].rsplit(":", 1)[0].strip("[]") for ln in x.get("links") or []]
        for h in hosts:
            if h and not is_loopback(h) and h not in local:
                count[h] = count.get(h, 0) + 1
                break
    return [f"{n} from {h}" for h, n in count.items()]


def zenoh_release(version: str | None) -> str | None:
    """The release part of a router's version ("v1.8.0" of "v1.8.0-3f2a..."; None: unknown)."""
    return version.split("-", 1)[0] if version else None


def linked_members(info: dict, s: Settings) -> list[dict[str, Any]]:
    """The member routers the master's router (its admin space *info*, read with *others*) has
    sessions with right now: id, name (what its config's metadata says, else the peer whose
    public IP it came from; None: neither), Zenoh version (None: not told), and the address
    and port it came from as the master's router sees it (the member modem's public side)."""
    known = {z.lstrip("0"): v for z, v in (info.get("routers") or {}).items()}
    by_ip = {p.public_ip: p.name for p in s.peers if p.public_ip}
    out = []
    for x in info.get("sessions") or []:
        if x.get("whatami") != "router":
            continue
        zid = str(x.get("zid", ""))
        seen = known.get(zid.lstrip("0")) or {}
        link = next((ln for ln in x.get("links") or [] if ln), "")
        address = printable(link.split("/", 1)[-1], 80) or None
        host = (address or "").rsplit(":", 1)[0].strip("[]")
        meta = seen.get("metadata") or {}
        name = printable(meta.get("name"), 64) if isinstance(meta.get("name"), str) else ""
        out.append({"zid": printable(zid, 40), "name": name or by_ip.get(host),
                    "version": printable(seen["version"], 80) if seen.get("version") else None,
                    "address": address})
    return out


def member_label(m: dict[str, Any]) -> str:
    """A linked member router in words: its name, else its id and where it came from."""
    return m.get("name") or f"router {str(m.get('zid'))[:8]} from {m.get('address') or '?'}"


def version_skew(members: list[dict[str, Any]], version: str | None) -> list[str]:
    """Labels of the *members* whose router runs another Zenoh release than *version* (the
    master's); an unknown version on either side is no skew."""
    mine = zenoh_release(version)
    return [member_label(m) for m in members
            if mine and zenoh_release(m.get("version")) not in (None, mine)]


@check("ros2.router", "ros", "The master's Zenoh router answers by name", FACTOR_ROUTER, ros=2)
async def check_router(ctx: CheckContext) -> Outcome:
    s = ctx.settings
    t = budget(ctx, "ros2.router")
    deadline = time.monotonic() + t - 0.1
    # Under a relay the path checked is this component's router to the relay's (the master's
    # router dials it too); else the master's router, the hub listening for the members.
    hub_here = s.is_master and not s.relayed
    hub = "the relay" if s.relayed else "the master"
    name, port = ((s.relay.host, s.relay.zenoh_port) if s.relayed
                  else (s.master_name, s.ros.zenoh_port))
    endpoint = ros2.hub_endpoint(s)
    role = "master" if s.is_master else "member"
    ipv6 = ros2.ipv6_available()
    data: dict[str, Any] = {"role": role, "endpoint": endpoint, "reachable": False,
                            "address": None, "failure": None, "ipv6": ipv6, "remote_peers": [],
                            "security": str(s.ros.security)}
    tls_paths = fleet_tls.tls_paths(default_config_dir())
    if ros2.mtls(s):   # in a thread: reading the certificates (cryptography's first import in
        # the round) would hold up every check the round has yet to start
        data["tls"] = await run_blocking(tls_handshake.local_state, s, tls_paths,
                                         timeout=max(t, 1.0))
    if not name:
        return Outcome(Status.SKIP, "skipped: no master is named in the settings (ros.master)",
                       [], data)
    ev: list[str] = []
    node_ep, how = node_endpoint(ctx)
    local_task = None
    if not hub_here and how == "router":
        local_task = asyncio.ensure_future(open_zenoh(node_ep, max(0.2, t * 0.3)))
    if hub_here:
        data["listening"] = lst = await run_blocking(
            lambda: services_listening(port, ctx.listeners), timeout=1.0)
        if not lst and ctx.listeners.rosnet_listens(port):  # router.port_open's stand-in
            ev.append(f"TCP {port} is held by rosnet-tui's own test listener (no router there)")
        else:
            ev.append(f"TCP {port} listened on here: {', '.join(lst) or 'nothing'}")
        # Known before the name is looked up: a name missing from /etc/hosts must not hide it.
        problem = None
        if not lst:
            problem = "not_running"
            cfg_listen = [e for e in _router_config_listen(ctx) if ros2.listen_problem(e, ipv6)
                          == "ipv6_only"]
            if cfg_listen and not ipv6:
                problem = "ipv6_only"
        elif all(is_loopback(a) for a in lst):
            problem = "loopback"
        data["listen_problem"] = problem
    addrs, err = await resolve_ipv4(name, min(1.0, t * 0.25))
    if not addrs:
        data["failure"] = "resolve"
        also = ""
        if local_task is not None:   # this machine's own router is asked all the same
            data["local_router"] = await _local_router(local_task, node_ep, ev, deadline)
            if not data["local_router"]["reachable"]:
                also = f"; this machine's own router does not answer at {node_ep} either"
        elif hub_here and data["listen_problem"] == "not_running":
            also = f"; nothing listens on TCP {port} here either (is rmw_zenohd running?)"
        return Outcome(Status.FAIL, f"{hub}'s name {name} does not resolve here ({err}): add "
                                    f"it to /etc/hosts (Linux step){also}", ev, data)
    data["address"] = addrs[0]
    ev.append(f"{name} resolves to {addrs[0]}")
    dialled: dict[str, Any] = {}
    kind, words, info = await dial_router(addrs[0], port, endpoint, t, deadline, ev,
                                          others=hub_here, facts=dialled)
    stalled = "slow_tcp_s" in dialled       # TCP connected, slowly: a slow or busy link
    data["failure"] = kind
    local: dict[str, Any] = {}
    if local_task is not None:
        data["local_router"] = local = await _local_router(local_task, node_ep, ev, deadline)
    if info:
        data.update(reachable=True, router_zid=info.get("zid"), router_version=info.get("version"),
                    locators=info.get("locators") or [])
        mine = ({s.this.local_ip} if s.is_master else
                {(s.peer(name) or Peer(name)).local_ip}) if not s.relayed else set()
        data["remote_peers"] = _remote_peers(info, {m for m in mine if m})
        ev.append(f"Zenoh router {info.get('zid')} answers at {endpoint}"
                  + (f", version {info['version']}" if info.get("version") else
                     " (admin space off: no version)")
                  + (f", listening on {', '.join(info.get('locators') or [])}"
                     if info.get("locators") else ""))
        if hub_here and info.get("version"):
            _members_evidence(s, info, data, ev)
    elif kind is None:
        data.update(reachable=True, router_zid=None)
    if not data["reachable"]:
        where = "here" if hub_here else f"on {name}"
        hint = {"refused": (f"is `rosnet-tui relay serve` running on {name}?" if s.relayed
                            else f"is rmw_zenohd running {where}?"),
                "timeout": (f"is TCP {port} open on the relay {name}?" if s.relayed
                            else f"is TCP {port} forwarded to {name} on its modem?"),
                "unreachable": "no route to that address",
                "not_zenoh": "something else answers on that port"}.get(kind or "", "")
        if kind == "not_zenoh" and ros2.mtls(s):   # TCP answered: name what TLS refused
            left = deadline - time.monotonic()
            began, wait = time.monotonic(), max(0.05, min(1.0, left - 0.1))
            try:
                problem, hint = await run_blocking(
                    tls_handshake.handshake, addrs[0], port, name, tls_paths, wait,
                    "relay" if s.relayed else "master", timeout=max(0.05, min(1.2, left)))
                # no refusal, only its own time running out: the handshake stalled too
                stalled |= problem == "unreachable" and time.monotonic() - began >= wait * 0.9
            except asyncio.TimeoutError:    # the check's time is up: said as not known
                problem, hint = None, "no answer in the time left (a slow or busy link?)"
                stalled = True
            data["tls"]["handshake"] = problem
            ev.append(f"TLS handshake with {name} ({addrs[0]}:{port}): {hint}")
        if kind == "not_zenoh" and stalled:
            return Outcome(Status.FAIL, f"no session with the Zenoh router at {endpoint} "
                                        f"({addrs[0]}) in the check's {t:g} s: TCP connects, but "
                                        "the TLS handshake did not finish either: a slow or busy "
                                        "link (see ros2.link) or a router that stalls; check "
                                        "again when the link is quieter, or raise [checks] "
                                        "timeout_s", ev, data)
        if hub_here and data.get("listen_problem") == "ipv6_only":
            hint = (f"the router's config listens on tcp/[::]:{port} and this host has no IPv6, "
                    f"so rmw_zenohd cannot start: listen on tcp/0.0.0.0:{port}")
        return Outcome(Status.FAIL, f"no Zenoh router at {endpoint} ({addrs[0]}): {words}"
                                    + (f"; {hint}" if hint else ""), ev, data)
    if hub_here and data.get("listen_problem") == "loopback":
        return Outcome(Status.FAIL, f"the router listens on loopback only ({', '.join(data['listening'])}"
                                    f"): the modem's forward of TCP {port} cannot reach it; "
                                    f"listen on tcp/0.0.0.0:{port}", ev, data)
    if local_task is not None and not local["reachable"]:
        return Outcome(Status.FAIL, f"{hub}'s router answers at {endpoint}, but this "
                                    f"machine's own router does not ({local['failure']}): start "
                                    "it (ros2 run rmw_zenoh_cpp rmw_zenohd), or run the nodes "
                                    "here in client mode", ev, data)
    if local_task is not None and data.get("router_zid") and \
            data["router_zid"] not in local["routers"]:
        return Outcome(Status.FAIL, f"this machine's router is not linked to {hub}'s router "
                                    f"({data['router_zid']}): its config must connect to "
                                    f"{endpoint} (ZENOH_ROUTER_CONFIG_URI; `rosnet-tui ros apply`)",
                       ev, data)
    if data.get("version_skew"):
        return Outcome(Status.WARN, f"member router(s) on another Zenoh version than this "
                                    f"router's {zenoh_release(data['router_version'])}: "
                                    f"{', '.join(_skew_words(data))}; mixed versions can drop "
                                    "data without a word: install the same rmw_zenoh version "
                                    "(the same distro's release) everywhere", ev, data)
    if data["remote_peers"]:
        return Outcome(Status.WARN, f"{hub}'s router has node(s) attached in peer mode from "
                                    f"another machine ({', '.join(data['remote_peers'])}): they "
                                    "see the graph but get no data; run them in client mode, "
                                    "or give their machine a router", ev, data)
    ver = f" ({data['router_version']})" if data.get("router_version") else ""
    if (data.get("tls") or {}).get("problem") == "expiring":
        return Outcome(Status.WARN, f"{hub}'s Zenoh router{ver} answers at {endpoint}, but "
                                    f"{tls_handshake.PROBLEM_WORDS['expiring']} (it expires "
                                    f"{data['tls']['not_after'][:10]})", ev, data)
    how_far = " (the relay carries the link)" if s.relayed else ""
    return Outcome(Status.PASS, f"{hub}'s Zenoh router{ver} answers at {endpoint} "
                                f"({addrs[0]}){how_far}", ev, data)


def _members_evidence(s: Settings, info: dict, data: dict[str, Any], ev: list[str]) -> None:
    """The master: which member routers are linked now (``member_routers``) and which run
    another Zenoh release (``version_skew``), from its router's admin space."""
    data["member_routers"] = members = linked_members(info, s)
    data["version_skew"] = version_skew(members, info.get("version"))
    ev.append(f"member routers linked now: {len(members)}" + "".join(
        f"; {member_label(m)}" + (f" ({m['address']})" if m.get("name") else "")
        + f", Zenoh {zenoh_release(m.get('version')) or 'version not told'}" for m in members))
    named = {m.get("name") for m in members}
    absent = [p.name for p in s.peers if p.name != s.this.name and p.name not in named]
    if absent and all(named):
        ev.append(f"not linked now: {', '.join(absent)}")


def _skew_words(data: dict[str, Any]) -> list[str]:
    by_label = {member_label(m): m for m in data.get("member_routers") or []}
    return [f"{n} runs {zenoh_release(by_label[n].get('version'))}" for n in data["version_skew"]]


async def _local_router(task: asyncio.Future, endpoint: str, ev: list[str], deadline: float
                        ) -> dict[str, Any]:
    """What the session *task* opened to this machine's own router found by *deadline*
    (ros2.router's ``local_router``); the session is closed."""
    local: dict[str, Any] = {"reachable": False, "endpoint": endpoint, "zid": None,
                             "version": None, "routers": [], "failure": None}
    try:
        ls, lwhy = await asyncio.wait_for(asyncio.shield(task),
                                          max(0.05, deadline - time.monotonic()))
    except asyncio.TimeoutError:
        ls, lwhy = None, "no session in the check's time"
        task.add_done_callback(lambda t: t.cancelled() or asyncio.ensure_future(
            close_zenoh(t.result()[0])))     # a late session is closed all the same
    if ls is None:
        local["failure"] = lwhy
        ev.append(f"this machine's router at {endpoint}: {lwhy}")
        return local
    left = deadline - time.monotonic()
    try:
        li = await run_blocking(zenohproto.router_info, ls, max(0.05, min(0.5, left - 0.1)),
                                timeout=max(0.05, min(1.0, left)))
    except asyncio.TimeoutError:
        li = {}
        ev.append(f"this machine's router at {endpoint}: its admin space gave no answer in "
                  "the check's time")
    finally:
        await close_zenoh(ls, min(1.0, deadline - time.monotonic()))
    local.update(reachable=True, zid=li.get("zid"), version=li.get("version"),
                 routers=router_links(li))
    ev.append(f"this machine's router at {endpoint}: {li.get('zid')} "
              f"{li.get('version') or ''}, linked to router(s) {local['routers'] or 'none'}")
    return local


def _router_config_listen(ctx: CheckContext) -> list[str]:
    path = zenoh_env(ctx).get("ZENOH_ROUTER_CONFIG_URI")
    if not path:
        return list(ros2.UPSTREAM_LISTEN)
    cfg, _ = _read_router_config(path)
    return ros2.endpoints_of(ros2.config_value(cfg or {}, "listen/endpoints"), "router")
