"""Step 3, ROS 2 with a relay: SSH through the relay's tunnels. relay.tunnel (this component's
sshd reached through its own tunnel) and linux.ssh to a peer behind the relay (the relay or the
peer's tunnel in the way, never the peer's modem)."""

from __future__ import annotations

from collections.abc import Mapping

from rosnet_tui.core.advisor.engine import Hit, rule
from rosnet_tui.core.advisor.evidence import Evidence, behind_relay
from rosnet_tui.core.ssh.known_hosts import fingerprint_command

CHECK = "relay.tunnel"


@rule("relay.tunnel.down", "linux", (CHECK,),
      "this component's port on the relay does not lead to its sshd",
      "Peers reach this component's sshd only through its reverse tunnel on the relay: with the "
      "tunnel down (or another sshd at its port) no peer can SSH here, so pairing, the peers' "
      "checks and the technician's `ssh NAME` fail.",
      "Keep `rosnet-tui relay tunnel` running here (`--install-service` for a systemd unit); "
      "the relay's host key must be in known_hosts, and the relay's authorized_keys must let "
      "this key listen at its port.",
      "linux", "fail")
def _down(ev: Evidence) -> list[Hit]:
    if not ev.is_fail(CHECK):
        return []
    d = ev.data("relay.tunnel")
    relay, port, why = d.get("relay") or "the relay", d.get("port"), d.get("failure")
    if why == "peer":
        return _peers_turned_away(ev, d, relay, port)
    first = {
        "down": f"On {ev.me}: run `rosnet-tui relay tunnel` (it says on each try why the tunnel "
                "drops), or `rosnet-tui relay tunnel --install-service` to keep it as a service.",
        "other_host": f"On {relay}: see who listens at 127.0.0.1:{port} (`sudo ss -tlnp`); two "
                      "components must not share a port under [relay.tunnels], and a stale "
                      "session goes away within seconds with sshd's ClientAliveInterval (see "
                      "docs/SECURITY.md).",
        "not_sshd": f"On {relay}: another program holds 127.0.0.1:{port}; give this component "
                    "a free port under [relay.tunnels] on every component.",
        "relay": f"Fix SSH from {ev.me} to {relay} first: its host key in known_hosts (ssh "
                 f"to it once and compare the fingerprint) and a key it accepts.",
    }.get(str(why), f"Check that {relay} answers SSH from {ev.me}, then run "
                    "`rosnet-tui relay tunnel` here.")
    return [Hit(f"{ev.me}'s port {port} on {relay} does not lead to its sshd ({why}): no peer "
                f"can SSH to {ev.me} through the relay.",
                [first, "Then re-run the Linux step here, and on a peer (its `linux.ssh`)."],
                evidence=[f"{CHECK}: {d.get('detail') or why}"])]


def _peers_turned_away(ev: Evidence, d: Mapping, relay: str, port: object) -> list[Hit]:
    """The tunnel is up, but a peer gets nothing of this machine through it (from its side)."""
    bad = {n: st for n, st in (d.get("peers") or {}).items()
           if isinstance(st, Mapping) and st.get("up") is False}
    name, st = next(iter(bad.items()), ("a peer", {}))
    login = f"{ev.s.relay.ssh_user}@{relay}" if ev.s.relay.ssh_user else relay
    first = {
        "relay": f"On {name}: run `ssh {login}` once, compare the relay's host key and accept "
                 f"it; in the relay account's authorized_keys, {name}'s key needs "
                 f"permitopen=\"127.0.0.1:{port}\" (docs/SECURITY.md).",
        "other_host": f"On {relay}: see who listens at 127.0.0.1:{port} (`sudo ss -tlnp`); "
                      f"{name} may have another port for {ev.me} under [relay.tunnels]: the "
                      "settings must be the same on every component.",
    }.get(str(st.get("failure")), f"On {name}: `rosnet-tui check` there (its linux.ssh to "
                                  f"{ev.me}) says what the way through {relay} lacks.")
    return [Hit(f"{ev.me}'s tunnel on {relay} is up, but {', '.join(bad) or 'a peer'} cannot "
                f"reach {ev.me}'s sshd through it: pairing, sync and the peers' checks fail "
                "from there.",
                [first, "Then re-run the Linux step here."],
                evidence=[f"relay.tunnel from {n}: {x.get('detail')}" for n, x in bad.items()])]


@rule("linux.ssh.relay", "linux", ("linux.ssh",),
      "SSH to a peer behind the relay fails on the way through the relay",
      "A peer with a tunnel under [relay.tunnels] is reached through the relay: SSH to the "
      "relay, then the peer's port on the relay's loopback. Either the relay turns us away (its "
      "host key, our key, forwarding not allowed) or the peer's tunnel is down; its modem and "
      "address play no part.",
      "The relay: ssh to it once and compare its host key, and let our key open the tunnels' "
      "ports (permitopen). The tunnel: keep `rosnet-tui relay tunnel` running on the peer (its "
      "relay.tunnel check says why it is down).",
      "linux", "fail")
def _ssh_relay(ev: Evidence) -> list[Hit]:
    hits = []
    relay = ev.s.relay.host
    for name, st in (ev.data("linux.ssh").get("peers") or {}).items():
        why = st.get("failure") if isinstance(st, Mapping) else None
        if not behind_relay(ev, name) or why not in ("relay", "network", "timeout"):
            continue
        port = ev.s.relay.tunnels.get(name)
        if why == "relay":
            meaning = (f"SSH from {ev.me} to {name} goes through the relay {relay}, and the "
                       f"relay turned us away before {name} was reached.")
            login = f"{ev.s.relay.ssh_user}@{relay}" if ev.s.relay.ssh_user else relay
            actions = [f"Run `ssh {login}` once from {ev.me}: "
                       "compare the host key it shows with the relay's own "
                       f"(`{fingerprint_command(ev.s.relay.ssh_port or 22)}` there) and "
                       "accept it; install this key there if it asks for a password.",
                       f"In the relay account's ~/.ssh/authorized_keys this key's line must "
                       f"allow permitopen=\"127.0.0.1:{port}\" (docs/SECURITY.md)."]
        else:
            meaning = (f"{name}'s tunnel on the relay {relay} is down: nothing answers at the "
                       f"relay's 127.0.0.1:{port}, so SSH to {name} cannot get through.")
            actions = [f"On {name}: `rosnet-tui relay tunnel` (or with --install-service); its "
                       "relay.tunnel check says why the tunnel is down.",
                       f"Then re-run the Linux step on {ev.me}."]
        hits.append(Hit(meaning, actions, evidence=[f"linux.ssh {name}: {st.get('detail')}"]))
    return hits
