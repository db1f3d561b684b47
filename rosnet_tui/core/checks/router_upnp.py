"""Step 2, Router/modem: ``router.upnp``, what the modem itself says about the forward we need.

Asked over UPnP IGD, PCP or NAT-PMP (the default gateway only, all at once, bounded well under the
check's timeout): pass when the forward the settings call for exists and points at this machine;
warn when the modem offers forwarding but the forward is missing (``rosnet-tui router map`` makes
it); fail when the port is forwarded to another machine; skip when no modem answers, or when
nothing needs mapping (a ROS 2 member). A ROS 2 check: ROS 1 needs a range, which no protocol
maps (the wizard's m and ``router map`` say so, with the manual and DMZ paths).
``router.port_open`` still proves reachability from outside.
"""

from __future__ import annotations

import asyncio
import time
from typing import Any

from rosnet_tui.core.checks import CheckContext, check
from rosnet_tui.core.checks.probes.budget import budget
from rosnet_tui.core.net.blocking import run_blocking
from rosnet_tui.core.results import Outcome, Status
from rosnet_tui.core.upnp import forwards as fw
from rosnet_tui.core.upnp.modem import Modem, find_modem
from rosnet_tui.core.upnp.wire import ModemError, label

MAP_COMMAND = "rosnet-tui router map"


def _ask(timeout: float, notes: list[str]) -> Modem | None:
    return find_modem(timeout, notes=notes)


def _inspect(modem: Modem, wanted: list[fw.Wanted], state_dir, deadline: float) -> dict[str, Any]:
    """What the modem holds for *wanted* (blocking: runs in a thread)."""
    out: dict[str, Any] = {"present": [], "missing": [], "conflicts": [], "forwards": [],
                           "detail": {}}
    recorded = fw.recorded_here(modem, state_dir)
    if modem.can_list:
        try:
            listed = modem.forwards(deadline)
        except ModemError as exc:
            listed = None
            out["error"] = str(exc)
        for f in listed or []:
            if f.internal_client == modem.local_ip:
                out["forwards"].append({**f.to_json(), "ours": fw.is_ours(f, modem,
                                                                          set(recorded))})
        for w in wanted:
            if listed is not None:
                f = next((x for x in listed if x.protocol == w.protocol
                          and x.external_port == w.port), None)
            else:
                try:
                    f = modem.forward_of(w.protocol, w.port, deadline)
                except ModemError as exc:
                    out["error"] = str(exc)
                    out["missing"].append(w.port)
                    continue
            if f is None:
                out["missing"].append(w.port)
            elif f.internal_client != modem.local_ip or f.internal_port != w.port:
                out["conflicts"].append({"port": w.port, "internal_client": f.internal_client,
                                         "description": f.description})
            else:
                out["present"].append(w.port)
                out["detail"][w.port] = (f"{f.protocol} {w.port} -> {f.internal_client}:"
                                         f"{f.internal_port} '{f.description}'"
                                         + (f", {f.lease_s} s of lease left" if f.lease_s
                                            else ", no expiry"))
        return out
    now = time.time()
    for w in wanted:
        m = recorded.get((w.protocol, w.port))
        ends = float(m.get("renewed_at", 0)) + int(m.get("lease_s", 0)) if m else 0.0
        if m and now < ends:
            out["present"].append(w.port)
            out["detail"][w.port] = (f"{w.protocol} {w.port}: made by rosnet-tui over "
                                     f"{label(str(m.get('via')))}, lease until "
                                     f"{time.strftime('%H:%M', time.localtime(ends))}")
        else:
            out["missing"].append(w.port)
    return out


@check("router.upnp", "router", "The modem forwards our port itself (UPnP IGD, NAT-PMP, PCP)", 1.5,
       ros=2)
