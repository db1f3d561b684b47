"""ROS 2 under a relay (issue 30): the rule that reads relay.router. When the relay's router does
not answer, every router-to-router path fails with it, so this comes first and names the relay
(not the master's router or modem, which carry nothing under a relay)."""

from __future__ import annotations

from rosnet_tui.core.advisor.engine import Hit, rule
from rosnet_tui.core.advisor.evidence import Evidence

ACTIONS = {
    "resolve": ["Give the relay's name a DNS record (or a line in /etc/hosts) pointing at its "
                "public address, on every component."],
    "refused": ["On the relay: run `rosnet-tui relay serve` (or start its service) and keep it "
                "running."],
    "timeout": ["Open TCP {port} on the relay (its own firewall and its provider's), and check "
                "that the relay is up."],
    "unreachable": ["Check the relay's address and this component's route to the internet."],
    "not_zenoh": ["The relay answers but takes no session with this component's certificate: "
                  "on the master, sign the relay's certificate again (`rosnet-tui relay "
                  "apply`); here, pair again if this component's certificate is from another CA "
                  "(`rosnet-tui ros pair --renew`)."],
}


@rule("relay.router.down", "router", ("relay.router", "router.port_open", "ros2.router",
                                      "ros2.graph", "ros2.pubsub_out", "ros2.pubsub_in"),
      "the relay's Zenoh router does not answer (ROS 2 under a relay)",
      "Under a relay every component's router, the master's included, links only to the relay's "
      "router: while it does not answer, no node on one site sees or hears the other.",
      "Make the relay's router answer: its name resolving, `rosnet-tui relay serve` running "
      "there, TCP zenoh_port open on it, its certificate signed by the fleet CA.",
      "ros", "fail")
def _relay_down(ev: Evidence) -> list[Hit]:
    d = ev.data("relay.router")
    if not (ev.s.ros2 and ev.s.relayed and ev.is_fail("relay.router")):
        return []
    failure = str(d.get("failure") or "")
    handshake = (d.get("tls") or {}).get("handshake")
    words = {"resolve": f"its name {ev.s.relay.host} does not resolve here",
             "refused": "the connection was refused: nothing listens there",
             "timeout": f"TCP {ev.s.relay.zenoh_port} got no answer",
             "unreachable": "there is no route to it",
             "not_zenoh": "it took no session with this component's certificate"
                          + (f" (TLS: {handshake})" if handshake else "")}.get(failure, failure)
    acts = [a.format(port=ev.s.relay.zenoh_port) for a in ACTIONS.get(failure, [])]
    ids = ["relay.router", *[c for c in ("router.port_open", "ros2.router", "ros2.graph",
                                         "ros2.pubsub_out", "ros2.pubsub_in") if ev.is_fail(c)]]
    return [Hit(f"The relay {ev.s.relay.host} ({d.get('endpoint')}) does not answer: {words}. "
                "Every ROS 2 link between the sites goes through it.",
                [*acts, "Then re-run the checks."], check_ids=ids,
                evidence=[f"relay.router: {failure or 'failed'}"])]
