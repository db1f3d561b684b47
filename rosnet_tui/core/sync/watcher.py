"""Watching this component's own addresses: local IP and default route (at once, through the
kernel's netlink notifications), and the public IP (polled, through
:func:`rosnet_tui.core.exposure.public_ip.find_public_ip`, which also keeps the public-IP history in the
state dir)."""

from __future__ import annotations

import asyncio
import contextlib
import copy
import logging
import math
import socket
import struct
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from rosnet_tui.core.config.settings_model import Settings
from rosnet_tui.core.exposure.public_ip import find_public_ip
from rosnet_tui.core.net.netinfo import (
    default_gateway,
    detect_local_net,
    interface_ipv4,
    route_netlink,
)

from .backoff import Backoff
from .state import Report
from .timing import FORCED_GAP_S
from .worker import Worker

log = logging.getLogger("rosnet_tui.sync")

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
        s = route_netlink()
        if s is None:
            return None
        try:
            s.bind((0, RTMGRP_LINK | RTMGRP_IPV4_IFADDR | RTMGRP_IPV4_ROUTE))
            s.setblocking(False)
        except OSError:
            s.close()
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


# --------------------------------------------------------------------------- the watcher
class AddressWatch:
    """The service's watcher of this component's addresses. Owns them (the local address, the
    public IP) and when to ask for the public IP again; hands the others :attr:`local`,
    :attr:`public_ip` and, from :meth:`observe_local` and :meth:`take_public`, whether they
    changed. The lookup runs on *lookups* (a :class:`~.worker.Worker`) while the service runs."""

    def __init__(self, report: Report, local_source: Callable[[Settings], LocalAddress],
                 public_source: Callable[[Settings], PublicLookup]) -> None:
        self.report = report
        self.local_source = local_source
        self.public_source = public_source
        self.local: LocalAddress | None = None
        self.public_ip = ""
        self.next_public = time.monotonic()       # monotonic: the next poll
        self.last_public_poll = -FORCED_GAP_S
        self.lookups: Worker | None = None        # the lookup's thread while the loop runs
        self.busy = False                         # a lookup is under way on that thread
        self.answered = False                     # a lookup has answered (or failed) once
        self.backoff = Backoff()

    @property
    def first_answer_pending(self) -> bool:
        """The first lookup is under way: its answer comes first (no stale address used)."""
        return self.busy and not self.answered

    def wake_at(self) -> float | None:
        """When the next poll is due (None: a lookup is under way; its answer wakes the loop)."""
        return None if self.busy else self.next_public

    def ask_soon(self) -> None:
        """Poll at once, but not more often than every FORCED_GAP_S (a flapping link)."""
        self.next_public = min(self.next_public, self.last_public_poll + FORCED_GAP_S)

    def observe_local(self, settings: Settings) -> bool:
        """Look at the local address now; True when it changed."""
        try:
            local = self.local_source(settings)
        except Exception as exc:  # noqa: BLE001 - a broken interface query is a result
            self.report.error("local_ip", f"cannot read this machine's addresses: {exc}")
            return False
        self.report.clear_error("local_ip")
        changed = local != self.local
        if changed:
            if self.local is not None:
                log.info("local address changed: %s -> %s", self.local.describe(),
                         local.describe())
                # a new route may mean a new public IP: ask now (within the forced gap)
                self.ask_soon()
            else:
                log.info("local address: %s", local.describe())
            if (self.local is not None and local.local_ip and self.local.local_ip
                    and local.local_ip != self.local.local_ip):
                log.warning("this component's local IP changed (%s -> %s): a modem that forwards "
                            "ports to the old address must be changed too (reserve the address in "
                            "the modem's DHCP settings)", self.local.local_ip, local.local_ip)
            self.local = local
        self.report.update_own(dirty=changed, local_ip=local.local_ip, interface=local.interface,
                               gateway=local.gateway)
        return changed

    def poll_if_due(self, settings: Settings, keep: str, interval_s: float) -> bool:
        """Ask for the public IP when due: on the lookup's thread while the service runs (the
        answer comes back to :meth:`take_public`), here and now otherwise (True when the address
        changed). *keep*: the address kept meanwhile (for the message when none is found)."""
        if time.monotonic() < self.next_public or self.busy:
            return False
        self.last_public_poll = mono = time.monotonic()
        self.next_public = math.inf     # a wish for an earlier poll meanwhile lowers it
        if self.lookups is not None:
            self.busy = True
            self.lookups.submit(mono, copy.deepcopy(settings))
            return False
        return self.take_public(mono, self.lookup(settings), keep, interval_s)

    def lookup(self, settings: Settings) -> PublicLookup:
        try:
            return self.public_source(settings)
        except Exception as exc:  # noqa: BLE001
            return PublicLookup(None, f"the lookup failed: {type(exc).__name__}: {exc}")

    def take_public(self, mono: float, lk: PublicLookup | None, keep: str,
                    interval_s: float) -> bool:
        """The answer of the lookup started at *mono*; True when the public IP changed."""
        self.busy = False
        self.answered = True
        wished = self.next_public       # inf, or an earlier poll asked for meanwhile
        changed = self._answer(mono, lk or PublicLookup(None, "the lookup failed (see the log)"),
                               keep, interval_s)
        self.next_public = min(self.next_public, wished)
        return changed

    def _answer(self, mono: float, lk: PublicLookup, keep: str, interval_s: float) -> bool:
        self.report.update_own(dirty=False, public_checked_at=time.time())
        if not lk.ip:
            self.next_public = self.report.fail(
                "public_ip", self.backoff,
                f"no public IP: {lk.summary}; keeping the last known ({keep or 'none known'})",
                mono, interval_s)
            return False
        self.backoff.succeed()
        self.report.clear_error("public_ip", f"public IP lookup works again ({lk.ip})")
        self.next_public = mono + interval_s
        changed = lk.ip != self.public_ip
        if changed:
            if self.public_ip:
                log.info("public IP changed: %s -> %s", self.public_ip, lk.ip)
            else:
                log.info("public IP: %s", lk.ip)
            self.public_ip = lk.ip
        self.report.update_own(public_ip=lk.ip)
        return changed
