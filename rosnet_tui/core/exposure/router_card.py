"""The router card: the exact values to type into the modem's web page for the Router step.

Forward TCP (and, if needed, UDP) 1024-65000 to this component's local IP, or make it the DMZ
host; reserve that IP for this machine's MAC by DHCP; what to do per connection type; and the
exposure warning. A data structure the UI shows as a panel, plus a plain-text or Markdown rendering
that fits 80 columns (to print, photograph, or hand to a network administrator).
"""

from __future__ import annotations

import textwrap
from dataclasses import dataclass, field

from rosnet_tui.core.config.settings_model import PORT_MAX, PORT_MIN, Settings
from rosnet_tui.core.exposure import firewall
from rosnet_tui.core.exposure.forwarding import ports_to_forward
from rosnet_tui.core.net import netinfo
from rosnet_tui.core.net.netinfo import LocalNet
from rosnet_tui.core.ros.rosbridge import forward_needed

PORT_RANGE = f"{PORT_MIN}-{PORT_MAX}"


@dataclass(frozen=True)
class ForwardRule:
    protocol: str          # "TCP" | "UDP"
    external_ports: str    # "1024-65000" or "22"
    internal_ip: str
    internal_ports: str
    required: bool
    note: str


@dataclass
class RouterCard:
    component: str
    role: str
    connection: str
    interface: str
    local_ip: str
    mac: str
    gateway: str
    modem_page: str
    forwards: list[ForwardRule]
    dmz_host: str
    reservation_ip: str
    reservation_mac: str
    connection_notes: list[str]
    exposure_warning: list[str]
    warnings: list[str] = field(default_factory=list)   # e.g. the settings and the machine disagree
    profile: str = "remote"   # a LAN profile (office, portable) forwards nothing
    missing: list[str] = field(default_factory=list)    # what we could not find, and how to
    verify: list[str] = field(default_factory=list)
    relay: list[str] = field(default_factory=list)     # under a relay: what the relay needs


def _detect(settings: Settings) -> LocalNet:
    """This machine's facts, for the interface the settings name (or the default route's)."""
    iface = settings.this.interface
    if not iface:
        return netinfo.detect_local_net()
    ip, mask = netinfo.interface_ipv4(iface)
    gw, gw_iface = netinfo.default_gateway()
    return LocalNet(iface, ip, gw if gw_iface == iface else "", netinfo.interface_mac(iface), mask)


def _connection_notes(conn: str, ip: str, mac: str, page: str) -> list[str]:
    where = f"the modem's web page ({page})" if page else "the modem's web page"
    if conn == "corporate":
        return [
            "Corporate or university network: the routers belong to the IT department. Hand "
            "this card to the network administrator and ask for:",
            f"- forwarding of TCP {PORT_RANGE} (or a DMZ host) to {ip or 'this machine'};",
            f"- a fixed address for this machine (reservation of {ip or 'its IP'} for MAC "
            f"{mac or 'see above'});",
            "- a fixed public address, and whether a firewall upstream blocks these ports.",
            "A cabled office LAN may need a separate Wi-Fi router for the robot.",
        ]
    if conn == "telecom":
        return [
            f"Mobile hotspot or tethered phone: the settings are in {where} or the hotspot's "
            "app, when the carrier allows forwarding at all (many allow it only on some modems).",
            "Many carriers put customers behind carrier-grade NAT (a WAN address in "
            "100.64.0.0/10): forwarding cannot work there. Check the ISP step's CGNAT result "
            "first, and ask the carrier's networking department, not first-line support.",
            "The public IP may change on every reconnect: keep the address sync running.",
        ]
    return [
        f"Home connection: open {where} and log in (the password is often on a sticker under "
        "the modem). Look for a section named Port forwarding, Virtual servers, NAT or "
        "Firewall; DHCP reservations are usually under LAN or DHCP.",
    ]


def relay_needs(settings: Settings) -> list[str]:
    """What the relay needs ([relay] host set), in the card's words: empty without a relay."""
    r = settings.relay
    if not settings.relayed:
        return []
    return [f"Every component's router dials the relay {r.host}; nothing is forwarded for ROS "
            "on any modem. The relay needs:",
            f"- a public address (a small VPS), its name {r.host} resolving to it from every "
            "component (DNS, or each one's hosts file);",
            f"- TCP {r.zenoh_port} open to the internet (its provider's firewall): its Zenoh "
            "router, mutual TLS, fleet certificates only;",
            f"- SSH open (TCP {r.ssh_port}, keys only): `relay apply` sets it up, and the "
            "tunnels of [relay.tunnels] end there;",
            "- `rosnet-tui relay serve` running there (its systemd unit)."]


