"""Step 2 (Router/modem): the rules that read the router.* checks.

Table 1 of the procedure (router.listener with router.port_open, its three ranked causes),
the local IP (including the link-down rule, whose symptom shows in step 1), the test port,
and security.exposed (what an open port exposes).
"""

from __future__ import annotations

from collections.abc import Mapping

from rosnet_tui.core.advisor.engine import Hit, rule
from rosnet_tui.core.advisor.evidence import (
    FORWARD_RANGE,
    Evidence,
    cgnat_text,
    join_and,
    offline_ids,
)
from rosnet_tui.core.advisor.ranking import Cause, local_ip_moved, nat_seen, table1_causes
from rosnet_tui.core.config.settings_model import PORT_MAX
from rosnet_tui.core.exposure.router_card import ros1_exposure


# ---- link (its symptom is step 1: nothing gets out) -----------------------------------------
@rule("router.local_ip.no_link", "isp", ("router.local_ip",),
      "no local address or no default route",
      "This machine is not on its LAN: the link is down (cable, Wi-Fi), or DHCP gave it no "
      "address or no gateway. Nothing else can work until it is.",
      "Connect the cable or Wi-Fi, check `ip addr` / `ip route`, renew DHCP; then start again "
      "from step 1.",
      "router", "fail")
def _no_link(ev: Evidence) -> list[Hit]:
    d = ev.data("router.local_ip")
    if not d or not ev.is_fail("router.local_ip") or (d.get("local_ip") and d.get("gateway")):
        return []
    known = d.get("interface") or ev.s.this.interface
    iface = known or "the network interface"
    if not d.get("local_ip"):
        meaning = (f"{ev.me} has no IPv4 address on {iface}: the link is down (cable unplugged, "
                   "Wi-Fi off or not joined) or the modem's DHCP did not answer.")
    else:
        meaning = (f"{ev.me} has the address {d['local_ip']} on {iface} but no default route: "
                   "it cannot reach the modem as its gateway (DHCP incomplete, or a static "
                   "address without a gateway).")
    ids = ["router.local_ip"] + (offline_ids(ev) if ev.is_fail("isp.internet") else [])
    if known:
        acts = [f"Check the link: `ip addr show {iface}` must show an address and state UP; "
                "reconnect the cable or the Wi-Fi (`nmcli device status`).",
                f"Renew the address: `sudo nmcli device reapply {iface}` (NetworkManager) or "
                f"`sudo dhclient -v {iface}`; `ip route` must then show a default route via "
                "the modem."]
    else:   # no interface to name: the commands that list them, and the rest in words
        acts = ["Find the interface that connects to the modem: `nmcli device status` (or "
                "`ip addr`) lists them; it must show an address and state UP. Reconnect the "
                "cable or the Wi-Fi.",
                "Renew its address with NetworkManager's `sudo nmcli device reapply` followed by "
                "the interface's name (or dhclient's `sudo dhclient -v` and the name); `ip route` "
                "must then show a default route via the modem."]
    return [Hit(meaning, acts + ["Then run the checks again from step 1."],
                check_ids=ids,
                evidence=[f"router.local_ip: address {d.get('local_ip') or 'none'}, gateway "
                          f"{d.get('gateway') or 'none'} on {iface}"])]


# ---- Table 1: the port test -----------------------------------------------------------------
T1 = "table1.listener_up_closed"


def _t1(ev: Evidence) -> tuple[dict, dict] | None:
    """(listener data, port_open data) when both checks have a verdict."""
    ld, pd = ev.data("router.listener"), ev.data("router.port_open")
    if "listening" not in ld or "test_port_open" not in pd:
        return None
    return ld, pd


def _t1_port(ev: Evidence) -> int:
    pd, ld = ev.data("router.port_open"), ev.data("router.listener")
    return int(pd.get("test_port") or ld.get("port") or ev.s.probe.port)


def _t1_where(ev: Evidence) -> str:
    pd = ev.data("router.port_open")
    return f"{pd.get('public_ip') or ev.my_public_ip()}:{_t1_port(ev)}"


