"""Step 2, Router/modem: local address, the test port, our listener, and forwarding from outside.

``router.port_open`` is the procedure's "start ``nc -l PORT``, ask a port checker" loop: our own
listener (:mod:`rosnet_tui.core.net.listener`) answers on each port we probe, and the outside view
comes from the peer over SSH (it connects to our public IP and must read our listener's greeting,
so a port forwarded to the wrong machine is caught) or from the echoip service in the settings.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import socket
from collections.abc import Callable
from typing import Any, Literal

import psutil

from rosnet_tui.core.checks import CheckContext, check
from rosnet_tui.core.checks.probes.agents import chat_agent, peer_run
from rosnet_tui.core.checks.probes.budget import budget
from rosnet_tui.core.checks.probes.listening import services_listening, who_listens
from rosnet_tui.core.checks.probes.peers import ssh_peers
from rosnet_tui.core.checks.probes.public_ip import fetch_public_ip, round_public_ip
from rosnet_tui.core.checks.probes.relay_port import relay_port_open
from rosnet_tui.core.config.settings_model import Peer
from rosnet_tui.core.jsonsafe import loads_bounded
from rosnet_tui.core.net.blocking import run_blocking
from rosnet_tui.core.net.connect import close_writer, kind_from_text
from rosnet_tui.core.net.http import http_get
from rosnet_tui.core.net.listener import GREETING, PortHeld, PortListener, SharedListener
from rosnet_tui.core.net.netinfo import (
    LinkState,
    LocalNet,
    detect_local_net,
    interface_ipv4,
    link_state,
)
from rosnet_tui.core.results import Outcome, Status
from rosnet_tui.core.saved.state import record_local_ip


# --------------------------------------------------------------------------- router.local_ip
@check("router.local_ip", "router", "Local IP is the one the modem forwards to", 1.0)
async def check_local_ip(ctx: CheckContext) -> Outcome:
    t = ctx.settings.this
    expected = t.local_ip

    def look() -> tuple[LocalNet, str, LinkState | None]:
        net = detect_local_net()
        interface = t.interface or net.interface
        return net, interface, link_state(interface) if interface else None

    net, interface, link = await run_blocking(look, timeout=budget(ctx, "router.local_ip") * 0.8)
    evidence = [f"default route: {net.gateway or 'none'}"
                + (f" via {net.interface}" if net.interface else "")]
    local_ip, mask = interface_ipv4(interface) if interface else ("", "")
    up = link is not None and link.up
    if link is not None:
        evidence.append(f"{interface}{' (from the settings)' if t.interface else ''}: "
                        f"{link.word}, {local_ip or 'no IPv4 address'}"
                        + (f"/{mask}" if mask else ""))
    gateway = net.gateway if (not net.interface or net.interface == interface) else ""
    addrs_here = {a.address for addrs in psutil.net_if_addrs().values() for a in addrs
                  if a.family == socket.AF_INET}
    differs = bool(expected) and expected != local_ip
    data: dict[str, Any] = {"local_ip": local_ip if up else "", "interface": interface,
                            "gateway": gateway, "expected_ip": expected, "differs": differs}
    if up and local_ip:
        try:
            rec = record_local_ip(ctx.paths.state_dir, local_ip)
            data.update(previous_ip=rec.previous_ip, changed=rec.changed, history=rec.history)
            if rec.changed:
                evidence.append(f"the local IP was {rec.previous_ip} on the last run: a modem "
                                f"that forwards to {rec.previous_ip} no longer reaches this machine")
        except OSError as exc:   # an unwritable state folder must not hide the address
            evidence.append(f"could not record the local IP in {ctx.paths.state_dir}: "
                            f"{exc.strerror or exc}")
    if not interface:
        return Outcome(Status.FAIL, "no network interface with an IPv4 address: this machine is not "
                                    "on a network", evidence, data)
    if link is None or not link.exists:
        return Outcome(Status.FAIL, f"the interface {interface} from the settings does not exist "
                                    "here", evidence, data)
    if not up:
        return Outcome(Status.FAIL, f"{interface} is down ({link.why})", evidence, data)
    if not local_ip:
        return Outcome(Status.FAIL, f"{interface} has no IPv4 address (no DHCP lease?)",
                       evidence, data)
    if data.get("changed") and not differs:
        return Outcome(Status.WARN, f"local IP is {local_ip} on {interface}, but it was "
                                    f"{data['previous_ip']} on the last run (a new DHCP lease): "
                                    "forwarding set up for the old address points nowhere; "
                                    "reserve the address in the modem or update the forwarding",
                       evidence, data)
    if differs:
        also = " (it is on another interface here)" if expected in addrs_here else ""
        return Outcome(Status.WARN, f"local IP is {local_ip} on {interface}, but the modem forwards to "
                                    f"{expected}{also}: after a DHCP change the forwarding points "
                                    "nowhere; reserve the address in the modem or update the "
                                    "forwarding", evidence, data)
    if not gateway:
        return Outcome(Status.WARN, f"{local_ip} on {interface}, but no default gateway through it: "
                                    "no way out to the internet", evidence, data)
    return Outcome(Status.PASS, f"{local_ip} on {interface}, gateway {gateway}", evidence, data)


# --------------------------------------------------------------------------- router.port_free
@check("router.port_free", "router", "The test port is free for our listener", 1.0)
async def check_port_free(ctx: CheckContext) -> Outcome:
    port = ctx.settings.probe.port
    data: dict[str, Any] = {"port": port, "in_use": False, "process": None, "pid": None}
    if (held := ctx.listeners.get(port)) is not None:
        return Outcome(Status.PASS, f"port {port} is free (our own listener has it for this round)",
                       [held.note or f"TCP {port}: held by rosnet-tui (pid {os.getpid()})"], data)
    try:
        async with ctx.listeners.hold(port, wait_s=budget(ctx, "router.port_free") * 0.4) as lst:
            pass
    except PortHeld as exc:     # not a failure of the port: say so, and when to look again
        data.update(in_use=True, pid=exc.pid, process="rosnet-tui (another check run)")
        return Outcome(Status.WARN, f"port {port} is held by another check run of rosnet-tui: "
                                    "run the checks again once it ends", [exc.strerror], data)
    except OSError as exc:
        pid, name, _found = await run_blocking(who_listens, port, timeout=budget(ctx, "router.port_free") * 0.45)
        data.update(in_use=True, pid=pid, process=name)
        who = (f"{name} (pid {pid})" if pid else
               "a process of another user (run as root to see which)")
        return Outcome(Status.FAIL, f"port {port} is in use by {who}: stop it or choose another test "
                                    "port above 1024", [f"bind 0.0.0.0:{port}: {exc.strerror or exc}",
                                                        f"listening there: {who}"], data)
    if isinstance(lst, SharedListener):     # another check run of rosnet-tui listens there
        return Outcome(Status.PASS, f"port {port} is free for rosnet-tui", [lst.note], data)
    return Outcome(Status.PASS, f"port {port} is free", [f"bind 0.0.0.0:{port}: ok (released)"]
                   + [lst.note] * bool(lst.note), data)


# --------------------------------------------------------------------------- router.listener
async def _talk_to(ip: str, port: int, timeout: float) -> tuple[bool, str]:
    """Connect to our own listener and read its greeting; (ok, what was seen)."""
    writer = None
    try:
        reader, writer = await asyncio.wait_for(asyncio.open_connection(ip, port), timeout)
        line = await asyncio.wait_for(reader.readline(), timeout)
        text = line.decode(errors="replace").strip()
        return text.startswith(GREETING), text
    except (OSError, asyncio.TimeoutError) as exc:
        return False, str(exc) or type(exc).__name__
    finally:
        if writer is not None:
            await close_writer(writer)


@check("router.listener", "router", "Our listener is up on the test port", 1.0)
async def check_listener(ctx: CheckContext) -> Outcome:
    port = ctx.settings.probe.port
    t = budget(ctx, "router.listener") * 0.4
    data = {"port": port, "listening": False}
    try:
        async with ctx.listeners.hold(port, wait_s=t * 0.4) as lst:
            evidence = [f"listening on 0.0.0.0:{port} (like nc -l {port})"] + [lst.note] * bool(lst.note)
            targets = ["127.0.0.1"]
            local = await run_blocking(_address_here, ctx.settings.this.interface,
                                       ctx.settings.this.local_ip, timeout=t)
            stale = ctx.settings.this.local_ip
            if stale and stale != local:
                evidence.append(f"the settings' local IP {stale} is not an address of this "
                                "machine now (see router.local_ip): not tested")
            if local and local != "127.0.0.1":
                targets.append(local)
            results = await asyncio.gather(*(_talk_to(ip, port, t) for ip in targets))
            for ip, (ok, seen) in zip(targets, results, strict=True):
                evidence.append(f"connect {ip}:{port} -> {seen!r}" if ok else
                                f"connect {ip}:{port} -> {seen}")
            if all(ok for ok, _ in results):
                data["listening"] = True
                return Outcome(Status.PASS, f"our listener answers on port {port} "
                                            f"({', '.join(targets)})", evidence, data)
            data["listening"] = lst.listening and results[0][0]
            bad = [ip for ip, (ok, _) in zip(targets, results, strict=True) if not ok]
            return Outcome(Status.FAIL, f"our listener on port {port} does not answer on "
                                        f"{', '.join(bad)} (a local firewall?)", evidence, data)
    except OSError as exc:
        return Outcome(Status.FAIL, f"cannot listen on port {port}: {exc.strerror or exc} "
                                    "(see router.port_free)",
                       [f"bind 0.0.0.0:{port}: {exc.strerror or exc}"], data)


# --------------------------------------------------------------------------- router.port_open
PROBE_SCRIPT = r"""
import json, socket, sys, threading
ip = sys.argv[1]; t = float(sys.argv[2]); ports = []; how = {}
optional = set()
for x in sys.argv[3].split(","):
    p, _, h = x.partition("=")
    if h.endswith("?"):
        optional.add(int(p)); h = h[:-1]
    ports.append(int(p)); how[int(p)] = h or "line"
