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
