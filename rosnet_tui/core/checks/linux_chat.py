"""Step 3, Linux: the TCP chat by name, both ways (linux.chat_out, linux.chat_in); under ROS 2
the one connection that crosses the modems, from each member to the master's router port.

The peer's side (:mod:`rosnet_tui.core.peer.chatproto`, stdlib only: nothing to install on the peer)
runs over SSH by the round's peer agent there, with ``nc`` as the fallback when the peer has no
python3.
"""

from __future__ import annotations

import asyncio
import contextlib
import re
import secrets
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from typing import Any

from rosnet_tui.core.checks import CheckContext, check
from rosnet_tui.core.checks.probes.agents import (
    CHAT_SOURCE,
    chat_agent,
    no_python,
    peer_python,
    peer_run,
    peer_session,
)
from rosnet_tui.core.checks.probes.budget import budget
from rosnet_tui.core.checks.probes.listening import services_listening
from rosnet_tui.core.checks.probes.peers import NO_SSH_USER, each_peer, ssh_peers
from rosnet_tui.core.checks.probes.ros2 import after_outsider_attempts
from rosnet_tui.core.config.settings_model import Peer
from rosnet_tui.core.net.blocking import run_blocking
from rosnet_tui.core.net.connect import close_writer, kind_from_text, tcp_failure_kind
from rosnet_tui.core.net.listener import ECHO, GREETING
from rosnet_tui.core.peer.chatproto import CHAT
from rosnet_tui.core.peer.commands import python_command, shq
from rosnet_tui.core.peer.peer_agent import AgentCall
from rosnet_tui.core.results import Outcome, Status
from rosnet_tui.core.ssh.connection import SshResult, resolve_ipv4
from rosnet_tui.core.ssh.session import SshSession, ssh_run, ssh_session

# --------------------------------------------------------------------------- chats

_IS_OPENBSD_NC = "nc -h 2>&1 | grep -q OpenBSD"


def _nc_chat(token: str, wait: float, openbsd_args: str, traditional_args: str) -> str:
    """The chat line sent with nc, OpenBSD's (``-N``: hang up after stdin ends) or the
    traditional one, bounded by ``timeout``."""
    w = max(int(wait + 0.999), 1)
    msg = shq(f"{CHAT} {token}")
    return (f"if {_IS_OPENBSD_NC}; then echo {msg} | timeout {w} nc -N {openbsd_args}; "
            f"else echo {msg} | timeout {w} nc {traditional_args}; fi")


def _python_else(py: str, fallback: str) -> str:
    """*py* when the peer has its python3, else *fallback*."""
    return f"if command -v {peer_python()} >/dev/null 2>&1; then {py}; else {fallback}; fi"


def listen_command(port: int, token: str, wait: float) -> str:
    """Peer side of chat_out without the round's agent: python3 when present, else ``nc -l``
    (OpenBSD or traditional)."""
    py = python_command(CHAT_SOURCE.decode(), "listen", str(port), token, f"{wait:.1f}",
                        python=peer_python())
    # NC first: the reader stops at LISTENING, and must know by then that nc (slow to listen,
    # so tried again) is the one listening
    nc = f"echo NC; echo LISTENING {port}; " + _nc_chat(token, wait, f"-l {port}", f"-l -p {port}")
    return _python_else(py, nc)


def connect_command(name: str, port: int, token: str, t: float) -> str:
    """Peer side of chat_in without the round's agent: connect to *name* as the peer resolves
    it (python3 when present, else nc)."""
    py = python_command(CHAT_SOURCE.decode(), "connect", name, str(port), f"{t:.1f}", token,
                        python=peer_python())
    target = f"{shq(name)} {port}"
    nc = (f"echo NC; echo RESOLVED $(getent ahostsv4 {shq(name)} | head -n1 | cut -d' ' -f1); "
          + _nc_chat(token, t, target, target))
    return _python_else(py, nc)


