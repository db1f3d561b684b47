"""This machine's network facts: interfaces, local IPv4 address, default gateway, MAC."""

from __future__ import annotations

import ipaddress
import socket
import struct
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import netifaces
import psutil

from rosnet_tui.core.addresses import is_lan_network

if TYPE_CHECKING:
    from rosnet_tui.core.config.settings_model import Settings

# Overlay and virtual interfaces that are never the LAN the modem forwards to.
OVERLAY_PREFIXES = ("lo", "tailscale", "zt", "hnet", "docker", "br-", "veth", "virbr", "wg", "tun")


@dataclass
class LocalNet:
    interface: str = ""
    local_ip: str = ""
    gateway: str = ""
    mac: str = ""
    netmask: str = ""


def is_overlay(ifname: str) -> bool:
    return ifname.startswith(OVERLAY_PREFIXES)


def default_gateway() -> tuple[str, str]:
    """(gateway IP, interface) of the IPv4 default route, or ("", "")."""
    try:
        gw = netifaces.gateways().get("default", {}).get(netifaces.AF_INET)
    except Exception:
        gw = None
    if gw:
        return gw[0], gw[1]
    return "", ""


def interface_ipv4(ifname: str) -> tuple[str, str]:
    """(first IPv4 address, netmask) of *ifname*, or ("", "")."""
    try:
        addrs = netifaces.ifaddresses(ifname).get(netifaces.AF_INET, [])
    except ValueError:
        return "", ""
    for a in addrs:
        if a.get("addr"):
            return a["addr"], a.get("netmask", "")
    return "", ""


def interface_mac(ifname: str) -> str:
    for a in psutil.net_if_addrs().get(ifname, []):
        if a.family == psutil.AF_LINK and a.address and a.address != "00:00:00:00:00:00":
            return a.address.lower()
    return ""


# ----------------------------------------------------------------------------- link state
# The kernel's operational state (RFC 2863) lags: a link whose carrier just came up reads "down"
# until the kernel's link watcher runs (up to ~1 s later), while it already carries traffic; and
# many LTE modems (wwan, ppp) and tunnels never report more than "unknown". So a link is judged
# by what carries traffic: switched on, and a carrier, or an address on a link that has no
# carrier of its own to report (point-to-point: ppp, raw-IP wwan, tun).

IFF_UP = 0x1
IFF_POINTOPOINT = 0x10
IFF_LOWER_UP = 0x10000                   # the carrier, as the link's flags carry it
POINT_TO_POINT_TYPES = {512, 519, 65534}  # ARPHRD_PPP, ARPHRD_RAWIP, ARPHRD_NONE (tun, wwan)
OPERSTATES = ("unknown", "notpresent", "down", "lowerlayerdown", "testing", "dormant", "up")


@dataclass(frozen=True)
class LinkFacts:
    """What the kernel says about one interface."""

    exists: bool
    switched_on: bool = False        # IFF_UP (`ip link set X up`)
    operstate: str = "unknown"       # one of OPERSTATES
    carrier: bool | None = None      # the carrier now (None: not known)
    point_to_point: bool = False     # ppp, wwan, tun: no carrier of their own to report
    has_ipv4: bool = False


@dataclass(frozen=True)
class LinkState:
    exists: bool
    up: bool
    why: str = ""     # what the verdict rests on, when "up" or "down" alone would not say it

    @property
    def word(self) -> str:
        """As the evidence shows it: "up", "DOWN (switched off)", "no such interface"."""
        if not self.exists:
            return "no such interface"
        word = "up" if self.up else "DOWN"
        return f"{word} ({self.why})" if self.why else word


def link_state_of(f: LinkFacts) -> LinkState:
    """Up or down, from the facts (see the note above)."""
    if not f.exists:
        return LinkState(False, False)
    if not f.switched_on:
        return LinkState(True, False, "switched off")
    if f.operstate == "dormant":
        return LinkState(True, False, "dormant: not joined or not authenticated yet")
    if f.operstate == "up":
        return LinkState(True, True)
    if f.operstate == "unknown":
        return LinkState(True, True, "state unknown, as modems and tunnels report")
    if f.carrier:   # the state catches up within a second
        return LinkState(True, True, "" if f.operstate in ("down", "lowerlayerdown")
                         else f"carrier, state {f.operstate}")
    if f.point_to_point and f.has_ipv4:
        return LinkState(True, True, f"point-to-point with an address, state {f.operstate}")
    if f.operstate == "notpresent":
        return LinkState(True, False, "device not present")
    return LinkState(True, False, "no carrier: cable unplugged, Wi-Fi off or modem disconnected")


