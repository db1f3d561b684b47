"""Finding the modem and asking it, whatever it speaks: UPnP IGD first (it can list its
forwards and label them), then PCP, then NAT-PMP.

:func:`find_modem` asks all three at once, towards the default gateway only, within one deadline;
a modem that speaks none of them costs the SSDP window (well under a second), because closed UDP
ports answer at once. :class:`Modem` then offers the same few operations over any protocol, and
refuses, before anything is sent, to forward to an address that is not this machine's own, a port
below 1024, or without a bounded lease.
"""

from __future__ import annotations

import socket
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

from rosnet_tui.core.addresses import KIND_WORDS, address_kind
from rosnet_tui.core.upnp import igd as igd_mod
from rosnet_tui.core.upnp import pmp
from rosnet_tui.core.upnp.wire import (
    HostileAnswer,
    ModemError,
    NoAnswer,
    Refused,
    label,
    ssdp_search,
)

PROTOCOLS = ("upnp", "pcp", "natpmp")      # preference order
LOWEST_PORT = 1024
LEASE_MIN_S, LEASE_MAX_S = 120, 7 * 24 * 3600


@dataclass
class Forward:
    """A forward the modem holds (or, for NAT-PMP/PCP, one we know we made)."""

    protocol: str          # "TCP" | "UDP"
    external_port: int
    internal_client: str
    internal_port: int
    description: str = ""
    lease_s: int = 0       # what is left of it, as the modem says (0: no expiry or unknown)

    def to_json(self) -> dict:
        return {"protocol": self.protocol, "external_port": self.external_port,
                "internal_client": self.internal_client, "internal_port": self.internal_port,
                "description": self.description, "lease_s": self.lease_s}


