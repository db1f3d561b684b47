"""What the ros2.* checks share (checks/ros2.py and checks/ros2_graph.py): the ROS 2
variables a node started here gets, Zenoh sessions, and reading a peer's Zenoh program."""

from __future__ import annotations

import asyncio
import contextlib
import functools
import sys
import time
from typing import Any

from rosnet_tui.core.checks import CheckContext
from rosnet_tui.core.checks.probes.agents import why_no_report
from rosnet_tui.core.checks.probes.peers import ssh_peers
from rosnet_tui.core.config.paths import default_config_dir
from rosnet_tui.core.config.settings_model import Peer
from rosnet_tui.core.net.blocking import run_blocking
from rosnet_tui.core.net.connect import close_writer, tcp_failure_kind
from rosnet_tui.core.peer import zenohproto
from rosnet_tui.core.peer.commands import PEER_INSTALL_PLACES, README_INSTALL
from rosnet_tui.core.ros import fleet_tls, ros2
from rosnet_tui.core.ssh.connection import SshResult


async def after_outsider_attempts(ctx: CheckContext, wait_s: float) -> None:
    """Let security.outsider's attempts go first (waiting up to *wait_s* for it to end) before
    a bare TCP connection to the master's Zenoh port under mutual TLS. The router refuses that
    connection's handshake, and Zenoh's TLS listener then sleeps 100 ms and takes no handshake
    meanwhile (TLS_ACCEPT_THROTTLE_TIME): the outsider's insider, whose session ticket times
    the fleet's way in, waited 120-160 ms behind the master's round's bare probes instead of
    7-10. linux.chat_in and linux.chat_out wait here; router.port_open does not (its own probe
    is long: behind the outsider it made the master's round slower)."""
    s = ctx.settings
    if s.ros2 and s.ros.security == "mtls" and not s.relayed:
        await ctx.after(("security.outsider",), time.monotonic() + max(wait_s, 0.0))


def zenoh_env(ctx: CheckContext) -> dict[str, str]:
    """The ROS 2 variables nodes started here get (environment, then ~/.bashrc)."""
    return zenohproto.ros_env(ctx.env, str(ctx.paths.bashrc_path))


def node_domain(ctx: CheckContext) -> int:
    """The ROS_DOMAIN_ID nodes started here use (unset: 0); ros2.env compares it with the settings."""
    value = zenoh_env(ctx).get("ROS_DOMAIN_ID", "").strip() or "0"
    return int(value) if value.isascii() and value.isdigit() else ctx.settings.ros.domain_id


def node_endpoint(ctx: CheckContext) -> tuple[str, str]:
    """(endpoint, 'router'|'client'): where a ROS 2 node started here connects."""
    return zenohproto.peer_endpoint(zenoh_env(ctx), ros2.local_endpoint())


def client_tls() -> dict[str, Any]:
    """How a check dials a ``tls/`` endpoint: with this component's fleet key and certificate,
    trusting the fleet CA, the name in the locator verified (ROS 2 mutual TLS)."""
    p = fleet_tls.tls_paths(default_config_dir())
    return {"root_ca_certificate": str(p.ca_crt), "connect_private_key": str(p.node_key),
            "connect_certificate": str(p.node_crt), "enable_mtls": True,
            "verify_name_on_connect": True}


async def open_zenoh(endpoint: str, t: float, how: str = "client"
                     ) -> tuple[Any | None, str | None]:
    """A Zenoh session on *endpoint* within *t* s: (session, None) or (None, why not). *how* is
    node_endpoint()'s answer (a node's way in: a peer of a router, or client), or "client".
    A ``tls/`` endpoint is dialled with this component's fleet certificate (client_tls)."""
    mode = zenohproto.session_mode(how)
    tls = client_tls() if endpoint.startswith("tls/") else None
    try:
        return await run_blocking(zenohproto.open_client, endpoint, t, mode, tls,
                                  timeout=t + 0.4), None
    except asyncio.TimeoutError:
        return None, f"no Zenoh session within {t + 0.4:.1f} s"
    except zenohproto.ZenohMissing:
        return None, (f"eclipse-zenoh is not installed for this Python ({sys.executable}); it "
                      f"comes with rosnet-tui: reinstall it as the README says (`{README_INSTALL}`)")
    except zenohproto.OpenFailed as exc:
        return None, str(exc)


async def close_zenoh(session: Any, wait_s: float = 1.0) -> None:
    """Close *session*, waiting *wait_s* at most (a close still under way on a slow link ends
    in the background)."""
    if session is not None:
        with contextlib.suppress(Exception):
            await run_blocking(session.close, timeout=max(0.05, wait_s))


