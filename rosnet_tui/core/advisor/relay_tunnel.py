"""Step 3, ROS 2 with a relay: the rule that reads relay.tunnel (this component's sshd reached
through its reverse tunnel on the relay)."""

from __future__ import annotations

from rosnet_tui.core.advisor.engine import Hit, rule
from rosnet_tui.core.advisor.evidence import Evidence

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