@dataclass
class Modem:
    gateway: str                 # the modem's LAN address (the default gateway)
    local_ip: str                # this machine's address towards it; requests leave from it
    protocols: list[str]         # what answered, in preference order
    igd: igd_mod.Igd | None = None
    external_ip: str | None = None   # as the modem reports it ("" : none; None: not learned)
    mac: str = ""                # the modem's MAC address, from this machine's ARP table
    notes: list[str] = field(default_factory=list)

    @property
    def protocol(self) -> str:
        return self.protocols[0]

    @property
    def can_list(self) -> bool:
        return self.igd is not None

    def describe(self) -> str:
        what = " and ".join(label(p) for p in self.protocols)
        who = ""
        if self.igd is not None and (self.igd.friendly_name or self.igd.model):
            who = f" ({self.igd.friendly_name or self.igd.model})"
        return f"the modem {self.gateway}{who} speaks {what}"

    def identity(self, protocol: str | None = None) -> dict:
        """What tells this modem from another one later (recorded with each forward we make)."""
        ident = {"protocol": protocol or self.protocol, "gateway": self.gateway, "mac": self.mac}
        if (protocol or self.protocol) == "upnp" and self.igd is not None:
            ident.update(udn=self.igd.udn, location=self.igd.location)
        return ident

    def same_as(self, ident: dict) -> tuple[bool, str]:
        """Whether *ident* (recorded earlier) names this modem; if not, why."""
        if ident.get("gateway") != self.gateway:
            return False, (f"the forward was made on the modem at {ident.get('gateway')}; the "
                           f"gateway here is {self.gateway}")
        if ident.get("mac") and self.mac and ident["mac"] != self.mac:
            return False, (f"the modem at {self.gateway} is another device now (MAC {self.mac}, "
                           f"the forward was made on {ident['mac']})")
        if ident.get("udn") and self.igd is not None and self.igd.udn \
                and ident["udn"] != self.igd.udn:
            return False, (f"the modem at {self.gateway} is another UPnP device now "
                           f"({self.igd.udn}, the forward was made on {ident['udn']})")
        return True, ""

    # ------------------------------------------------------------------ reading
    def forwards(self, deadline: float) -> list[Forward]:
        """Every forward the modem lists (UPnP IGD only; the others cannot list)."""
        if self.igd is None:
            raise ModemError(f"{label(self.protocol)} cannot list a modem's forwards")
        return [Forward(m.protocol, m.external_port, m.internal_client, m.internal_port,
                        m.description, m.lease_s)
                for m in igd_mod.list_mappings(self.igd, deadline) if m.enabled]

    def forward_of(self, protocol: str, port: int, deadline: float) -> Forward | None:
        """The modem's forward of external *port* (UPnP IGD only), or None."""
        if self.igd is None:
            raise ModemError(f"{label(self.protocol)} cannot look up a modem's forwards")
        m = igd_mod.get_mapping(self.igd, protocol, port, deadline)
        if m is None or not m.enabled:
            return None
        return Forward(m.protocol, m.external_port, m.internal_client, m.internal_port,
                       m.description, m.lease_s)

    # ------------------------------------------------------------------ changing
    def _guard(self, internal_client: str, port: int, lease_s: int) -> None:
        if internal_client != self.local_ip:
            raise ValueError(f"refused: {internal_client} is not this machine's address towards "
                             f"the modem ({self.local_ip}); rosnet-tui never forwards a port to "
                             "another machine")
        if not LOWEST_PORT <= port <= 65535:
            raise ValueError(f"refused: port {port} is below {LOWEST_PORT} (system services); "
                             "rosnet-tui never forwards those")
        if not LEASE_MIN_S <= lease_s <= LEASE_MAX_S:
            raise ValueError(f"refused: a lease of {lease_s} s; forwards are made for "
                             f"{LEASE_MIN_S} s to {LEASE_MAX_S // 86400} days, never for ever")

    def add(self, protocol: str, port: int, lease_s: int, description: str, deadline: float, *,
            via: str | None = None, nonce: bytes | None = None) -> dict:
        """Forward external *port* to the same port of this machine; what was made (the record
        undo and renewal need: protocol used, lease, the PCP nonce)."""
        via = via or self.protocol
        self._guard(self.local_ip, port, lease_s)
        if via == "upnp":
            if self.igd is None:
                raise ModemError("the modem does not speak UPnP IGD")
            igd_mod.add_mapping(self.igd, protocol, port, self.local_ip, port, description,
                                lease_s, deadline)
            return {"via": "upnp", "lease_s": lease_s}
        if via == "pcp":
            nonce = nonce or pmp.new_nonce()
            ans = pmp.pcp_map(self.gateway, self.local_ip, protocol, port, port, lease_s, nonce,
                              deadline, notes=self.notes)
            if ans.external_port != port:
                given_back = True
                try:
                    pmp.pcp_map(self.gateway, self.local_ip, protocol, port, ans.external_port, 0,
                                nonce, deadline, notes=self.notes)
                except ModemError:
                    given_back = False
                raise _taken("pcp", port, ans.external_port, ans.lifetime, given_back)
            if ans.external_ip:
                self.external_ip = wan_address(ans.external_ip, "pcp", self.notes)
            return {"via": "pcp", "lease_s": ans.lifetime, "nonce": nonce.hex()}
        if via == "natpmp":
            eport, life = pmp.natpmp_map(self.gateway, protocol, port, port, lease_s, deadline,
                                         source_ip=self.local_ip, notes=self.notes)
            if eport != port:
                given_back = True
                try:
                    pmp.natpmp_map(self.gateway, protocol, port, 0, 0, deadline,
                                   source_ip=self.local_ip, notes=self.notes)
                except ModemError:
                    given_back = False
                raise _taken("natpmp", port, eport, life, given_back)
            return {"via": "natpmp", "lease_s": life}
        raise ValueError(f"unknown protocol {via!r}")

    def remove(self, record: dict, deadline: float) -> str:
        """Remove a forward we made (*record* as :meth:`add` returned it, plus protocol and
        port). UPnP: only when the modem's forward still points at this machine. Says what
        happened."""
        protocol, port, via = record["protocol"], int(record["port"]), record["via"]
        if via == "upnp":
            if self.igd is None:
                raise ModemError("the modem no longer answers UPnP IGD")
            now = self.forward_of(protocol, port, deadline)
            if now is None:
                return f"{protocol} {port}: already gone from the modem"
            if now.internal_client != self.local_ip or now.internal_port != port:
                return (f"{protocol} {port}: left as it is, it now forwards to "
                        f"{now.internal_client}:{now.internal_port} (not ours any more)")
            igd_mod.delete_mapping(self.igd, protocol, port, deadline)
            return f"{protocol} {port}: removed from the modem"
        if via == "pcp":
            pmp.pcp_map(self.gateway, self.local_ip, protocol, port, 0, 0,
                        bytes.fromhex(record["nonce"]), deadline, notes=self.notes)
            return f"{protocol} {port}: removed from the modem (PCP)"
        if via == "natpmp":
            pmp.natpmp_map(self.gateway, protocol, port, 0, 0, deadline,
                           source_ip=self.local_ip, notes=self.notes)
            return f"{protocol} {port}: removed from the modem (NAT-PMP)"
        raise ValueError(f"unknown protocol {via!r}")


# What a modem's external address may be: the internet's, or a carrier's or a LAN's in front of it.
WAN_KINDS = ("public", "documentation", "shared", "private")


def wan_address(reported: str, protocol: str, notes: list[str]) -> str:
    """The modem's external address as it reported it, or "" (none) when what it reported cannot
    be one: 0.0.0.0 (usual when the modem has no WAN address), loopback, link-local, multicast,
    broadcast, reserved. Said in *notes*."""
    if not reported:
        return ""
    kind = address_kind(reported)
    if kind in WAN_KINDS:
        return reported
    notes.append(f"{label(protocol)}: the modem reports {reported} as its external address, "
                 f"{KIND_WORDS[kind]}: read as no public address")
    return ""