XMLRPC = ('<?xml version="1.0"?><methodCall><methodName>getPid</methodName><params><param>'
          '<value><string>/rosnet_tui_port_probe</string></value></param></params></methodCall>')
res = {}
def probe(p):
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.settimeout(t)
    try:
        s.connect((ip, p))
    except socket.timeout:
        res[p] = ["timeout", ""]; s.close(); return
    except Exception as e:
        res[p] = ["error", str(e)]; s.close(); return
    b = b""
    try:
        if how[p] == "xmlrpc":
            s.sendall(("POST /RPC2 HTTP/1.0\r\nHost: %s:%d\r\nContent-Type: text/xml\r\n"
                       "Content-Length: %d\r\n\r\n%s" % (ip, p, len(XMLRPC), XMLRPC)).encode())
        if how[p] != "accept":
            s.settimeout(min(t, 1.5 if how[p] == "line" else 1.0))
            while b"\n" not in b and len(b) < 200:
                c = s.recv(200)
                if not c:
                    break
                b += c
    except Exception:
        pass
    s.close()
    res[p] = ["open", b.decode("utf-8", "replace").strip().split("\n")[0].strip()[:160]]
def icmp():
    import shutil, subprocess
    exe = shutil.which("ping")
    if exe:
        try:
            r = subprocess.run([exe, "-c", "1", "-W", str(max(1, int(t))), ip], timeout=t + 1,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            res["ping"] = r.returncode == 0
        except Exception:
            pass
import time
t0 = time.monotonic()
th = {p: threading.Thread(target=probe, args=(p,)) for p in ports}
th["ping"] = threading.Thread(target=icmp)
for x in th.values():
    x.daemon = True; x.start()
for k, x in th.items():
    if k not in optional and k != "ping":
        x.join(t + 2)
grace = max(0.25, time.monotonic() - t0)
for k in ["ping", *optional]:
    th[k].join(max(0.0, t0 + grace - time.monotonic()) if len(optional) < len(ports) else t + 2)
    if k not in res and k != "ping":
        res[k] = ["pending", "%.2f" % grace]
ping = res.pop("ping", None)
print("PING " + json.dumps(ping))
print("RESULT " + json.dumps(res))
"""
# How the peer's probe talks to each port once connected (what answers there):
#   "line": a server that speaks first (our listener's greeting, an SSH banner): read its line;
#   "xmlrpc": the ROS master (XML-RPC over HTTP never speaks first): ask it a harmless getPid
#             and read the status line of its answer;
#   "accept": a server that waits for a request we have no harmless one for (a Zenoh router):
#             the accepted connection is the answer, nothing is read.
# A "?" after it marks a port the verdict does not need: once the others are done, it gets as
# long again (at least 0.25 s), then it is reported "pending" (its text: the seconds waited).
PortTalk = Literal["line", "xmlrpc", "accept", "line?", "xmlrpc?", "accept?"]


def port_probe_argv(ip: str, t_connect: float, ports: dict[int, PortTalk]) -> list[str]:
    """The arguments of PROBE_SCRIPT, run by a peer to test *ports* (how to talk to each) at *ip*,
    and ping it: it prints ``PING true|false|null`` and ``RESULT {port: [state, first line read]}``
    (state: open, timeout, error, or pending for an optional port not waited for longer)."""
    return [ip, f"{t_connect:.2f}", ",".join(f"{p}={h}" for p, h in ports.items())]


def _talk(port: int, lst: PortListener | None, ros_port: int) -> PortTalk:
    """How to talk to *port* (*lst*: our listener holds it)."""
    if lst is not None or port == 22:
        return "line"
    return "xmlrpc" if port == ros_port else "accept"


def _what_answered(how: PortTalk, text: str) -> str:
    """What the peer's probe got from an open port, in a few words."""
    how = how.rstrip("?")  # type: ignore[assignment]
    if how == "accept":
        return "connection accepted (the service waits for its client to speak first)"
    if how == "xmlrpc":
        return (f"getPid over XML-RPC answered {text[:60]!r}" if text else
                "connection accepted (no answer to getPid over XML-RPC in time)")
    return f"read {text[:60]!r}"


async def _probe_from_peer(ctx: CheckContext, peer: Peer, public_ip: str,
                           ports: dict[int, PortTalk], left: Callable[[], float]
                           ) -> tuple[dict[int, tuple[str, str]] | None, bool | None, str]:
    """The peer's view of *ports* at *public_ip*, whether it answers ping, and why not, within
    the time *left* says remains of the check's budget.

    The wait for the SSH connection is bounded (patience): an unreachable peer leaves the rest
    of the budget to the port checker.
    """
    t_connect, total = min(max(left() * 0.35, 0.5), 3.0), left() * 0.9
    patience = max(ctx.timeout_s * 0.6, 0.3)
    res = await peer_run(ctx, peer, chat_agent(ctx), "port_probe",     # the round's agent there
                         port_probe_argv(public_ip, t_connect, ports), timeout=total,
                         tcp_timeout=patience, connect_timeout=min(patience, total),
                         source=PROBE_SCRIPT.encode())
    if not res.ok:
        return None, None, f"SSH to {peer.name} failed ({res.failure}): {res.detail}"
    ping = next((_PING_WORDS[ln[5:].strip()] for ln in res.stdout.splitlines()
                 if ln.startswith("PING ") and ln[5:].strip() in _PING_WORDS), None)
    result = parse_probe_result(res.stdout)
    if result is not None:
        return result, ping, ""
    why = (res.stderr.strip().splitlines() or ["no output"])[-1]
    if "python3" in res.stderr and ("not found" in res.stderr or "No such file" in res.stderr):
        why = "python3 is not installed there"
    return None, ping, f"the probe on {peer.name} did not run: {why}"


_PING_WORDS = {"true": True, "false": False, "null": None}


def parse_probe_result(stdout: str) -> dict[int, tuple[str, str]] | None:
    """The peer probe's ``RESULT {port: [state, text]}`` line (the first one), or None when it
    is missing or not that shape (peer output: bounded depth, any shape refused cleanly)."""
    for line in stdout.splitlines():
        if line.startswith("RESULT "):
            try:
                raw = loads_bounded(line[7:], unique_keys=False)
                return {int(k): (str(v[0]), str(v[1])) for k, v in raw.items()}
            except (ValueError, KeyError, IndexError, TypeError, AttributeError):
                return None
    return None


def _answer_kind(state: str, text: str, lst: PortListener | None) -> str:
    """How a port answered the peer (data.PortAnswer): our token, another program, or the way
    the connection failed."""
    if state == "open":
        return "other" if lst is not None and lst.token not in text else "token"
    return "timeout" if state == "timeout" else kind_from_text(text)


def _explain_connect_error(text: str) -> str:
    low = text.lower()
    if "refused" in low:
        return (" (refused: the modem rejects it, or forwards it to a machine where nothing "
                "listens)")
    if "no route" in low or "unreachable" in low:
        return (" (no machine answered: the modem may forward to a local IP where nobody is, "
                "or the address is not this modem's)" if "host" in low else "")
    return ""


async def _probe_echoip(ctx: CheckContext, port: int, timeout: float) -> tuple[bool | None, str]:
    base = ctx.settings.probe.port_check_url.rstrip("/")
    ans = await http_get(f"{base}/port/{port}", timeout)
    if not ans.ok:
        if ans.status == 429:
            return None, f"GET {base}/port/{port} -> HTTP 429: the checker's rate limit; try later"
        return None, ans.describe()
    try:
        body = loads_bounded(ans.text, unique_keys=False)
        reachable = body.get("reachable")
    except (ValueError, AttributeError):
        return None, f"GET {base}/port/{port} -> not echoip JSON: {ans.text.strip()[:80]!r}"
    if not isinstance(reachable, bool):
        return None, f"GET {base}/port/{port} -> no 'reachable' in {ans.text.strip()[:80]!r}"
    ip = body.get("ip")
    return reachable, (f"GET {base}/port/{port} -> reachable={str(reachable).lower()}"
                       + (f" (tested {ip})" if ip else ""))


def _address_here(interface: str, wanted: str) -> str:
    """*wanted* when this machine has it, else the address of *interface* (or the default
    route's): the address our listener can really be reached on."""
    here = {a.address for addrs in psutil.net_if_addrs().values() for a in addrs
            if a.family == socket.AF_INET}
    if wanted and wanted in here:
        return wanted
    if interface:
        return interface_ipv4(interface)[0]
    return detect_local_net().local_ip


LAN_SKIP = ("on the {profile} LAN profile every component is on the same LAN, so nothing needs "
            "forwarding, and a phone hotspot cannot forward at all; the Linux step tests the "
            "LAN itself")


@check("router.port_open", "router", "Ports are open from outside (port forwarding works)", 3.0)
async def check_port_open(ctx: CheckContext) -> Outcome:
    s = ctx.settings
    if s.this.profile != "remote":      # LAN profiles (office, portable): nothing to forward
        return Outcome(Status.SKIP, "skipped: " + LAN_SKIP.format(profile=s.this.profile), [],
                       {"ports": [], "test_port": s.probe.port, "test_port_open": None,
                        "public_ip": None})
    if s.ros2:  # ROS 2 over rmw_zenoh: one port, on the master only (see below)
        return await _port_open_ros2(ctx)
    total = budget(ctx, "router.port_open") * 0.9
    loop = asyncio.get_running_loop()
    start = loop.time()

    def left() -> float:
        return max(total - (loop.time() - start), 0.2)

    test_port = s.probe.port
    ours: dict[int, PortListener | None] = {}
    evidence: list[str] = []
    async with contextlib.AsyncExitStack() as stack:
        try:
            ours[test_port] = lst = await stack.enter_async_context(
                ctx.listeners.hold(test_port, wait_s=left() * 0.3))
            evidence += [lst.note] * bool(lst.note)
        except OSError as exc:
            ours[test_port] = None
            evidence.append(f"our listener could not bind {test_port}: {exc.strerror or exc}")
        randoms: list[int] = []
        for _ in range(2):          # two random ports of the range, each one that is free here
            with contextlib.suppress(OSError):
                lst = await stack.enter_async_context(ctx.listeners.hold_spare(
                    {test_port, 11311, s.ros.port, *randoms}))
                ours[lst.port] = lst
                randoms.append(lst.port)
        services: list[int] = []
        for p in (22, s.ros.port or 11311):
            if p not in services and await run_blocking(
                    lambda p=p: services_listening(p, reachable=True), timeout=1.0):
                services.append(p)
        ports = [test_port, *randoms, *services]
        peer = next(iter(ssh_peers(s)), None)
        via = "echoip"
        public_ip: str | None = None
        outcomes: dict[int, tuple[bool | None, str]] = {}
        answers: dict[int, str | None] = {}     # how each port answered (peer test only)
        ping: bool | None = None
        if peer is not None:
            public_ip = await fetch_public_ip(ctx, min(left() * 0.25, 3.0)) or s.this.public_ip or None
            if public_ip and s.this.public_ip and public_ip != s.this.public_ip:
                evidence.append(f"the internet sees {public_ip}; the settings say {s.this.public_ip}")
            if not public_ip:
                evidence.append("the public IP is unknown, so the peer cannot be asked")
            else:
                talk = {p: _talk(p, ours.get(p), s.ros.port or 11311) for p in ports}
                raw, ping, why = await _probe_from_peer(ctx, peer, public_ip, talk, left)
                if ping is not None:
                    evidence.append(f"{peer.name} -> ping {public_ip}: "
                                    + ("reply (the address is online)" if ping else "no reply"))
                if raw is None:
                    evidence.append(why + "; asking the port checker instead")
                else:
                    via = f"peer:{peer.name}"
                    for p in ports:
                        state, text = raw.get(p, ("error", "no result"))
                        lst = ours.get(p)
                        answers[p] = _answer_kind(state, text, lst)
                        if state == "open":
                            if lst is not None and lst.token not in text:
                                outcomes[p] = (False, f"{peer.name} -> {public_ip}:{p}: accepted, but "
                                                      f"not by our listener (it said {text!r}): the "
                                                      "port is forwarded to another machine")
                            else:
                                src = ""
                                if lst is not None:
                                    seen = [x.address for x in lst.seen]
                                    src = f"; our listener saw {seen[-1]}" if seen else ""
                                outcomes[p] = (True, f"{peer.name} -> {public_ip}:{p}: open, "
                                                     f"{_what_answered(talk[p], text)}{src}")
                        elif state == "timeout":
                            outcomes[p] = (False, f"{peer.name} -> {public_ip}:{p}: no answer "
                                                  "(dropped: no forwarding or a firewall)")
                        else:
                            outcomes[p] = (False, f"{peer.name} -> {public_ip}:{p}: {text}"
                                           + _explain_connect_error(text))
        if not outcomes:
            via = "echoip"
            checkable = [p for p in ports if p >= 1024]
            for p in ports:
                if p < 1024:
                    outcomes[p] = (None, f"port {p}: the port checker only tests 1024-65535")
            t = left() * 0.9
            got = await asyncio.gather(*(_probe_echoip(ctx, p, t) for p in checkable))
            outcomes.update(zip(checkable, got, strict=True))
            if public_ip is None:
                public_ip = round_public_ip(ctx) or s.this.public_ip or None
    rows: list[dict[str, Any]] = []
    for p in ports:
        reachable, line = outcomes[p]
        listener = ours.get(p) is not None if p in ours else True
        rows.append({"port": p, "reachable": reachable, "listener": listener, "via": via,
                     "answer": answers.get(p) if via != "echoip" else None})
        evidence.append(line)
    test_open = outcomes[test_port][0]
    data = {"ports": rows, "test_port": test_port, "test_port_open": test_open,
            "public_ip": public_ip, "public_ip_ping": ping}
    exposed = [p for p in services if outcomes[p][0]]
    if exposed:
        evidence.append("open to the whole internet: " + ", ".join(
            {22: "22 (SSH)"}.get(p, f"{p} (ROS master)") for p in exposed))
    where = f"from {via[5:]}" if via.startswith("peer:") else "by the port checker"
    listener_up = ours.get(test_port) is not None
    if test_open is None and all(r["reachable"] is None for r in rows):
        return Outcome(Status.FAIL, "could not test from outside: " + outcomes[test_port][1],
                       evidence, data)
    if test_open is False:
        if listener_up:
            return Outcome(Status.FAIL, f"test port {test_port} is closed {where} while our listener "
                                        "runs: port forwarding is not working", evidence, data)
        return Outcome(Status.FAIL, f"test port {test_port} is closed {where}, and our listener could "
                                    "not start there (port in use)", evidence, data)
    closed = [r["port"] for r in rows if r["reachable"] is False]
    unknown = [r["port"] for r in rows if r["reachable"] is None and int(r["port"]) >= 1024]
    hard = [p for p in closed if p != 22 and (p != s.ros.port or s.is_master or p in randoms)]
    if hard:
        return Outcome(Status.FAIL, f"test port {test_port} is open {where}, but "
                                    f"{', '.join(map(str, hard))} {'is' if len(hard) == 1 else 'are'} "
                                    "closed: forward the whole range 1024-65000, not single ports",
                       evidence, data)
    if closed or unknown:
        what = ", ".join(map(str, closed + unknown))
        return Outcome(Status.WARN, f"test port {test_port} is open {where}; {what} could not be "
                                    "confirmed", evidence, data)
    n = len(ports)
    return Outcome(Status.PASS, f"{n} port{'s' if n > 1 else ''} open {where} "
                                f"({', '.join(map(str, ports))})", evidence, data)


# --------------------------------------------------------------------------- ROS 2 (rmw_zenoh)
async def _port_open_ros2(ctx: CheckContext) -> Outcome:
    """router.port_open under [ros] version = 2: only the master's modem forwards anything, TCP
    zenoh_port to its router; a member needs no forwarding (its router connects out)."""
    s = ctx.settings
    zport, test_port = s.ros.zenoh_port, s.probe.port
    data: dict[str, Any] = {"ports": [], "test_port": test_port, "public_ip": None,
                            "zenoh_port": zport, "zenoh_port_open": None, "zenoh_listener": "none"}
    if s.relayed:       # the relay's port is the one to test from outside
        return await relay_port_open(ctx, budget(ctx, "router.port_open") * 0.9)
    if not s.is_master:
        return Outcome(Status.SKIP, f"skipped: {s.this.name or 'this component'} is a ROS 2 "
                       "member: its router connects out to the master's, so its modem needs no "
                       "forwarding at all", [], data)
    total = budget(ctx, "router.port_open") * 0.9
    loop = asyncio.get_running_loop()
    start = loop.time()

    def left() -> float:
        return max(total - (loop.time() - start), 0.2)

    evidence: list[str] = []
    ours: dict[int, PortListener | None] = {}
    async with contextlib.AsyncExitStack() as stack:
        if await run_blocking(lambda: services_listening(zport, ctx.listeners, reachable=True),
                              timeout=1.0):
            data["zenoh_listener"] = "router"
            evidence.append(f"TCP {zport}: a process listens here (the Zenoh router)")
        else:
            with contextlib.suppress(OSError):
                ours[zport] = await stack.enter_async_context(ctx.listeners.hold(zport))
                data["zenoh_listener"] = "ours"
                evidence.append(f"TCP {zport}: no router listens; our listener stands in for it")
        with contextlib.suppress(OSError):
            ours[test_port] = await stack.enter_async_context(
                ctx.listeners.hold(test_port, wait_s=left() * 0.3))
        ports = [zport, test_port]
        peer = next(iter(ssh_peers(s)), None) if s.this.profile == "remote" else None
        public_ip = await fetch_public_ip(ctx, min(left() * 0.25, 3.0)) or s.this.public_ip or None
        data["public_ip"] = public_ip
        outcomes: dict[int, tuple[bool | None, str]] = {}
        via = "echoip"
        answers: dict[int, str | None] = {}     # how each port answered (peer test only)
        if peer is not None and public_ip:
            # The verdict needs zenoh_port only: the test port is not waited for much longer.
            talk: dict[int, PortTalk] = {zport: _talk(zport, ours.get(zport), 0)}
            talk[test_port] = "line?" if test_port in ours else "accept?"
            raw, data["public_ip_ping"], why = await _probe_from_peer(ctx, peer, public_ip,
                                                                        talk, left)
            if raw is None:
                evidence.append(why + "; asking the port checker instead")
            else:
                via = f"peer:{peer.name}"
                for p in ports:
                    state, text = raw.get(p, ("error", "no result"))
                    lst = ours.get(p)
                    answers[p] = None if state == "pending" else _answer_kind(state, text, lst)
                    if state == "pending":
                        outcomes[p] = (None, f"{peer.name} -> {public_ip}:{p}: no answer within "
                                             f"{text} s after TCP {zport} answered; not waited "
                                             "for longer")
                    elif state == "open" and lst is not None and lst.token not in text:
                        outcomes[p] = (False, f"{peer.name} -> {public_ip}:{p}: accepted, but not "
                                              "by this machine: forwarded to another one")
                    elif state == "open":
                        outcomes[p] = (True, f"{peer.name} -> {public_ip}:{p}: open")
                    elif state == "timeout":
                        outcomes[p] = (False, f"{peer.name} -> {public_ip}:{p}: no answer "
                                              "(dropped: no forwarding or a firewall)")
                    else:
                        outcomes[p] = (False, f"{peer.name} -> {public_ip}:{p}: {text}"
                                       + _explain_connect_error(text))
        if not outcomes:
            got = await asyncio.gather(*(_probe_echoip(ctx, p, left() * 0.9) for p in ports))
            outcomes.update(zip(ports, got, strict=True))
    for p in ports:
        reachable, line = outcomes[p]
        data["ports"].append({"port": p, "reachable": reachable, "via": via,
                              "listener": p in ours or (p == zport and
                                                        data["zenoh_listener"] == "router"),
                              "answer": answers.get(p) if via != "echoip" else None})
        evidence.append(line + ("" if p == zport else " (the test port: not needed for ROS 2)"))
    zopen = outcomes[zport][0]
    data["zenoh_port_open"] = zopen
    where = f"from {via[5:]}" if via.startswith("peer:") else "by the port checker"
    who = {"router": "the Zenoh router listens", "ours": "our listener stands in for the router",
           "none": "nothing could listen"}[data["zenoh_listener"]]
    if zopen is None:
        return Outcome(Status.FAIL, f"could not test TCP {zport} from outside: {outcomes[zport][1]}",
                       evidence, data)
    if not zopen:
        return Outcome(Status.FAIL, f"TCP {zport} (the master's Zenoh router) is closed {where} "
                                    f"while {who} here: the modem does not forward it to "
                                    f"{s.this.local_ip or 'this machine'}", evidence, data)
    return Outcome(Status.PASS, f"TCP {zport} is open {where} ({who}); ROS 2 needs no other "
                                "port", evidence, data)