def _exposure(settings: Settings) -> list[str]:
    """What the forwards expose, and to whom, for the settings in force: ROS 2 with or without
    mutual TLS, master or member; ROS 1 with or without the peers-only firewall."""
    ssh = "- SSH, when port 22 is forwarded: keys only (PasswordAuthentication no)."
    off = "- Remove the forwarding when the robot is not in use."
    bp = settings.rosbridge.port
    bridge = ([f"- rosbridge (TCP {bp}) takes any client that reaches it, like an unprotected "
               "master: forward it only while web clients need it."]
              if forward_needed(settings) else [])
    if settings.relayed:
        return [f"Under the relay: this component's router dials out to {settings.relay.host} "
                "and listens on no address of the internet, so nothing of ROS is exposed on "
                "this modem.", *bridge, ssh]
    if settings.ros2:
        port = settings.ros.zenoh_port
        if not settings.is_master:
            return ["ROS 2 member: no ROS port is forwarded here (its router connects out to the "
                    "master's), so nothing of ROS is exposed on this modem.", *bridge, ssh]
        if settings.ros.security == "mtls":
            head = (f"Mutual TLS ([ros] security = \"mtls\"): the router on TCP {port} opens a "
                    "session only for a certificate signed by the fleet's CA; anyone else who "
                    "reaches the port is refused at the handshake. Restricting the forward to "
                    "your members' public IPs, where the modem can, narrows it further.")
        else:
            head = (f"[ros] security = \"none\": rmw_zenoh has no authentication of its own, so "
                    f"whoever reaches TCP {port} joins the ROS network and can command the "
                    "robot. Turn security back on (set-up: Security on, mutual TLS), or at least "
                    "restrict the forward to your members' public IPs if the modem can.")
        return [head, *bridge, ssh, off]

    sources = [f"{p.public_ip} ({p.name})" for p in settings.peers if p.public_ip]
    allow = (f"allow only the peers' public IPs: {', '.join(sources)}" if sources
             else "allow only the peers' public IPs")
    if firewall.wanted(settings):
        head = (ros1_exposure(settings) + " That holds for SSH and TCP " + PORT_RANGE + "; a "
                "DMZ host also opens the ports below 1024, which the firewall leaves alone.")
        return [head, f"- If the modem can restrict a rule to source addresses, {allow} there "
                      "too.", *bridge, ssh, off]
    return [
        ros1_exposure(settings) + " Forwarding every port exposes SSH too, when port 22 is "
        "forwarded or with a DMZ host. Set security back on (set-up: Security on) for the "
        "peers-only firewall.",
        f"- If the modem can restrict a rule to source addresses, {allow}.",
        *bridge, ssh, off,
    ]


def ros1_exposure(settings: Settings) -> str:
    """Who can command a ROS 1 component through its forwards, for the settings in force: the
    one sentence of the router card, the Router step and the advisor."""
    head = (f"ROS 1 has no authentication: the ROS master ({settings.ros.port}) and every node "
            "obey anyone who reaches them.")
    if firewall.wanted(settings):
        return head + (" With [ros] security = \"firewall\" the peers-only firewall (Linux "
                       "step, `rosnet-tui firewall apply`) lets in only the peers, this "
                       "machine's LAN, the addresses you allow ([firewall] allow) and the SSH "
                       "session that loaded it; until it is loaded, anyone on the internet.")
    return head + " [ros] security = \"none\": no firewall, so that is the whole internet."