def _taken(protocol: str, port: int, offered: int, lease_s: int = 0,
           given_back: bool = True) -> Refused:
    back = "the offer was given back" if given_back else (
        f"giving the offer back was not confirmed: the modem may forward its port {offered} to "
        f"this machine for up to {lease_s} s, until its lease ends")
    return Refused(protocol, -1, "PortTaken",
                   f"the modem offered external port {offered} instead of {port}: port {port} is "
                   f"already forwarded to another machine ({back})")


# --------------------------------------------------------------------------- finding it
def source_towards(gateway: str) -> str:
    """This machine's address on the way to *gateway* (no packet is sent)."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        s.connect((gateway, pmp.PORT))
        return s.getsockname()[0]
    finally:
        s.close()


def arp_mac(ip: str) -> str:
    """The MAC address this machine's ARP table holds for *ip* ("" when none)."""
    try:
        with open("/proc/net/arp", encoding="ascii", errors="replace") as f:
            for line in f.read(65536).splitlines()[1:]:
                cols = line.split()
                if len(cols) >= 4 and cols[0] == ip and cols[3] != "00:00:00:00:00:00":
                    return cols[3].lower()
    except OSError:
        pass
    return ""


def find_modem(timeout: float, *, gateway: str | None = None,
               protocols: tuple[str, ...] = PROTOCOLS, notes: list[str] | None = None
               ) -> Modem | None:
    """Ask the default gateway over every protocol in *protocols*, all at once, within
    *timeout* seconds. None when nothing answered (*notes* says what was tried)."""
    notes = notes if notes is not None else []
    start = time.monotonic()
    deadline = start + timeout
    if gateway is None:
        from rosnet_tui.core.net.netinfo import default_gateway

        gateway = default_gateway()[0]
    if not gateway:
        notes.append("no default gateway: there is no modem to ask")
        return None
    try:
        local_ip = source_towards(gateway)
    except OSError as exc:
        notes.append(f"no route to the gateway {gateway}: {exc.strerror or exc}")
        return None
    ssdp_window = min(0.8, timeout * 0.5)

    def ask_upnp() -> igd_mod.Igd | None:
        found = ssdp_search(ssdp_window, gateway=gateway, source_ip=local_ip, notes=notes)
        if found is None:
            notes.append(f"UPnP IGD: no answer to SSDP from {gateway}")
            return None
        return igd_mod.describe(found.location, gateway, deadline, source_ip=local_ip)

    def ask_natpmp() -> str:
        return pmp.natpmp_external(gateway, min(deadline, time.monotonic() + 1.0),
                                   source_ip=local_ip, notes=notes)[0]

    def ask_pcp() -> int:
        return pmp.pcp_announce(gateway, local_ip, min(deadline, time.monotonic() + 1.0),
                                notes=notes)

    asks = {"upnp": ask_upnp, "natpmp": ask_natpmp, "pcp": ask_pcp}
    answered: dict[str, object] = {}
    with ThreadPoolExecutor(max_workers=3) as pool:
        futures = {p: pool.submit(asks[p]) for p in protocols if p in asks}
        for p, fut in futures.items():
            try:
                got = fut.result(timeout=max(deadline - time.monotonic(), 0.05) + 0.5)
            except Refused as exc:
                # It speaks the protocol and refused the question: still an answer.
                answered[p] = exc
                notes.append(f"{label(p)}: {exc}")
                continue
            except (NoAnswer, HostileAnswer, ModemError) as exc:
                notes.append(f"{label(p)}: {exc}")
                continue
            except Exception as exc:  # noqa: BLE001 - a timeout or a bug: a result, not a crash
                notes.append(f"{label(p)}: no answer ({type(exc).__name__})")
                continue
            if got is not None:
                answered[p] = got
    if not answered:
        return None
    modem = Modem(gateway, local_ip, [p for p in PROTOCOLS if p in answered],
                  mac=arp_mac(gateway), notes=notes)
    got_igd = answered.get("upnp")
    if isinstance(got_igd, igd_mod.Igd):
        modem.igd = got_igd
        try:
            modem.external_ip = wan_address(
                igd_mod.external_ip(got_igd, max(deadline, time.monotonic() + 1)), "upnp", notes)
        except ModemError as exc:
            notes.append(f"UPnP IGD: external address: {exc}")
    elif "upnp" in modem.protocols:
        modem.protocols.remove("upnp")
    nat = answered.get("natpmp")
    if modem.external_ip is None and isinstance(nat, str):
        modem.external_ip = wan_address(nat, "natpmp", notes)
    elif modem.external_ip is None and isinstance(nat, Refused) and nat.code == 3:
        modem.external_ip = ""   # NAT-PMP "network failure": the modem has no public address
    if not modem.protocols:
        return None
    return modem
