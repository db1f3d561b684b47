"""relay.router (issue 30): the relay's Zenoh router answers by name with mutual TLS, with this
component's fleet certificate, and its certificate names the relay. Skipped without a relay.

One Zenoh session as this component's router opens it (a real one, eclipse-zenoh, with this
component's key); when it fails, a plain TCP connect and a standard-library TLS handshake say why
(nothing there, the port dropped, the relay's certificate naming another host or from another CA,
this component's certificate refused).
"""

from __future__ import annotations

import time
from typing import Any

from rosnet_tui.core.checks import CheckContext, check
from rosnet_tui.core.checks.probes.budget import budget
from rosnet_tui.core.checks.probes.ros2 import dial_router
from rosnet_tui.core.config.paths import default_config_dir
from rosnet_tui.core.net.blocking import run_blocking
from rosnet_tui.core.results import Outcome, Status
from rosnet_tui.core.ros import fleet_tls, ros2, tls_handshake
from rosnet_tui.core.ssh.connection import resolve_ipv4

HINTS = {"refused": "is `rosnet-tui relay serve` running there?",
         "timeout": "is TCP {port} open on the relay (its provider's firewall) and the relay up?",
         "unreachable": "no route to that address",
         "not_zenoh": "something answers on that port, but no Zenoh session with this "
                      "component's certificate"}


@check("relay.router", "ros", "The relay's Zenoh router answers by name with mutual TLS", 1.0,
       ros=2, switch="relay")
async def check_relay_router(ctx: CheckContext) -> Outcome:
    s = ctx.settings
    if not s.relayed:
        return Outcome(Status.SKIP, "skipped: no relay in the settings ([relay] host)", [], {})
    t = budget(ctx, "relay.router")
    deadline = time.monotonic() + t - 0.1
    name, port = s.relay.host, s.relay.zenoh_port
    endpoint = ros2.relay_endpoint(s)
    paths = fleet_tls.tls_paths(default_config_dir())
    data: dict[str, Any] = {"role": "master" if s.is_master else "member",
                            "endpoint": endpoint, "address": None,
                            "reachable": False, "failure": None,
                            "tls": tls_handshake.local_state(s, paths)}
    ev: list[str] = []
    addrs, err = await resolve_ipv4(name, min(1.0, t * 0.25))
    if not addrs:
        data["failure"] = "resolve"
        return Outcome(Status.FAIL, f"the relay's name {name} does not resolve here ({err}): "
                                    "give it a DNS record, or add it to /etc/hosts", ev, data)
    data["address"] = addrs[0]
    ev.append(f"{name} resolves to {addrs[0]}")
    kind, words, info = await dial_router(addrs[0], port, endpoint, t, deadline, ev,
                                   " with this component's certificate")
    data["failure"] = kind
    if kind is not None:
        hint = HINTS.get(kind, "").format(port=port)
        if kind == "not_zenoh":   # TCP answered: name what TLS refused
            problem, hint = await run_blocking(
                tls_handshake.handshake, addrs[0], port, name, paths,
                max(0.2, min(1.0, deadline - time.monotonic())), "relay",
                timeout=max(0.3, min(1.2, deadline - time.monotonic() + 0.2)))
            data["tls"]["handshake"] = problem
            ev.append(f"TLS handshake with {name} ({addrs[0]}:{port}): {hint}")
        return Outcome(Status.FAIL, f"no Zenoh router of the relay at {endpoint} ({addrs[0]}): "
                                    f"{words}" + (f"; {hint}" if hint else ""), ev, data)
    data.update(reachable=True, router_zid=(info or {}).get("zid"),
                router_version=(info or {}).get("version"))
    ver = f" ({data['router_version']})" if data.get("router_version") else ""
    ev.append(f"Zenoh router {data['router_zid']}{ver} answers at {endpoint} with mutual TLS")
    if data["tls"].get("problem") == "expiring":
        return Outcome(Status.WARN, f"the relay's Zenoh router{ver} answers at {endpoint}, but "
                                    f"{tls_handshake.PROBLEM_WORDS['expiring']}", ev, data)
    return Outcome(Status.PASS, f"the relay's Zenoh router{ver} answers at {endpoint} "
                                f"({addrs[0]}) and took this component's certificate", ev, data)