def build_router_card(settings: Settings, net: LocalNet | None = None) -> RouterCard:
    """The card for this component; *net* defaults to what netinfo reads from the interface."""
    net = net if net is not None else _detect(settings)
    t = settings.this
    ip = t.local_ip or net.local_ip
    warnings, missing = [], []
    if t.local_ip and net.local_ip and t.local_ip != net.local_ip:
        warnings.append(
            f"The settings say this component's local IP is {t.local_ip}, but "
            f"{net.interface or 'the interface'} has {net.local_ip} now. The modem must forward "
            "to the address the machine really has: update the settings (or the reservation) "
            "first.")
    if not ip:
        missing.append("Local IP: unknown. Connect to the modem's network, then run "
                       "'ip -4 addr' and use the address on that interface.")
    if not net.mac:
        iface = net.interface or t.interface or "IFACE"
        missing.append(f"MAC address: not found. Read it with 'ip link show {iface}' (the "
                       "value after link/ether).")
    if not net.gateway:
        missing.append("Modem address: unknown (no default route). It is usually the "
                       "'default via' address in 'ip route'.")
    page = f"http://{net.gateway}/" if net.gateway else ""
    to = ip or "(local IP)"

    forwards = [ForwardRule(f.protocol, f.ports, to, f.ports, f.required, f.why)
                for f in ports_to_forward(settings)]
    role = "ROS master" if settings.is_master else "ROS member"
    if t.profile != "remote":             # a LAN profile: nothing to forward, nothing exposed
        return RouterCard(
            component=t.name, role=role, connection=t.connection,
            interface=net.interface or t.interface, local_ip=ip, mac=net.mac,
            gateway=net.gateway, modem_page=page, forwards=[], dmz_host="", reservation_ip=to,
            reservation_mac=net.mac or "(MAC, see below)",
            connection_notes=[
                f"{t.profile.capitalize()} profile: every component is on the same LAN, so "
                "nothing needs forwarding and nothing is exposed to the internet. A phone "
                "hotspot cannot forward at all; here it does not need to."],
            exposure_warning=[], warnings=warnings, missing=missing, profile=t.profile,
            verify=["The outside port test is skipped on this profile; the Linux step tests "
                    "the LAN (ping, SSH and " + ("each member's connection by name to the "
                                                 "master's router port" if settings.ros2 else
                                                 "a chat by name, both ways") + ")."])
    return RouterCard(
        component=t.name, role=role, connection=t.connection, interface=net.interface or t.interface,
        local_ip=ip, mac=net.mac, gateway=net.gateway, modem_page=page, forwards=forwards,
        dmz_host="" if settings.ros2 else to, reservation_ip=to, reservation_mac=net.mac or "(MAC, see below)",
        connection_notes=_connection_notes(t.connection, ip, net.mac, page),
        exposure_warning=_exposure(settings), warnings=warnings, missing=missing,
        verify=_verify(settings), relay=relay_needs(settings))


def _verify(settings: Settings) -> list[str]:
    if settings.relayed:
        r = settings.relay
        return [f"Under the relay nothing is forwarded here. The Router step tests the relay's "
                f"TCP {r.zenoh_port} from outside ({r.host}); relay.router (ROS step) opens "
                "a session there with this component's certificate."]
    if settings.ros2 and not settings.is_master:
        return ["ROS 2 member: nothing to forward here (no DMZ either); its router connects out "
                "to the master's. The port test is skipped on a member."]
    if settings.ros2:
        return [f"Then run the Router step's checks: TCP {settings.ros.zenoh_port} tested from "
                "outside must reach the router (ROS 2 needs no other port)."]
    return [f"Then run the Router step's checks: a listener on the test port "
            f"({settings.probe.port}) and an outside port check must report Open. Repeat "
            "with other ports in the range."]


# --------------------------------------------------------------------------- rendering
def _wrap(text: str, width: int, indent: str = "") -> list[str]:
    hang = indent + ("  " if text.startswith("- ") else "")
    return textwrap.wrap(text, width, initial_indent=indent, subsequent_indent=hang,
                         break_on_hyphens=False, break_long_words=True) or [indent]


def render_router_card(card: RouterCard, *, markdown: bool = False, width: int = 80) -> str:
    """The card as plain text (or Markdown), no line longer than *width* (80 by default)."""
    return (_render_markdown if markdown else _render_text)(card, width)


