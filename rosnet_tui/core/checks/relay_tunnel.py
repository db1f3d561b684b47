"""relay.tunnel (ROS 2 with a relay, Linux step): this component's reverse tunnel on the relay
is up, and the peers reach this component's sshd through it.

- From here, as a peer would: the relay's 127.0.0.1:<port> answers with this machine's own sshd
  host key (:mod:`rosnet_tui.core.ssh.tunnel_probe`).
- From each peer's side, as the other checks run theirs (the round's peer agent over SSH): the
  peer logs in to the relay with its own keys, its own known_hosts checking the relay's key, and
  reads the key at that port (core/peer/tunnelproto.py); it must be this machine's. A peer the
  relay turns away cannot SSH here (pairing, sync, its checks), even with the tunnel up.
"""

from __future__ import annotations

import asyncio
import base64
import binascii
from typing import Any

from rosnet_tui.core.checks import CheckContext, check
from rosnet_tui.core.checks.probes.agents import (
    ZENOH_AGENT,
    peer_program_problem,
    peer_run,
    why_no_report,
)
from rosnet_tui.core.checks.probes.budget import budget
from rosnet_tui.core.checks.probes.peers import each_peer, ssh_peers
from rosnet_tui.core.config.settings_model import Peer
from rosnet_tui.core.exposure.outsider import parse_marked
from rosnet_tui.core.net.blocking import run_blocking
from rosnet_tui.core.peer import tunnelproto
from rosnet_tui.core.peer.commands import NO_INSTALL_EXIT
from rosnet_tui.core.results import Outcome, Status
from rosnet_tui.core.ssh.known_hosts import key_fingerprint
from rosnet_tui.core.ssh.options import RelayRoute, relay_route
from rosnet_tui.core.ssh.sshd_keys import SSHD_T_TIMEOUT_S, OwnKeys, own_host_keys
from rosnet_tui.core.ssh.tunnel_probe import probe_tunnel

WHY = {
    "down": "nothing answers there: `rosnet-tui relay tunnel` is not running here, or its "
            "link is down",
    "other_host": "another sshd answers there (another component's tunnel on the same port, or "
                  "a stale session on the relay)",
    "not_sshd": "something that is not sshd answers there",
    "relay": "the relay itself cannot be used",
    "timeout": "no answer in time",
}


async def _from_peer(ctx: CheckContext, peer: Peer, route: RelayRoute, port: int,
                     own: set[bytes], t: float) -> dict[str, Any]:
    """What *peer* gets at the relay's 127.0.0.1:*port*: ``up`` True (this machine's key),
    False (something else, ``failure`` says what), None (the peer's side could not run)."""
    res = await peer_run(ctx, peer, ZENOH_AGENT, "tunnel",
                         [route.host, str(route.port), route.user, str(port), f"{t * 0.7:.1f}"],
                         timeout=t * 0.95, connect_timeout=t * 0.45, tcp_timeout=ctx.timeout_s,
                         needs_install=True)
    problem = peer_program_problem(res, peer)
    if problem is None and res.exit_status == NO_INSTALL_EXIT:
        problem = f"rosnet-tui is not installed on {peer.name} (its side needs its paramiko)"
    rep = None if problem else parse_marked(res.stdout, tunnelproto.MARK)
    if rep is None:
        return {"up": None, "failure": None, "fingerprint": None,
                "detail": problem or f"no report from {peer.name} "
                                     f"({why_no_report(res)})"}
    key = rep.get("key")
    if isinstance(key, str) and key:
        try:
            blob = base64.b64decode(key, validate=True)
        except (binascii.Error, ValueError):
            blob = b""
        fp = key_fingerprint(blob) if blob else None
        if blob in own:
            return {"up": True, "failure": None, "fingerprint": fp,
                    "detail": f"{peer.name} reaches this machine's sshd ({fp}) through the relay"}
        return {"up": False, "failure": "other_host", "fingerprint": fp,
                "detail": f"{peer.name} finds a key that is not this machine's ({fp}) at "
                          f"127.0.0.1:{port} on {route.host}"}
    why = rep.get("failure")
    why = why if why in tunnelproto.FAILURES else "relay"
    return {"up": False, "failure": why, "fingerprint": None,
            "detail": f"{peer.name}: {str(rep.get('detail') or why)[:300]}"}


@check("relay.tunnel", "linux", "This component's SSH tunnel answers on the relay", 2.0, ros=2,
       switch="relay")
async def check_relay_tunnel(ctx: CheckContext) -> Outcome:
    s = ctx.settings
    route = relay_route(s.relay)
    port = route.tunnel_port(s.this.name) if route is not None else None
    if route is None or port is None:
        return Outcome(Status.SKIP, f"no tunnel for {s.this.name or 'this component'} under "
                                    "[relay.tunnels]: its peers reach it directly")
    data: dict[str, Any] = {"relay": route.host, "port": port}
    try:   # sshd -T (as root) or the config files: bounded, off the event loop
        mine = await run_blocking(own_host_keys, ctx.paths.sshd_dir,
                                  timeout=SSHD_T_TIMEOUT_S + 1.0)
    except asyncio.TimeoutError:
        mine = OwnKeys(source="`sshd -T` gave no answer in time")
    own = set(mine.keys)
    if not own:
        data.update(up=None, failure="own_keys")
        return Outcome(Status.WARN, "this machine's sshd host keys cannot be read "
                                    f"({mine.words()}): whose sshd answers on the relay "
                                    "cannot be told", [mine.words()], data)
    t = budget(ctx, "relay.tunnel")
    peers = ssh_peers(s)
    here, there = await asyncio.gather(
        probe_tunnel(ctx.ssh, route, port, own, min(ctx.timeout_s, t * 0.9)),
        each_peer(peers, lambda p: _from_peer(ctx, p, route, port, own, t * 0.9)))
    got = {p.name: st for p, st in zip(peers, there, strict=True)}
    data.update(up=here.up, failure=here.failure, fingerprint=here.fingerprint,
                detail=here.detail, peers=got)
    evidence = [f"ssh {route.user}@{route.host}, then 127.0.0.1:{port} there: {here.detail}",
                f"compared with {mine.words()}"]
    evidence += [f"from {n}: {st['detail']}" for n, st in got.items()]
    where = f"127.0.0.1:{port} on {route.host}"
    if not here.up:
        return Outcome(Status.FAIL, f"the tunnel at {where} does not reach this machine: "
                                    f"{WHY.get(here.failure or '', here.detail)}", evidence, data)
    bad = [n for n, st in got.items() if st["up"] is False]
    if bad:
        data["failure"] = "peer"
        first = got[bad[0]]
        return Outcome(Status.FAIL, f"the tunnel at {where} is up, but {', '.join(bad)} cannot "
                                    f"reach this machine through it: {first['detail']}",
                       evidence, data)
    reached = [n for n, st in got.items() if st["up"]]
    if peers and not reached:
        return Outcome(Status.WARN, f"the tunnel at {where} leads to this machine's sshd, but no "
                                    "peer could test it from its side: "
                                    + "; ".join(st["detail"] for st in got.values()),
                       evidence, data)
    by = (f"; {', '.join(reached)} reach{'es' if len(reached) == 1 else ''} it through the "
          "relay" if reached else "; no peer has an SSH user to test it from its side")
    return Outcome(Status.PASS, f"the relay {route.host} leads to this machine's sshd at "
                                f"127.0.0.1:{port}{by}", evidence, data)