def _other_open_ports(ev: Evidence) -> list[int]:
    pd = ev.data("router.port_open")
    tp = _t1_port(ev)
    return [p["port"] for p in pd.get("ports") or []
            if isinstance(p, Mapping) and p.get("reachable") and p.get("port") != tp]


def _causes(ev: Evidence) -> dict[str, tuple[int, Cause]]:
    """Table 1's causes by key: (rank, the cause with its observations)."""
    return {c.key: (i, c) for i, c in enumerate(table1_causes(ev))}


def _t1_hit(ev: Evidence, key: str, meaning: str, acts: list[str], ids: list[str],
            more: list[str] | None = None) -> Hit:
    """One cause's finding: the observations appended to its meaning, its rank as order."""
    order, cause = _causes(ev)[key]
    said = cause.sentence()
    return Hit(meaning + (" " + said if said else ""), acts, check_ids=ids, order=order,
               goto_step=cause.step,
               evidence=["router.listener: listening", "router.port_open: Closed",
                         *cause.evidence(), *(more or [])])


def _listener_up_closed(ev: Evidence) -> bool:
    t = _t1(ev)
    return bool(t and t[0]["listening"] is True and t[1]["test_port_open"] is False)


_T1_CHECKS = ("router.listener", "router.port_open")


@rule("table1.open", "router", _T1_CHECKS,
      "listener up, checker says Open",
      "Port forwarding works: a connection from the internet reached the listener on this "
      "component.",
      "Go on to step 3 (Linux).",
      "linux", "info")
def _t1_open(ev: Evidence) -> list[Hit]:
    t = _t1(ev)
    if not t or t[0]["listening"] is not True or t[1]["test_port_open"] is not True:
        return []
    return [Hit(f"Port forwarding works: a connection from outside reached the listener on "
                f"{_t1_where(ev)}.", ["Go on to step 3 (Linux)."],
                evidence=["router.listener: listening", "router.port_open: Open"])]


@rule("table1.no_listener", "router", _T1_CHECKS,
      "listener down, checker says Closed",
      "Nothing listened on the test port, so Closed says nothing about the forwarding yet.",
      "Start the listener (`nc -l PORT`, or re-run the Router step, whose listener check starts "
      "one) and test the port again.",
      "router", "fail")
def _t1_no_listener(ev: Evidence) -> list[Hit]:
    t = _t1(ev)
    if not t or t[0]["listening"] is not False or t[1]["test_port_open"] is not False:
        return []
    port = _t1_port(ev)
    acts = [f"Start a listener on port {port} (`nc -l {port}`, or re-run the Router step: its "
            "listener check starts one for the test) and test the port again."]
    ids = list(_T1_CHECKS)
    pf = ev.data("router.port_free")
    if pf.get("in_use"):
        proc = pf.get("process") or "another program"
        pid = f" (pid {pf['pid']})" if pf.get("pid") else ""
        acts.insert(0, f"Port {port} is taken by {proc}{pid}, so our listener could not start: "
                       f"choose another test port between 1024 and {PORT_MAX} (port = N under "
                       f"[probe] in the settings), or stop {proc} if it should not run.")
        ids.append("router.port_free")
    return [Hit(f"Nothing was listening on port {port} when the checker tried {_t1_where(ev)}, "
                "so its Closed says nothing about the forwarding yet.", acts, check_ids=ids,
                evidence=["router.listener: not listening", "router.port_open: Closed"])]


@rule("table1.no_listener_open", "router", _T1_CHECKS,
      "listener down, checker says Open",
      "Our listener is not up, yet the port answered from outside: another program owns the "
      "port, and the forwarding works for it.",
      "Pick a free test port and test again; make sure the program on the port should be "
      "reachable from the internet.",
      "router", "warn")