@contextlib.asynccontextmanager
async def _peer_side(ctx: CheckContext, peer: Peer, argv: list[str], shell_command: str, *,
                     timeout: float, tcp_timeout: float) -> AsyncIterator[AgentCall | SshSession]:
    """The chat's peer side on *peer* for an ``async with`` block: run by the round's agent
    there, or, when that found no python3, by *shell_command* (its nc fallback)."""
    async with peer_session(ctx, peer, chat_agent(ctx), "chat", argv, timeout=timeout,
                            tcp_timeout=tcp_timeout) as call:
        if not no_python(call):
            yield call
            return
    async with ssh_session(ctx.ssh, peer, shell_command, timeout=timeout,
                           tcp_timeout=tcp_timeout) as sess:
        yield sess


async def _peer_chat_run(ctx: CheckContext, peer: Peer, argv: list[str], shell_command: str | None,
                         *, timeout: float, connect_timeout: float) -> SshResult:
    """Run the chat's peer side on *peer* to its end (see _peer_side): by the round's agent, or
    *shell_command* when that found no python3 (None: no fallback)."""
    res = await peer_run(ctx, peer, chat_agent(ctx), "chat", argv, timeout=timeout,
                         connect_timeout=connect_timeout, tcp_timeout=ctx.timeout_s)
    if shell_command is None or not no_python(res):
        return res
    return await ssh_run(ctx.ssh, peer, shell_command, timeout=timeout,
                         connect_timeout=connect_timeout, tcp_timeout=ctx.timeout_s)


async def _chat_per_peer(ctx: CheckContext, check_id: str,
                         one: Callable[[Peer, float], Awaitable[tuple[bool, str | None, list[str]]]],
                         what: str, kinds: dict[str, str] | None = None) -> Outcome:
    data: dict[str, Any] = {"peers": {}}
    peers = ssh_peers(ctx.settings)
    for p in ctx.settings.peers:
        if not p.ssh_user:
            data["peers"][p.name] = {"ok": False, "failure": "no_user"}
    if not peers:
        return Outcome(Status.SKIP, NO_SSH_USER, data=data)
    t = budget(ctx, check_id) * 0.9
    got = await each_peer(peers, lambda p: one(p, t))
    evidence: list[str] = []
    good: list[str] = []
    bad: list[str] = []
    for p, (ok, failure, lines) in zip(peers, got, strict=True):
        data["peers"][p.name] = {"ok": ok, "failure": failure}
        if kinds and p.name in kinds:
            data["peers"][p.name]["tcp"] = kinds[p.name]
        evidence.extend(lines)
        (good if ok else bad).append(f"{p.name}" if ok else f"{p.name} ({failure})")
    if bad:
        return Outcome(Status.FAIL, f"{what} failed: {', '.join(bad)}", evidence, data)
    return Outcome(Status.PASS, f"{what} works: {', '.join(good)}", evidence, data)


def _ssh_failure(res: SshResult, peer: Peer) -> tuple[bool, str, list[str]]:
    return False, f"ssh:{res.failure}", [f"could not run the peer's side on {peer.name} over SSH "
                                         f"({res.failure}): {res.detail}"]