async def check_upnp(ctx: CheckContext) -> Outcome:
    s = ctx.settings
    data: dict[str, Any] = {"protocol": None, "protocols": [], "gateway": None,
                            "external_ip": None, "wan": "unknown", "cgnat": False, "needed": [],
                            "present": [], "missing": [], "conflicts": [], "forwards": [],
                            "can_list": False, "range_needed": False, "tried": []}
    if not ctx.upnp:
        return Outcome(Status.SKIP, "skipped: the modem was not asked (UPnP turned off for this "
                                    "run)", [], data)
    need = fw.needs(s)
    lasting = [w for w in need.forwards if not w.temporary]
    data["needed"] = [w.port for w in lasting]
    if need.note:
        return Outcome(Status.SKIP, f"skipped: {need.note}", [], data)
    if need.refusal:  # ROS 1: whatever the modem speaks, a range cannot be asked for
        data["range_needed"] = True
        ip = s.this.local_ip or "this machine's local IP"
        return Outcome(Status.SKIP, "skipped: ROS 1 needs TCP 1024-65000 and no protocol maps a "
                                    "range (UPnP IGD, PCP and NAT-PMP forward one port per "
                                    f"request): forward the range to {ip} by hand in the modem's "
                                    f"page, or make {ip} the DMZ host", [need.refusal], data)
    total = budget(ctx, "router.upnp") * 0.9
    start = time.monotonic()
    notes: list[str] = []
    try:
        modem = await run_blocking(_ask, min(total * 0.5, 2.0), notes, timeout=total * 0.6)
    except asyncio.TimeoutError:
        modem = None
        notes.append("the modem did not finish answering in time")
    data["tried"] = list(notes)
    if modem is None:
        return Outcome(Status.SKIP, "skipped: no modem answered UPnP IGD, PCP or NAT-PMP (the "
                                    "default gateway was asked); forward by hand in its web page",
                       notes, data)
    data.update(protocol=modem.protocol, protocols=list(modem.protocols), gateway=modem.gateway,
                external_ip=modem.external_ip, wan=fw.wan_kind(modem.external_ip),
                can_list=modem.can_list)
    evidence = [f"{modem.describe()}; this machine is {modem.local_ip} towards it"]
    if modem.external_ip is not None:
        evidence.append(f"the modem's external address: {modem.external_ip or '(none)'}")
    evidence += [n for n in notes if "error" in n or "refused" in n]
    deadline = start + total
    try:
        got = await run_blocking(_inspect, modem, lasting, ctx.paths.state_dir, deadline,
                                 timeout=max(deadline - time.monotonic(), 0.2))
    except asyncio.TimeoutError:
        return Outcome(Status.FAIL, "the modem answered, but did not finish listing its forwards "
                                    "in time", evidence, data)
    for k in ("present", "missing", "conflicts", "forwards"):
        data[k] = got[k]
    if got.get("error"):
        evidence.append(f"listing the forwards: {got['error']}")
    evidence += list(got["detail"].values())
    if got["conflicts"]:
        c = got["conflicts"][0]
        return Outcome(Status.FAIL, f"the modem forwards TCP {c['port']} to {c['internal_client']}, "
                                    f"another machine, not to this one ({modem.local_ip})",
                       evidence + [f"TCP {x['port']} -> {x['internal_client']} "
                                   f"'{x['description']}'" for x in got["conflicts"]], data)
    if not got["missing"]:
        ports = ", ".join(f"TCP {p}" for p in got["present"])
        return Outcome(Status.PASS, f"{ports} forwarded to this machine ({modem.local_ip}) by the "
                                    f"modem ({label(modem.protocol)})", evidence, data)
    missing = ", ".join(f"TCP {p}" for p in got["missing"])
    if data["wan"] in ("none", "shared"):
        data["cgnat"] = True
        return Outcome(Status.WARN, f"{missing} is not forwarded, and the modem "
                                    f"{fw.wan_words(modem.external_ip)}: carrier-grade NAT, a "
                                    "forward would be refused", evidence, data)
    how = "" if modem.can_list else f" (as far as rosnet-tui knows: {label(modem.protocol)} " \
                                     "cannot list forwards)"
    return Outcome(Status.WARN, f"{missing} is not forwarded{how}; the modem offers forwarding "
                                f"({label(modem.protocol)}): `{MAP_COMMAND}` asks it",
                   evidence, data)