_NLMSG = struct.Struct("=LHHLL")
_IFINFO = struct.Struct("=BxHiII")
_RTA = struct.Struct("=HH")
_RTM_NEWLINK, _RTM_GETLINK = 16, 18
_NLMSG_ERROR, _NLMSG_DONE = 2, 3
_IFLA_IFNAME, _IFLA_OPERSTATE, _IFLA_CARRIER = 3, 16, 33
_LINK_DUMP_LIMIT = 4096   # messages read at most (a bounded loop)


def route_netlink() -> socket.socket | None:
    """A raw rtnetlink socket (links, addresses, routes), or None where netlink is not available
    (not Linux, no permission)."""
    family = getattr(socket, "AF_NETLINK", None)
    if family is None:
        return None
    try:
        return socket.socket(family, socket.SOCK_RAW | socket.SOCK_CLOEXEC,
                             getattr(socket, "NETLINK_ROUTE", 0))
    except OSError:
        return None


def _netlink_links() -> dict[str, tuple[int, int, str | None, bool | None]] | None:
    """{name: (flags, type, operstate, carrier)} from the kernel's rtnetlink (the namespace this
    thread is in, which /sys may not show), or None where rtnetlink is not available."""
    sock = route_netlink()
    if sock is None:
        return None
    links: dict[str, tuple[int, int, str | None, bool | None]] = {}
    with sock:
        try:
            sock.settimeout(2.0)
            body = _IFINFO.pack(socket.AF_UNSPEC, 0, 0, 0, 0)
            sock.send(_NLMSG.pack(_NLMSG.size + len(body), _RTM_GETLINK, 0x301, 1, 0) + body)
            for _ in range(_LINK_DUMP_LIMIT):
                data = sock.recv(65536)
                off = 0
                while off + _NLMSG.size <= len(data):
                    length, mtype, _flags, _seq, _pid = _NLMSG.unpack_from(data, off)
                    if length < _NLMSG.size:
                        return links
                    if mtype in (_NLMSG_DONE, _NLMSG_ERROR):
                        return links if mtype == _NLMSG_DONE else None
                    if mtype == _RTM_NEWLINK:
                        name, link = _parse_link(data[off + _NLMSG.size:off + length])
                        if name:
                            links[name] = link
                    off += (length + 3) & ~3
        except OSError:
            return None
    return links


def _parse_link(msg: bytes) -> tuple[str, tuple[int, int, str | None, bool | None]]:
    _family, kind, _index, flags, _change = _IFINFO.unpack_from(msg, 0)
    name, operstate, carrier = "", None, None
    off = _IFINFO.size
    while off + _RTA.size <= len(msg):
        length, atype = _RTA.unpack_from(msg, off)
        if length < _RTA.size:
            break
        value = msg[off + _RTA.size:off + length]
        if atype == _IFLA_IFNAME:
            name = value.split(b"\0", 1)[0].decode(errors="replace")
        elif atype == _IFLA_OPERSTATE and value:
            operstate = OPERSTATES[value[0]] if value[0] < len(OPERSTATES) else "unknown"
        elif atype == _IFLA_CARRIER and value:
            carrier = bool(value[0])
        off += (length + 3) & ~3
    return name, (flags, kind, operstate, carrier)


def link_facts(ifname: str) -> LinkFacts:
    """The kernel's facts about *ifname* (rtnetlink; psutil's flags where there is none)."""
    has_ipv4 = bool(interface_ipv4(ifname)[0])
    links = _netlink_links()
    if links is not None:
        if ifname not in links:
            return LinkFacts(False)
        flags, kind, operstate, carrier = links[ifname]
        if carrier is None:   # a kernel without IFLA_CARRIER: the flags carry it
            carrier = bool(flags & IFF_LOWER_UP)
        return LinkFacts(True, bool(flags & IFF_UP), operstate or "unknown", carrier,
                         bool(flags & IFF_POINTOPOINT) or kind in POINT_TO_POINT_TYPES, has_ipv4)
    stats = psutil.net_if_stats().get(ifname)
    if stats is None:
        return LinkFacts(False)
    flags = set(getattr(stats, "flags", "").split(","))
    return LinkFacts(True, stats.isup or "up" in flags, "up" if stats.isup else "down", None,
                     "pointopoint" in flags, has_ipv4)