@check("linux.chat_out", "linux", "Chat by name: we connect to the peer", 3.0)
async def check_chat_out(ctx: CheckContext) -> Outcome:
    if ctx.settings.ros2:  # ROS 2 over rmw_zenoh: only the way to the master's router matters
        return await chat_ros2(ctx, out=True)
    me = ctx.settings.this.name or "this component"
    kinds: dict[str, str] = {}      # how our TCP connection to each peer's listener went

    async def one(peer: Peer, total: float) -> tuple[bool, str | None, list[str]]:
        start = time.monotonic()

        def left() -> float:
            return max(total - (time.monotonic() - start), 0.2)

        peer_token = secrets.token_hex(6)
        my_token = secrets.token_hex(6)
        port = ctx.settings.probe.port
        ev: list[str] = []
        async with _peer_side(ctx, peer, ["listen", str(port), peer_token, f"{total * 0.6:.1f}"],
                              listen_command(port, peer_token, total * 0.6),
                              timeout=total * 0.45, tcp_timeout=ctx.timeout_s) as sess:
            if not sess.ok:
                return _ssh_failure(sess.result, peer)
            out = await sess.read_until("LISTENING", left() * 0.6)
            if out is None:
                res = await sess.wait(0.3)
                text = (res.stdout + res.stderr).strip().splitlines()
                return False, "peer_listen", [f"{peer.name} did not start listening: "
                                              f"{text[-1] if text else 'no output'}"]
            m = re.search(r"LISTENING (\d+)", out)
            rport = int(m.group(1)) if m else port
            use_nc = "\nNC" in out or out.startswith("NC")
            ev.append(f"{peer.name} listens on TCP {rport} (over SSH, "
                      f"{'nc' if use_nc else 'python3'})")
            addrs, err = await resolve_ipv4(peer.name, min(left() * 0.3, 2.0))
            if not addrs:
                return False, "resolve", ev + [f"{peer.name} does not resolve here: {err}"]
            reader = writer = None
            connect_err = ""
            for _ in range(8 if use_nc else 1):
                try:
                    reader, writer = await asyncio.wait_for(
                        asyncio.open_connection(addrs[0], rport),
                        min(left() * 0.5, ctx.timeout_s))
                    kinds[peer.name] = "connected"
                    break
                except (OSError, asyncio.TimeoutError) as exc:
                    kinds[peer.name] = tcp_failure_kind(exc)
                    connect_err = str(exc) or "no answer (timed out)"
                    if not use_nc:
                        break
                    await asyncio.sleep(0.15)
            if writer is None:
                await sess.wait(0.2)
                return False, "connect", ev + [
                    f"connect {peer.name} ({addrs[0]}):{rport}: {connect_err}: the peer listens, "
                    f"but its modem does not let the connection in (port forwarding on "
                    f"{peer.name}'s side), or the name points to the wrong address"]
            assert reader is not None
            try:
                hello = await asyncio.wait_for(reader.readline(), left() * 0.5)
                writer.write(f"{CHAT} hello from {me} {my_token}\n".encode())
                await asyncio.wait_for(writer.drain(), left() * 0.5)
            except (OSError, asyncio.TimeoutError) as exc:
                hello = b""
                ev.append(f"exchange with {peer.name}: {exc or 'timed out'}")
            finally:
                await close_writer(writer)
            hello_text = hello.decode(errors="replace").strip()
            ev.append(f"connect {peer.name} ({addrs[0]}):{rport}: connected, read {hello_text!r}")
            res = await sess.wait(left())
        got_line = next((ln for ln in res.stdout.splitlines() if my_token in ln), None)
        src = next((ln[5:] for ln in res.stdout.splitlines() if ln.startswith("FROM ")), None)
        if peer_token not in hello_text:
            return False, "wrong_peer", ev + [f"the answer did not come from our listener on "
                                              f"{peer.name}: the name or the forwarding leads "
                                              "to another machine"]
        if got_line is None:
            return False, "no_message", ev + [f"{peer.name} did not receive our message "
                                              f"(its output: {res.stdout.strip()[-120:]!r})"]
        ev.append(f"{peer.name} received {got_line.removeprefix('GOT ')!r}"
                  + (f" from {src}" if src else ""))
        return True, None, ev

    return await _chat_per_peer(ctx, "linux.chat_out", one, f"chat from {me} to the peer", kinds)