def _t1_no_listener_open(ev: Evidence) -> list[Hit]:
    t = _t1(ev)
    if not t or t[0]["listening"] is not False or t[1]["test_port_open"] is not True:
        return []
    port = _t1_port(ev)
    proc = ev.data("router.port_free").get("process")
    owner = proc or "another program"
    return [Hit(f"Our listener is not up, yet {_t1_where(ev)} answered from outside: {owner} "
                f"owns port {port}, and the forwarding delivers to it.",
                [f"Choose a free test port (port = N under [probe], between 1024 and "
                 f"{PORT_MAX}) and re-run the Router step.",
                 f"Check that {proc or 'the program on that port'} is meant to be reachable "
                 "from the whole internet."],
                check_ids=[*_T1_CHECKS, "router.port_free"],
                evidence=["router.listener: not listening", "router.port_open: Open"])]


@rule(f"{T1}.port_in_use", "router", _T1_CHECKS,
      "listener up, checker says Closed - cause (a)",
      "Cause (a): the port may be used by another service (here or on the modem itself), so the "
      "test never reaches our listener.",
      f"Try another port between 1024 and {PORT_MAX} (port = N under [probe]); stop the program "
      "holding the port if it should not run.",
      "router", "fail", group=T1)
def _t1_cause_port(ev: Evidence) -> list[Hit]:
    if not _listener_up_closed(ev):
        return []
    port = _t1_port(ev)
    pf = ev.data("router.port_free")
    ids = list(_T1_CHECKS)
    if pf.get("in_use"):
        proc = pf.get("process") or "another program"
        pid = f" (pid {pf['pid']})" if pf.get("pid") else ""
        meaning = (f"Port {port} is also held by {proc}{pid}, so the checker's connection may "
                   "not reach our listener.")
        acts = [f"Try another port between 1024 and {PORT_MAX}: set port = N under [probe] and "
                "re-run the Router step.",
                f"Or stop {proc}{pid} if it should not be running."]
        ids.append("router.port_free")
    else:
        meaning = (f"Port {port} may be used by another service, on this machine or on the "
                   "modem itself (its web page, VPN or remote-management port), so the test "
                   "does not reach our listener.")
        if pf.get("in_use") is False and _causes(ev)["port_in_use"][0] == 2:
            meaning += " Least likely here."
        acts = [f"Try another port between 1024 and {PORT_MAX}: set port = N under [probe] "
                "and re-run the Router step; try two or three ports."]
    return [_t1_hit(ev, "port_in_use", meaning, acts, ids)]


@rule(f"{T1}.isp", "router", _T1_CHECKS,
      "listener up, checker says Closed - cause (b)",
      "Cause (b): the provider or the network administrator blocks incoming connections before "
      "they reach the modem (carrier-grade NAT is the hard form of it).",
      "Back to the ISP step: ask the provider (networking department) or the administrator to "
      "allow port forwarding, and for a public IP.",
      "isp", "fail", group=T1)
def _t1_cause_isp(ev: Evidence) -> list[Hit]:
    if not _listener_up_closed(ev):
        return []
    nat = nat_seen(ev)
    ids = list(_T1_CHECKS)
    more: list[str] = []
    if nat.kind == "inner":
        outer = nat.hop or "the outer router"
        meaning = (f"The outer router ({outer}) may belong to the provider: then only the "
                   "provider can forward through it (or give this line a public IP, or switch "
                   "their box to bridge mode).")
        acts = [f"If you cannot log in to {outer}, ask the provider to forward TCP "
                f"{FORWARD_RANGE} to your router's WAN address{f' ({nat.wan_ip})' if nat.wan_ip else ''}"
                ", to make it the DMZ host, or to put their box in bridge mode.",
                "Back to step 1 (ISP) once they answer."]
        ids.append("isp.cgnat")
    elif nat.kind:
        meaning, acts, more = cgnat_text(ev)
        ids.append("isp.cgnat")
    else:
        c = ev.s.this.connection
        who = {"corporate": "the network administrator", "telecom": "the carrier",
               "home": "the provider"}.get(c, "the provider")
        meaning = (f"{who[0].upper() + who[1:]} may block incoming connections before they reach "
                   "the modem, whatever the modem is set to.")
        if c == "corporate":
            acts = [f"Ask the network administrator to allow incoming TCP (and UDP) "
                    f"{FORWARD_RANGE} to {ev.my_local_ip()} on their firewall, or to set it as "
                    "the DMZ host; they usually configure the router as well."]
        elif c == "telecom":
            acts = ["Call the carrier and ask for the networking department (first-line support "
                    "rarely knows port forwarding): is forwarding allowed on this plan and "
                    "modem, and is the public IP really yours?"]
        else:
            acts = ["Ask the provider whether incoming connections are blocked on this line, "
                    "and how to lift it (some need a setting in the customer portal)."]
        acts.append("Back to step 1 (ISP) once they answer.")
    return [_t1_hit(ev, "isp", meaning, acts, ids, more)]