def link_state(ifname: str) -> LinkState:
    return link_state_of(link_facts(ifname))


def links_up() -> set[str]:
    """The names of the interfaces that are up (one look at the kernel for all of them)."""
    links = _netlink_links()
    if links is None:
        return {n for n, st in psutil.net_if_stats().items() if st.isup}
    up = set()
    for name, (flags, kind, operstate, carrier) in links.items():
        facts = LinkFacts(True, bool(flags & IFF_UP), operstate or "unknown",
                          bool(flags & IFF_LOWER_UP) if carrier is None else carrier,
                          bool(flags & IFF_POINTOPOINT) or kind in POINT_TO_POINT_TYPES,
                          bool(interface_ipv4(name)[0]))
        if link_state_of(facts).up:
            up.add(name)
    return up


def detect_local_net() -> LocalNet:
    """The LAN this machine uses to reach the internet: default-route interface first."""
    gateway, ifname = default_gateway()
    if ifname and not is_overlay(ifname):
        ip, mask = interface_ipv4(ifname)
        if ip:
            return LocalNet(ifname, ip, gateway, interface_mac(ifname), mask)
    up = links_up()
    for name, addrs in psutil.net_if_addrs().items():
        if is_overlay(name) or name not in up:
            continue
        for a in addrs:
            if a.family == socket.AF_INET and not ipaddress.ip_address(a.address).is_loopback:
                return LocalNet(name, a.address, "", interface_mac(name), a.netmask or "")
    return LocalNet()


def with_detected(settings: Settings, net: LocalNet | None = None) -> Settings:
    """A copy of *settings* whose blank local IP and interface come from this machine.

    For one run only: the settings file keeps what the user wrote. An interface is taken only
    when it is the one that holds the local IP.
    """
    t = settings.this
    if t.local_ip and t.interface:
        return settings
    net = net if net is not None else detect_local_net()
    local_ip, interface = t.local_ip, t.interface
    if not local_ip and net.local_ip:
        local_ip, interface = net.local_ip, interface or net.interface
    elif not interface and net.local_ip == local_ip:
        interface = net.interface
    return replace(settings, this=replace(t, local_ip=local_ip, interface=interface))


# --------------------------------------------------------------------------- this machine's LAN
def _net_text(net: ipaddress.IPv4Network | ipaddress.IPv6Network) -> str:
    """A network as nft lists it: one address without its /32 or /128."""
    return str(net.network_address) if net.num_addresses == 1 else str(net)


def collapse(entries: list[str]) -> list[str]:
    """Addresses and networks merged where they overlap or touch (nft refuses overlapping
    intervals in one set), IPv4 first, each family in order."""
    nets = [ipaddress.ip_network(e, strict=False) for e in entries]
    out: list[str] = []
    for version in (4, 6):
        fam = [n for n in nets if n.version == version]
        out += [_net_text(n) for n in ipaddress.collapse_addresses(fam)]  # type: ignore[arg-type]
    return out


def _prefix_len(netmask: str) -> int | None:
    try:
        return bin(int(ipaddress.ip_address(netmask.split("/")[0]))).count("1")
    except ValueError:
        return None


def lan_networks() -> list[str]:
    """The networks of this machine's interface addresses that are a LAN (addresses.is_lan_network:
    private, link-local or unique-local; a public block or the carriers' shared 100.64.0.0/10
    has the internet or strangers as neighbours):
    loopback and point-to-point links (ppp, wwan in raw-IP mode, VPN tunnels) left out, and so
    are networks of one address. Merged, IPv4 first."""
    import psutil

    try:
        stats, addrs = psutil.net_if_stats(), psutil.net_if_addrs()
    except OSError:
        return []
    nets: list[str] = []
    for name, items in addrs.items():
        flags = set(str(getattr(stats.get(name), "flags", "") or "").split(","))
        if "loopback" in flags or "pointopoint" in flags or name == "lo":
            continue
        for a in items:
            if a.family not in (socket.AF_INET, socket.AF_INET6) or not a.netmask:
                continue
            plen = _prefix_len(a.netmask)
            if plen is None:
                continue
            try:
                net = ipaddress.ip_interface(f"{a.address.split('%')[0]}/{plen}").network
            except ValueError:
                continue
            if net.num_addresses == 1 or net.network_address.is_loopback:
                continue
            if is_lan_network(net):
                nets.append(str(net))
    return collapse(nets)