@check("linux.chat_in", "linux", "Chat by name: the peer connects to us", 3.0)
async def check_chat_in(ctx: CheckContext) -> Outcome:
    if ctx.settings.ros2:  # ROS 2 over rmw_zenoh: only the way to the master's router matters
        return await chat_ros2(ctx, out=False)
    me = ctx.settings.this.name
    if not me:
        return Outcome(Status.SKIP, "this component has no name in the settings yet",
                       data={"peers": {}})
    kinds: dict[str, str] = {}      # how the peer's TCP connection to our listener went

    async def one(peer: Peer, total: float) -> tuple[bool, str | None, list[str]]:
        start = time.monotonic()
        token = secrets.token_hex(6)
        ev: list[str] = []
        port = ctx.settings.probe.port
        async with contextlib.AsyncExitStack() as stack:
            try:
                lst = await stack.enter_async_context(
                    ctx.listeners.hold(port, wait_s=min(total * 0.2, 1.0)))
            except OSError as exc:
                return False, "local_listen", [f"cannot listen on our test port {port}: "
                                               f"{exc.strerror or exc} (see router.port_free)"]
            ev.append(f"we listen on TCP {port}" + (f" ({lst.note})" if lst.note else ""))
            left = max(total - (time.monotonic() - start), 0.5)
            t = min(left * 0.45, ctx.timeout_s)
            res = await _peer_chat_run(ctx, peer, ["connect", me, str(port), f"{t:.1f}", token],
                                       connect_command(me, port, token, t),
                                       timeout=left * 0.95, connect_timeout=left * 0.45)
            if not res.ok and res.failure != "timeout" and not res.stdout:
                return _ssh_failure(res, peer)
            seen = await lst.wait_for_line(token, 0.3)
        out = res.stdout
        resolved = next((ln[9:] for ln in out.splitlines() if ln.startswith("RESOLVED ")), None)
        hello = next((ln[6:] for ln in out.splitlines() if ln.startswith("HELLO ")), None)
        if hello is None:
            hello = next((ln for ln in out.splitlines() if ln.startswith(GREETING)), None)
        for ln in out.splitlines():
            if ln.startswith(("RESOLVE-ERROR", "CONNECT-ERROR", "ERROR")):
                ev.append(f"on {peer.name}: {ln}")
            if ln.startswith("CONNECT-ERROR"):
                kinds[peer.name] = kind_from_text(ln)
            elif ln.startswith("HELLO ") or ln.startswith(GREETING):
                kinds[peer.name] = "connected"
        if resolved is not None and not resolved.strip():
            resolved = None
        if resolved is None:
            return False, "peer_resolve", ev + [f"{peer.name} cannot resolve {me}: add it to "
                                                f"{peer.name}'s hosts file"]
        ev.append(f"{peer.name} resolves {me} -> {resolved}")
        if hello is None:
            return False, "connect", ev + [
                f"{peer.name} could not connect to {me} ({resolved}):{port}: our modem does not "
                f"forward the port to us, or {peer.name}'s hosts entry for {me} is stale"]
        if lst.token not in hello:
            return False, "wrong_peer", ev + [f"{peer.name} reached something else on "
                                              f"{resolved}:{port} ({hello[:60]!r}), not our listener"]
        if seen is None:
            return False, "no_message", ev + [f"{peer.name} connected but its message did not "
                                              "arrive here"]
        echo = next((ln[5:] for ln in out.splitlines() if ln.startswith("ECHO ")), "")
        ev.append(f"we received {seen.line!r} from {seen.address}"
                  + (f"; {peer.name} got our reply" if ECHO in echo else ""))
        return True, None, ev

    return await _chat_per_peer(ctx, "linux.chat_in", one, f"chat from the peer to {me}", kinds)