@rule(f"{T1}.forwarding", "router", _T1_CHECKS,
      "listener up, checker says Closed - cause (c)",
      "Cause (c): the modem's port forwarding is missing or points at the wrong local address.",
      f"Back to the Router step: forward TCP {FORWARD_RANGE} (or DMZ) to this component's local "
      "IP, and reserve that IP by DHCP.",
      "router", "fail", group=T1)
def _t1_cause_forwarding(ev: Evidence) -> list[Hit]:
    if not _listener_up_closed(ev):
        return []
    li = ev.data("router.local_ip")
    local = ev.my_local_ip()
    ids = list(_T1_CHECKS)
    moved = local_ip_moved(ev)
    nat = nat_seen(ev)
    answer = next((p.get("answer") for p in ev.data("router.port_open").get("ports") or []
                   if isinstance(p, Mapping) and p.get("port") == _t1_port(ev)), None)
    if moved:
        old, local = moved
        meaning = (f"The modem forwards to {old}, but {ev.me}'s local IP is now {local} "
                   f"(on {li.get('interface') or 'its interface'}): the forwarding points at the "
                   "old address, so connections from outside go nowhere.")
        acts = [f"In the modem's web page, change the forwarding (or DMZ host) from {old} to "
                f"{local}.",
                f"Reserve {local} for {ev.me} by DHCP (a reservation for its MAC address) so "
                "it does not move again.",
                f"Set local_ip = \"{local}\" under [this] in the settings, then re-run the "
                "Router step."]
        ids.append("router.local_ip")
    elif nat.kind == "inner":
        gw = li.get("gateway") or "the router this component is plugged into"
        outer = nat.hop or "the outer router"
        wan = f" ({nat.wan_ip})" if nat.wan_ip else ""
        meaning = (f"Two routers of your own: {ev.me}'s router ({gw}, e.g. a travel router) is "
                   f"plugged into another router ({outer}). Connections from outside that the "
                   f"outer router forwards stop at the inner one, which does not forward them "
                   f"on to {ev.me}.")
        acts = [f"On the inner router ({gw}, {ev.me}'s gateway): forward TCP (and UDP) "
                f"{FORWARD_RANGE} to {local}, or make {local} its DMZ host - or switch it to "
                f"bridge / access-point mode, so that {ev.me} sits directly on the outer "
                "router's network.",
                f"On the outer router ({outer}): forward the same range to the inner router's "
                f"WAN address{wan} (or make it the DMZ host); after bridge mode, to {ev.me}'s "
                "new local IP instead.",
                f"Reserve {local} for {ev.me} by DHCP, then re-run the Router step."]
        ids.append("isp.cgnat")
    else:
        meaning = (f"The modem does not seem to forward port {_t1_port(ev)} to {ev.me} "
                   f"({local}): the forwarding may be missing, cover other ports, or point at "
                   "another address.")
        if answer == "other":
            meaning = (f"Port {_t1_port(ev)} is forwarded, but to another machine or service "
                       f"than {ev.me} ({local}).")
        elif answer == "unreachable":
            meaning = (f"The modem forwards port {_t1_port(ev)} to a local address where no "
                       f"machine answers, not to {ev.me} ({local}): an old address of "
                       f"{ev.me}, or a typo.")
        others = _other_open_ports(ev)
        if others:
            meaning += (f" Ports {join_and(map(str, others))} do get through, so the path to the "
                        "modem works: the forwarding rule itself is incomplete.")
        acts = [f"In the modem's web page (firewall / NAT / port forwarding), forward TCP (and "
                f"UDP if needed) {FORWARD_RANGE} to {local}, or set the DMZ host to {local}.",
                f"Reserve {local} for {ev.me} by DHCP so the forwarding keeps pointing at it.",
                "Save, restart the modem if it asks, and re-run the Router step."]
    return [_t1_hit(ev, "forwarding", meaning, acts, ids)]


