"""Is this component's reverse tunnel up? Asked through the relay, as a peer would reach it: log
in to the relay (its host key verified), open a ``direct-tcpip`` channel to the relay's
``127.0.0.1:<port>`` and read the host key of the sshd that answers there; it must be one of
this machine's own sshd host keys (:mod:`.sshd_keys`; another key: a stale session, or another
component's tunnel on that port). No login at the far end: the key is all the question needs.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from dataclasses import dataclass

from rosnet_tui.core.config.settings_model import Peer
from rosnet_tui.core.net.blocking import run_blocking
from rosnet_tui.core.ssh.connection import (
    CHANNEL_CONNECT_FAILED,
    Holder,
    JumpSock,
    connect_blocking,
    load_paramiko,
)
from rosnet_tui.core.ssh.known_hosts import key_fingerprint
from rosnet_tui.core.ssh.options import RelayRoute, SshOptions

TUNNEL_FAILURES = ("relay", "down", "other_host", "not_sshd", "timeout")


@dataclass
class TunnelState:
    up: bool
    failure: str | None      # None or one of TUNNEL_FAILURES
    detail: str
    fingerprint: str | None = None   # the key that answered at the port, when one did


def _probe(opts: SshOptions | None, route: RelayRoute, port: int, own: set[bytes],
           deadline: float, holder: Holder) -> TunnelState:
    paramiko = load_paramiko()

    relay = Peer(name=route.host, ssh_user=route.user, ssh_port=route.port)
    conn = connect_blocking(opts, relay, deadline, holder)
    if conn.transport is None:
        return TunnelState(False, "relay", f"the relay {route.host}: {conn.result.detail}")
    rt = conn.transport
    try:
        try:
            chan = rt.open_channel("direct-tcpip", ("127.0.0.1", port), ("127.0.0.1", 0),
                                   timeout=max(deadline - time.monotonic(), 0.05))
        except paramiko.ChannelException as exc:
            if exc.code == CHANNEL_CONNECT_FAILED:
                return TunnelState(False, "down", f"nothing answers at 127.0.0.1:{port} on "
                                                  f"{route.host}: the tunnel is down")
            return TunnelState(False, "relay", f"{route.host} does not let {route.user} open "
                                               f"127.0.0.1:{port} ({exc.text or exc.code})")
        t = paramiko.Transport(JumpSock(chan, rt))
        holder.transport = t
        left = max(deadline - time.monotonic(), 0.05)
        t.banner_timeout = t.handshake_timeout = left
        try:
            t.start_client(timeout=left)
            key = t.get_remote_server_key()
        except Exception as exc:  # noqa: BLE001 - not sshd there, or it said nothing in time
            if time.monotonic() >= deadline:
                return TunnelState(False, "timeout", f"no SSH handshake at 127.0.0.1:{port} on "
                                                     f"{route.host} within the timeout")
            return TunnelState(False, "not_sshd", f"127.0.0.1:{port} on {route.host} does not "
                                                  f"speak SSH: {str(exc) or type(exc).__name__}")
        fp = key_fingerprint(key.asbytes())
        if key.asbytes() in own:
            return TunnelState(True, None, f"127.0.0.1:{port} on {route.host} answers with this "
                                           f"machine's sshd key {fp}", fp)
        return TunnelState(False, "other_host", f"127.0.0.1:{port} on {route.host} answers with "
                                                f"a key that is not this machine's ({fp}): "
                                                "another component's tunnel, or a stale one", fp)
    except Exception as exc:  # noqa: BLE001 - the relay's connection died under us
        return TunnelState(False, "relay", f"the relay {route.host}: "
                                           f"{str(exc) or type(exc).__name__}")
    finally:
        holder.close()


async def probe_tunnel(opts: SshOptions | None, route: RelayRoute, port: int, own: set[bytes],
                       timeout: float) -> TunnelState:
    """Whether the relay's 127.0.0.1:*port* answers with one of the keys *own*; a verdict
    within *timeout* (+ a thread's wake-up), never an exception."""
    holder = Holder()
    deadline = time.monotonic() + timeout
    try:
        return await run_blocking(_probe, opts, route, port, own, deadline, holder,
                                  timeout=timeout + 0.3)
    except asyncio.TimeoutError:
        return TunnelState(False, "timeout", f"no answer through the relay {route.host} within "
                                             f"{timeout:.1f} s")
    finally:
        with contextlib.suppress(Exception):
            holder.close()
