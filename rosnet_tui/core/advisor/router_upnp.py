"""Step 2 (Router/modem): the rules that read ``router.upnp``, the modem's own word over UPnP IGD,
PCP or NAT-PMP: a forward it could make for us, one it gives another machine, carrier-grade NAT
in its own answer. (ROS 1's range, which no protocol maps, is said by the check itself: it skips
with the manual and DMZ paths.)
"""

from __future__ import annotations

from rosnet_tui.core.advisor.engine import Hit, rule
from rosnet_tui.core.advisor.evidence import Evidence, join_and

_PROTO = {"upnp": "UPnP IGD", "pcp": "PCP", "natpmp": "NAT-PMP"}


def _speaks(d) -> str:
    return join_and(_PROTO.get(str(p), str(p)) for p in d.get("protocols") or []) or "UPnP"


def _ports(ports) -> str:
    return join_and(f"TCP {p}" for p in ports or [])


@rule("router.upnp.conflict", "router", ("router.upnp",),
      "the modem forwards a port this component needs to another machine",
      "Another machine on the LAN holds the forward (made by hand, or asked for over UPnP by a "
      "program there): traffic for this component goes to it instead.",
      "Remove that forward in the modem's page (or stop the program asking for it), or choose "
      "another port for every component.",
      "router", "fail")
def _conflict(ev: Evidence) -> list[Hit]:
    d = ev.data("router.upnp")
    rows = d.get("conflicts") or []
    if not rows:
        return []
    c = rows[0]
    held = join_and(f"TCP {x.get('port')} to {x.get('internal_client')} ('{x.get('description')}')"
                    for x in rows)
    return [Hit(f"The modem {d.get('gateway')} forwards {held}: another machine, not {ev.me} "
                f"({ev.my_local_ip()}). Connections meant for {ev.me} end there.",
                [f"In the modem's page (port forwarding / UPnP list), remove the forward of TCP "
                 f"{c.get('port')} to {c.get('internal_client')}, or stop the program on that "
                 "machine that asks for it; then `rosnet-tui router map` here.",
                 "Or give this network another port (zenoh_port under [ros], the same on every "
                 "component) and forward that one."],
                evidence=[f"router.upnp: {held}"])]


@rule("router.upnp.cgnat", "router", ("router.upnp",),
      "the modem itself reports no public address, or a shared (100.64/10) one",
      "The modem has no public address of its own: the provider's carrier-grade NAT sits in "
      "front of it, so it refuses forwards, and none could be reached from the internet anyway.",
      "Make a component with a public address the master (ROS 2), run a router on a public "
      "server, or ask the provider for a public IP.",
      "isp", "fail")
def _cgnat(ev: Evidence) -> list[Hit]:
    d = ev.data("router.upnp")
    if d.get("cgnat") is not True:
        return []
    ip = d.get("external_ip")
    said = (f"reports {ip}, an address of the carriers' shared range 100.64.0.0/10"
            if ip else "reports no public address at all")
    return [Hit(f"The modem {d.get('gateway')} answers {_speaks(d)} but {said} on its internet "
                "side: carrier-grade NAT. It refuses forwards (that is how it answers "
                "`rosnet-tui router map`), and no forward on it could be reached from the "
                "internet.",
                ["Under ROS 2 the master is only the hub the routers link to: make a component "
                 "with a public address (a home or office line) the master.",
                 "Or run a Zenoh router on a small public server (VPS) and point every "
                 "component's router at it.",
                 "Or ask the provider for a public IP on this line (its networking department; "
                 "some sell it as an option)."],
                evidence=[f"router.upnp: external address {ip!r} ({d.get('wan')})"])]


@rule("router.upnp.missing", "router", ("router.upnp",),
      "the modem offers to forward ports itself, and the needed forward is missing",
      "The modem speaks UPnP IGD, PCP or NAT-PMP: it can make the forward this component needs "
      "on request, with no web page to find.",
      "Run `rosnet-tui router map` (it shows what it asks for and waits for your yes); undo with "
      "`rosnet-tui undo`.",
      "router", "warn")
def _missing(ev: Evidence) -> list[Hit]:
    d = ev.data("router.upnp")
    if d.get("cgnat") is True or d.get("conflicts") or not d.get("missing"):
        return []
    missing = _ports(d.get("missing"))
    proto = _PROTO.get(str(d.get("protocol")), "UPnP")
    return [Hit(f"The modem {d.get('gateway')} speaks {_speaks(d)} and does not forward "
                f"{missing} to {ev.me} yet: it can make that forward itself, on request.",
                [f"`rosnet-tui router map` asks it ({proto}) to forward {missing} to "
                 f"{ev.my_local_ip()}, with a lease; it shows the request and waits for your "
                 "yes (`--yes` in scripts). The wizard's Router step offers the same (m).",
                 "`rosnet-tui undo` (or `router unmap`) removes it again; the sync service "
                 "renews its lease.",
                 "Or forward it by hand in the modem's page, as the Router step describes."],
                evidence=[f"router.upnp: {missing} missing; the modem speaks {_speaks(d)}"])]