# ---- the router's other checks ---------------------------------------------------------------
@rule("router.local_ip.differs", "router", ("router.local_ip",),
      "local IP differs from the forwarded one",
      "The DHCP server gave this component a new local address; forwarding or DMZ set for the "
      "old one now goes nowhere.",
      "Point the forwarding at the new local IP, reserve it by DHCP, update local_ip in the "
      "settings.",
      "router", "warn", superseded_by=(f"{T1}.forwarding",))
def _local_differs(ev: Evidence) -> list[Hit]:
    d = ev.data("router.local_ip")
    moved = local_ip_moved(ev) if d.get("differs") or d.get("changed") else None
    if not moved:
        return []
    old, now = moved
    was = "as in the settings" if d.get("differs") else "as on the last run"
    return [Hit(f"{ev.me}'s local IP is now {now} (on {d.get('interface') or '?'}, gateway "
                f"{d.get('gateway') or '?'}), not {old} {was}: a forwarding or DMZ "
                f"entry for {old} no longer reaches it.",
                [f"In the modem's web page, change the forwarding (or DMZ host) from {old} to "
                 f"{now}.",
                 f"Reserve {now} for {ev.me} by DHCP (a reservation for its MAC address).",
                 f"Set local_ip = \"{now}\" under [this] in the settings and apply the hosts "
                 "entries again (`rosnet-tui hosts apply`): its own name must map to "
                 f"{now}."],
                severity=ev.sev("router.local_ip", "warn"),
                evidence=[f"router.local_ip: {now}, settings {old}"])]


@rule("router.port_in_use", "router", ("router.port_free",),
      "test port used by another program",
      "Another program holds the test port, so our listener cannot use it.",
      "Choose another test port (port under [probe]) or stop that program.",
      "router", "warn", superseded_by=(f"{T1}.port_in_use", "table1.no_listener",
                                       "table1.no_listener_open"))
def _port_in_use(ev: Evidence) -> list[Hit]:
    d = ev.data("router.port_free")
    if not d.get("in_use"):
        return []
    port, proc = d.get("port") or ev.s.probe.port, d.get("process") or "another program"
    pid = f" (pid {d['pid']})" if d.get("pid") else ""
    return [Hit(f"Port {port} is in use by {proc}{pid}, so the test listener cannot use it.",
                [f"Choose another test port between 1024 and {PORT_MAX}: port = N under [probe] "
                 "in the settings.",
                 f"Or stop {proc}{pid} if it should not run."],
                severity=ev.sev("router.port_free", "warn"),
                evidence=[f"router.port_free: {port} held by {proc}{pid}"])]


@rule("router.port_open.partial", "router", ("router.port_open",),
      "test port Open, other listened ports Closed",
      "The forwarding covers only part of what ROS needs: some ports with a listener get "
      "through, others do not.",
      f"Forward the whole range {FORWARD_RANGE} (plus 22 for SSH), or use DMZ.",
      "router", "fail")
def _port_partial(ev: Evidence) -> list[Hit]:
    d = ev.data("router.port_open")
    if d.get("test_port_open") is not True:
        return []
    closed = [p["port"] for p in d.get("ports") or []
              if isinstance(p, Mapping) and p.get("listener") and p.get("reachable") is False]
    if not closed:
        return []
    local = ev.my_local_ip()
    acts = []
    if 22 in closed:
        acts.append(f"SSH (22) is outside {FORWARD_RANGE}: forward TCP 22 to {local} as well "
                    "(or set the DMZ host).")
    if any(p != 22 for p in closed):
        acts.append(f"Forward the whole range TCP {FORWARD_RANGE} to {local}: ROS picks random "
                    "ports for its nodes, so a partial range breaks some topics and not others.")
    return [Hit(f"Port {d.get('test_port')} is Open, but {join_and(map(str, closed))} "
                f"{'is' if len(closed) == 1 else 'are'} Closed although something listens "
                "there: the forwarding covers only part of what is needed.", acts,
                severity=ev.sev("router.port_open", "warn"),
                evidence=[f"router.port_open: closed with a listener: {join_and(map(str, closed))}"])]


