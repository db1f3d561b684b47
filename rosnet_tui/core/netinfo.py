"""This machine's network facts: interfaces, local IPv4 address, default gateway, MAC."""

from __future__ import annotations

import ipaddress
import socket
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import netifaces
import psutil

if TYPE_CHECKING:
    from rosnet_tui.core.settings_model import Settings

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


def detect_local_net() -> LocalNet:
    """The LAN this machine uses to reach the internet: default-route interface first."""
    gateway, ifname = default_gateway()
    if ifname and not is_overlay(ifname):
        ip, mask = interface_ipv4(ifname)
        if ip:
            return LocalNet(ifname, ip, gateway, interface_mac(ifname), mask)
    stats = psutil.net_if_stats()
    for name, addrs in psutil.net_if_addrs().items():
        if is_overlay(name) or not stats.get(name) or not stats[name].isup:
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
# Only these blocks count as a LAN (private, link-local, unique local): an interface on a public
# block, or on the carrier's shared 100.64.0.0/10, has the internet or strangers as neighbours.
LAN_BLOCKS = tuple(ipaddress.ip_network(n) for n in (
    "10.0.0.0/8", "172.16.0.0/12", "192.168.0.0/16", "169.254.0.0/16", "fe80::/10", "fc00::/7"))


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


def is_lan(net: ipaddress.IPv4Network | ipaddress.IPv6Network) -> bool:
    """True when *net* lies inside a private, link-local or unique-local block."""
    return any(net.version == b.version and net.subnet_of(b)  # type: ignore[arg-type]
               for b in LAN_BLOCKS)


def _prefix_len(netmask: str) -> int | None:
    try:
        return bin(int(ipaddress.ip_address(netmask.split("/")[0]))).count("1")
    except ValueError:
        return None


def lan_networks() -> list[str]:
    """The networks of this machine's interface addresses that are a LAN (see LAN_BLOCKS):
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
            if is_lan(net):
                nets.append(str(net))
    return collapse(nets)