# --------------------------------------------------------------------------- ROS 2: the Linux chats
async def chat_ros2(ctx: CheckContext, out: bool) -> Outcome:
    """linux.chat_out / linux.chat_in under ROS 2 (they call it first thing).

    Under ROS 2 only one connection crosses the modems: from each member, by name, to the
    master's router port. So the chat toward the master is a TCP connection by name to
    turtlebot:<zenoh_port> (made here on a member; made by each member over SSH on the master),
    and the other direction is skipped: members accept nothing."""
    s = ctx.settings
    data: dict[str, Any] = {"peers": {}}
    port, me = s.ros.zenoh_port, s.this.name or "this component"
    if s.relayed:   # no path between the sites to test: both dial the relay
        return Outcome(Status.SKIP, f"skipped: under the relay ({s.relay.host}) no component "
                                    "connects to another; every router dials the relay "
                                    "(relay.router tests that path)", [], data)
    if out == s.is_master:
        why = (f"{me} is the ROS 2 master: it never connects to the members (their routers "
               "connect in to it; linux.chat_in tests that way)" if out else
               f"{me} is a ROS 2 member: it accepts no connections (its router connects out "
               "to the master's; linux.chat_out tests that way)")
        return Outcome(Status.SKIP, f"skipped: {why}", [], data)
    t = budget(ctx, "linux.chat_in" if not out else "linux.chat_out") * 0.8
    if out:
        master = s.master_name
        addrs, err = await resolve_ipv4(master, min(1.0, t * 0.3))
        if not addrs:
            data["peers"][master] = {"ok": False, "failure": "resolve"}
            return Outcome(Status.FAIL, f"{master} does not resolve here: {err}", [], data)
        await after_outsider_attempts(ctx, min(1.0, t * 0.2))
        ok, line, kind = await _tcp_connect(addrs[0], port, t * 0.6)
        data["peers"][master] = {"ok": ok, "failure": None if ok else "connect", "tcp": kind}
        ev = [f"{master} -> {addrs[0]}", line]
        if ok:
            return Outcome(Status.PASS, f"{me} reaches {master}:{port} by name (the master's "
                                        "router port, through its modem)", ev, data)
        return Outcome(Status.FAIL, f"{me} cannot connect to {master}:{port} by name "
                                    f"({addrs[0]}): the master's modem does not forward TCP "
                                    f"{port}, or nothing listens there", ev, data)
    peers = ssh_peers(s)
    for p in s.peers:
        if not p.ssh_user:
            data["peers"][p.name] = {"ok": False, "failure": "no_user"}
    if not peers:
        return Outcome(Status.SKIP, "no peer has an SSH user in the settings (peer.ssh_user), so "
                                    "the members' side cannot be run from here", data=data)
    began = time.monotonic()
    await after_outsider_attempts(ctx, min(1.0, t * 0.2))
    t -= time.monotonic() - began
    async with contextlib.AsyncExitStack() as stack:
        if not await run_blocking(lambda: services_listening(port, ctx.listeners),
                                  timeout=1.0):
            with contextlib.suppress(OSError):
                await stack.enter_async_context(ctx.listeners.hold(port, wait_s=t * 0.1))
        argv = ["connect", me, str(port), f"{t * 0.5:.1f}"]
        got = await each_peer(peers, lambda p: _peer_chat_run(ctx, p, argv, None, timeout=t,
                                                               connect_timeout=t * 0.5))
    ev: list[str] = []
    bad: list[str] = []
    for p, res in zip(peers, got, strict=True):
        text = res.stdout
        if "CONNECTED" in text:
            data["peers"][p.name] = {"ok": True, "failure": None, "tcp": "connected"}
            ev.append(f"{p.name} connected to {me}:{port} by name ({text.split()[1]})")
            continue
        failure = ("peer_resolve" if "RESOLVE-ERROR" in text else "connect" if text else
                   f"ssh:{res.failure or 'sshd'}")
        data["peers"][p.name] = {"ok": False, "failure": failure}
        err_line = next((ln for ln in text.splitlines() if ln.startswith("CONNECT-ERROR")), None)
        if err_line is not None:
            data["peers"][p.name]["tcp"] = kind_from_text(err_line)
        ev.append(f"{p.name}: {text.strip() or res.detail}")
        bad.append(f"{p.name} ({failure})")
    if bad:
        return Outcome(Status.FAIL, f"members cannot reach {me}:{port} by name: {', '.join(bad)}",
                       ev, data)
    return Outcome(Status.PASS, f"every member reaches {me}:{port} by name (the router port)",
                   ev, data)


async def _tcp_connect(host: str, port: int, timeout: float) -> tuple[bool, str, str]:
    """(connected, the line saying how, core.net.connect's kind of the attempt)."""
    writer = None
    try:
        _r, writer = await asyncio.wait_for(asyncio.open_connection(host, port), timeout)
        return True, f"TCP {host}:{port}: connected", "connected"
    except asyncio.TimeoutError as exc:
        return False, f"TCP {host}:{port}: no answer within {timeout:.1f} s", tcp_failure_kind(exc)
    except OSError as exc:
        return False, f"TCP {host}:{port}: {exc.strerror or exc}", tcp_failure_kind(exc)
    finally:
        if writer is not None:
            await close_writer(writer)