def _render_text(card: RouterCard, width: int) -> str:
    out: list[str] = []
    title = f"ROUTER CARD: {card.component or 'this component'} ({card.role}, " \
            f"{card.connection} connection)"
    out += _wrap(title, width)
    out.append("=" * min(width, max(len(x) for x in out)))
    facts = [("Modem web page", card.modem_page or "unknown (see below)"),
             ("Interface", card.interface or "unknown"),
             ("Local IP", card.local_ip or "unknown"),
             ("MAC address", card.mac or "unknown")]
    for k, v in facts:
        out += _wrap(f"{k + ':':<16}{v}", width)
    for w in card.warnings:
        out.append("")
        out += _wrap("WARNING: " + w, width)
    if card.relay:
        out += ["", "The relay: what it needs"]
        for n in card.relay:
            out += _wrap(n, width, "   ")
    if not card.forwards:
        out += ["", f"1. Port forwarding: none on the {card.profile} LAN"]
        out += _wrap("Nothing to forward: the components reach each other on the LAN.", width,
                     "   ")
        return _render_text_tail(card, width, out)
    out += ["", "1. Port forwarding (firewall / NAT / virtual servers)"]
    head = f"   {'Proto':<6}{'Outside ports':<15}{'To local IP':<17}{'Ports':<12}"
    out.append(head.rstrip())
    for r in card.forwards:
        need = "required" if r.required else "optional"
        row = f"   {r.protocol:<6}{r.external_ports:<15}{r.internal_ip:<17}{r.internal_ports:<12}"
        out.append((row + need).rstrip())
        out += _wrap(r.note, width, " " * 9)
    if card.dmz_host:  # ROS 2 forwards one port: no DMZ
        out += _wrap(f"Or, instead of these rules: DMZ host = {card.dmz_host} (forwards every "
                     "port, below 1024 too).", width, "   ")
    return _render_text_tail(card, width, out)


def _render_text_tail(card: RouterCard, width: int, out: list[str]) -> str:
    out += ["", "2. DHCP reservation (LAN / DHCP settings)"]
    out += _wrap(f"Reserve IP {card.reservation_ip} for MAC {card.reservation_mac}"
                 f"{f' ({card.component})' if card.component else ''}. Without it the "
                 "forwarding breaks when the modem hands this machine another address.",
                 width, "   ")
    out += ["", f"3. Your connection ({card.connection})"]
    for n in card.connection_notes:
        out += _wrap(n, width, "   ")
    if card.exposure_warning:
        out += ["", "!! Exposure"]
    for n in card.exposure_warning:
        out += _wrap(n, width, "   ")
    if card.missing:
        out += ["", "Not found on this machine"]
        for n in card.missing:
            out += _wrap("- " + n, width, "   ")
    out.append("")
    for n in card.verify:
        out += _wrap(n, width)
    return "\n".join(line.rstrip() for line in out) + "\n"


def _render_markdown(card: RouterCard, width: int) -> str:
    out: list[str] = []
    out += _wrap(f"## Router card: {card.component or 'this component'} ({card.role}, "
                 f"{card.connection} connection)", width)
    out.append("")
    out += ["| | |", "|---|---|",
            f"| Modem web page | {card.modem_page or 'unknown'} |",
            f"| Interface | {card.interface or 'unknown'} |",
            f"| Local IP | {card.local_ip or 'unknown'} |",
            f"| MAC address | {card.mac or 'unknown'} |"]
    for w in card.warnings:
        out.append("")
        out += _wrap(f"**Warning:** {w}", width)
    if card.relay:
        out += ["", "### The relay: what it needs", ""]
        for n in card.relay:
            out += _wrap(n, width)
    if card.forwards:
        out += ["", "### 1. Port forwarding", "",
                "| Proto | Outside ports | To local IP | Ports | Need |", "|---|---|---|---|---|"]
        for r in card.forwards:
            need = "required" if r.required else "optional"
            out.append(f"| {r.protocol} | {r.external_ports} | {r.internal_ip} | "
                       f"{r.internal_ports} | {need} |")
        out.append("")
        if card.dmz_host:  # ROS 2 forwards one port: no DMZ
            out += _wrap(f"Or, instead of these rules: DMZ host = {card.dmz_host} (forwards "
                         "every port, below 1024 too).", width)
    else:
        out += ["", f"### 1. Port forwarding: none on the {card.profile} LAN", ""]
        out += _wrap("Nothing to forward: the components reach each other on the LAN.", width)
    out += ["", "### 2. DHCP reservation", ""]
    out += _wrap(f"Reserve IP {card.reservation_ip} for MAC {card.reservation_mac}. Without it "
                 "the forwarding breaks when the modem hands this machine another address.", width)
    out += ["", f"### 3. Your connection ({card.connection})", ""]
    for n in card.connection_notes:
        out += _wrap(n, width)
    if card.exposure_warning:
        out += ["", "### Exposure", ""]
    for n in card.exposure_warning:
        out += _wrap(n, width)
    if card.missing:
        out += ["", "### Not found on this machine", ""]
        for n in card.missing:
            out += _wrap("- " + n, width)
    out.append("")
    for n in card.verify:
        out += _wrap(n, width)
    return "\n".join(line.rstrip() for line in out) + "\n"