def ros2_peers(ctx: CheckContext) -> list[Peer]:
    """Peers to run the other side on (those with an SSH user), the master first."""
    s = ctx.settings
    return sorted(ssh_peers(s), key=lambda p: p.name != s.master_name)


def member_arg(ctx: CheckContext, peer: Peer) -> list[str]:
    """Tell the peer program it is a member (its router must be linked to the master's)."""
    return ["--member", "1"] if peer.name != ctx.settings.master_name else []


def zenoh_peer_problem(res: SshResult, peer: Peer, rep: dict | None) -> str | None:
    """Why the peer's zenoh program gave no usable report (None: it did)."""
    if res.failure and res.failure != "timeout" and rep is None:
        return f"SSH to {peer.name} failed ({res.failure}): {res.detail}"
    if rep is not None and rep.get("error") == "no_install":
        return (f"rosnet-tui is not installed on {peer.name} (looked in {PEER_INSTALL_PLACES}): "
                f"install it there as the README says, in a checkout: `{README_INSTALL}`")
    if res.exit_status == 127:
        return f"{peer.name} has no sh or python3 to run the probe (exit status 127)"
    if rep is not None and rep.get("error") == "no_zenoh":
        return (f"the rosnet-tui on {peer.name} ({rep.get('python') or 'its Python'}) has no "
                f"eclipse-zenoh: reinstall it there as the README says, in a checkout: "
                f"`{README_INSTALL}`")
    if rep is None:
        return (f"the probe on {peer.name} gave no report "
                f"({why_no_report(res)})")
    return None


def router_links(info: dict) -> list[str]:
    """Ids of the routers a router (its admin space *info*) has sessions with."""
    return [x["zid"] for x in info.get("sessions") or [] if x.get("whatami") == "router"]


async def tcp_reach(host: str, port: int, t: float) -> tuple[str | None, str]:
    """(None, 'connected') or (failure kind, words) of a plain TCP connect to a router's port
    (ros2.router, relay.router)."""
    writer = None
    try:
        _r, writer = await asyncio.wait_for(asyncio.open_connection(host, port), t)
        return None, "connected"
    except asyncio.TimeoutError:
        return "timeout", f"no answer within {t:.1f} s (dropped: no forwarding, or a firewall)"
    except ConnectionRefusedError:
        return "refused", "connection refused (forwarded, but nothing listens there)"
    except OSError as exc:
        kind = "unreachable" if tcp_failure_kind(exc) == "unreachable" else "refused"
        return kind, exc.strerror or str(exc)
    finally:
        if writer is not None:
            await close_writer(writer, 0.3)


SLOW_TCP_S = 0.5     # a TCP connect slower than this to a router: a slow or busy link


async def dial_router(address: str, port: int, endpoint: str, t: float, deadline: float,
                      ev: list[str], how: str = "", *, others: bool = False,
                      facts: dict[str, Any] | None = None) -> tuple[str | None, str, Any]:
    """Reach a Zenoh router as this component's router would (ros2.router, relay.router): TCP
    to *address*:*port*, then a session on *endpoint* and the router's own account of itself
    (with *others*, the other routers' too: zenohproto.router_info).
    (failure kind or None, the TCP attempt in words, the router's info or None); what was seen
    goes to *ev* (*how* says with what the session was opened); *facts* gets ``slow_tcp_s``, the
    seconds a TCP connect took when it was slower than :data:`SLOW_TCP_S`."""
    began = time.monotonic()
    kind, words = await tcp_reach(address, port,
                                  max(0.2, min(t * 0.4, deadline - time.monotonic())))
    took = time.monotonic() - began
    if kind is None and took > SLOW_TCP_S:     # a thin or busy link: said with the figure
        words = f"connected after {took:.1f} s (a slow or busy link)"
        if facts is not None:
            facts["slow_tcp_s"] = round(took, 2)
    ev.append(f"TCP {address}:{port}: {words}")
    if kind is not None:
        return kind, words, None
    # the session has the time left but what its account (or a TLS handshake saying why not)
    # and the close need
    session, why = await open_zenoh(endpoint, max(0.2, deadline - time.monotonic() - 1.0))
    if session is None:
        ev.append(f"Zenoh session on {endpoint}{how}: {why}")
        return "not_zenoh", words, None
    try:
        left = deadline - time.monotonic()   # two questions with *others*: half each
        try:
            return None, words, await run_blocking(
                functools.partial(zenohproto.router_info, others=others), session,
                max(0.1, min(0.8, left / (2 if others else 1))), timeout=max(0.2, left))
        except asyncio.TimeoutError:    # the session opened: a router, silent on itself
            ev.append(f"Zenoh router at {endpoint}: its admin space gave no answer in time")
            return None, words, {}
    finally:
        await close_zenoh(session, min(1.0, deadline - time.monotonic()))
