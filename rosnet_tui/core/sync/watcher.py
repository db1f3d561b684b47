"""Watching this component's own addresses: local IP and default route (at once, through the
kernel's netlink notifications), and the public IP (polled, through
:func:`rosnet_tui.core.public_ip.find_public_ip`, which also keeps the public-IP history in the
state dir)."""

from __future__ import annotations

import asyncio
import contextlib
import socket
import struct
from dataclasses import dataclass
from pathlib import Path

from rosnet_tui.core.netinfo import default_gateway, detect_local_net, interface_ipv4
from rosnet_tui.core.public_ip import find_public_ip
from rosnet_tui.core.settings_model import Settings

# rtnetlink multicast groups and message types (linux/rtnetlink.h)
RTMGRP_LINK = 0x1
RTMGRP_IPV4_IFADDR = 0x10
RTMGRP_IPV4_ROUTE = 0x40
_RELEVANT = {16, 17, 20, 21, 24, 25}   # NEW/DELLINK, NEW/DELADDR, NEW/DELROUTE
_NLMSGHDR = struct.Struct("=LHHLL")
_MAX_DRAIN = 256                        # messages read per drain (a storm cannot hold us)


@dataclass(frozen=True)
class LocalAddress:
    interface: str
    local_ip: str
    gateway: str

    def describe(self) -> str:
        if not self.local_ip:
            return "no local IPv4 address"
        via = f", default route via {self.gateway}" if self.gateway else ", no default route"
        return f"{self.local_ip} on {self.interface or '?'}{via}"


def observe_local(settings: Settings) -> LocalAddress:
    """This component's LAN address now: the settings' interface if named, else the interface
    of the default route (see netinfo.detect_local_net)."""
    gateway, gw_if = default_gateway()
    iface = settings.this.interface
    if iface:
        ip, _ = interface_ipv4(iface)
        return LocalAddress(iface, ip, gateway if gw_if == iface else "")
    net = detect_local_net()
    return LocalAddress(net.interface, net.local_ip, net.gateway)


class NetlinkMonitor:
    """A netlink socket that becomes readable when a link, an IPv4 address or a route changes."""

    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock

    @classmethod
    def open(cls) -> NetlinkMonitor | None:
        """The monitor, or None where netlink is not available (not Linux, no permission)."""
        family = getattr(socket, "AF_NETLINK", None)
        if family is None:
            return None
        try:
            s = socket.socket(family, socket.SOCK_RAW | socket.SOCK_CLOEXEC,
                              getattr(socket, "NETLINK_ROUTE", 0))
            s.bind((0, RTMGRP_LINK | RTMGRP_IPV4_IFADDR | RTMGRP_IPV4_ROUTE))
            s.setblocking(False)
        except OSError:
            return None
        return cls(s)

    def fileno(self) -> int:
        return self.sock.fileno()

    def drain(self) -> bool:
        """Read what is pending (bounded); True when a link, address or route changed."""
        changed = False
        for _ in range(_MAX_DRAIN):
            try:
                data = self.sock.recv(65536)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                # ENOBUFS: the kernel dropped notifications; something surely changed
                changed = True
                break
            if not data:
                break
            off = 0
            while off + _NLMSGHDR.size <= len(data):
                length, mtype, _, _, _ = _NLMSGHDR.unpack_from(data, off)
                if mtype in _RELEVANT:
                    changed = True
                if length < _NLMSGHDR.size:
                    break
                off += (length + 3) & ~3
        return changed

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self.sock.close()


# --------------------------------------------------------------------------- public IP
@dataclass(frozen=True)
class PublicLookup:
    ip: str | None
    summary: str          # what the lookup said (why there is no address)


def lookup_public_ip(settings: Settings, state_dir: Path, timeout_s: float) -> PublicLookup:
    """This component's public IP as the settings' what-is-my-IP services see it (bounded by
    *timeout_s*); ``ip`` None when they do not answer or disagree."""
    found = asyncio.run(find_public_ip(settings.probe.public_ip_urls, state_dir, timeout_s))
    ip = found.ip
    return PublicLookup(ip, found.problem() or f"public IP {ip}")