@rule("router.port_open.no_verdict", "router", ("router.port_open",),
      "the port checker gave no verdict",
      "The outside test could not be made (port checker unreachable or refusing), so Table 1 "
      "cannot be read.",
      "Fix the internet connection, check port_check_url, or give a peer an ssh_user so it "
      "tests from its side.",
      "router", "warn", superseded_by=("isp.no_internet.dns", "isp.no_internet.http"))
def _port_no_verdict(ev: Evidence) -> list[Hit]:
    d = ev.data("router.port_open")
    if not d or "test_port_open" not in d or d.get("test_port_open") is not None:
        return []
    return [Hit("No outside test of the port was possible: neither the port checker "
                f"({ev.s.probe.port_check_url}) nor a peer gave a verdict.",
                ["Check that the internet works (ISP step).",
                 "Check port_check_url under [probe]: it must speak the echoip protocol "
                 "(GET /port/N); `rosnet-tui probe-server` runs one you can host.",
                 "Or set ssh_user for a peer: the port is then tested from the peer itself."],
                severity=ev.sev("router.port_open", "warn"),
                evidence=["router.port_open: no verdict"])]


# ---- security -------------------------------------------------------------------------------
@rule("security.exposed", "router", ("router.port_open",),
      "ports reachable from the internet (forwarding or DMZ in use)",
      "Forwarding exposes this component: SSH to password guessing, and the ROS master (ROS 1 "
      "has no authentication) to whoever the peers-only firewall lets in, or to the whole "
      "internet without it.",
      "SSH keys only (`PasswordAuthentication no`), restrict source addresses on the modem to "
      "the peers, forward only while needed.",
      "router", "security")
def _exposed(ev: Evidence) -> list[Hit]:
    if ev.s.ros2:
        return []  # ROS 2: one port, security.zenoh_exposed
    d = ev.data("router.port_open")
    reach = [p["port"] for p in d.get("ports") or [] if isinstance(p, Mapping) and p.get("reachable")]
    if d.get("test_port_open") is True and d.get("test_port") and d["test_port"] not in reach:
        reach.append(d["test_port"])
    if not reach:
        return []
    me = ev.me
    parts = [f"Ports of {me} are reachable from the whole internet ({join_and(map(str, reach))}), "
             "not only from the peers."]
    acts = []
    if 22 in reach:
        parts.append("SSH (22) is open to everyone: password-guessing bots find it within hours.")
    else:
        parts.append("With the whole range (or DMZ) forwarded, SSH and every other service here "
                     "are as exposed as the test port.")
    if ev.s.ros.port in reach or ev.s.is_master:
        parts.append(ros1_exposure(ev.s))
    acts.append(f"On {me}: accept SSH keys only - in /etc/ssh/sshd_config set "
                "`PasswordAuthentication no` and `KbdInteractiveAuthentication no`, then "
                "`sudo systemctl reload ssh` (install your keys first: `ssh-copy-id`).")
    peers = [f"{p.name} {p.public_ip}" for p in ev.s.peers if p.public_ip]
    acts.append("Where the modem allows it, restrict the forwarding to the peers' public "
                f"addresses{' (' + join_and(peers) + ')' if peers else ''}.")
    acts.append("Forward only while the robot is in use, and switch DMZ/forward-all off "
                "afterwards; for the ROS master, restricting who can connect (or a VPN) is the "
                "only protection there is.")
    return [Hit(" ".join(parts), acts,
                evidence=[f"router.port_open: reachable from outside: {join_and(map(str, reach))}"])]
