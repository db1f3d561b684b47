"""NAT-PMP (RFC 6886) and PCP (RFC 6887): small UDP messages to the default gateway, port 5351.

Requests are retransmitted from 250 ms, doubling, until a deadline; an answer counts only when it
comes from the gateway's port 5351, has exactly the expected length and opcode, and (PCP) carries
our nonce. Anything else is noted and ignored (a modem that sends only garbage never answers).
A closed port (ICMP port unreachable) ends the wait at once.
"""

from __future__ import annotations

import ipaddress
import os
import socket
import struct
import time
from dataclasses import dataclass

from rosnet_tui.core.upnp.wire import BadAnswers, HostileAnswer, NoAnswer, Refused

PORT = 5351
PROTO_NUM = {"TCP": 6, "UDP": 17}

NATPMP_RESULTS = {
    1: ("UnsupportedVersion", "the modem does not speak this version of NAT-PMP"),
    2: ("NotAuthorized", "the modem refuses forwards (NAT-PMP is switched off for forwarding, or "
                         "this port or machine is not allowed)"),
    3: ("NetworkFailure", "the modem has no public address of its own to forward from (it is "
                          "not connected, or sits behind another NAT)"),
    4: ("OutOfResources", "the modem's table of forwards is full, or the port is taken"),
    5: ("UnsupportedOpcode", "the modem does not offer this request"),
}
PCP_RESULTS = {
    1: ("UNSUPP_VERSION", "the modem does not speak this version of PCP"),
    2: ("NOT_AUTHORIZED", "the modem's rules do not allow this forward"),
    3: ("MALFORMED_REQUEST", "the modem did not understand the request"),
    4: ("UNSUPP_OPCODE", "the modem does not offer this request"),
    5: ("UNSUPP_OPTION", "the modem does not support an option of the request"),
    6: ("MALFORMED_OPTION", "the modem did not understand an option"),
    7: ("NETWORK_FAILURE", "the modem has no working public side right now"),
    8: ("NO_RESOURCES", "the modem cannot make this forward (no public address to forward from, "
                        "or its table is full)"),
    9: ("UNSUPP_PROTOCOL", "the modem cannot forward this protocol"),
    10: ("USER_EX_QUOTA", "this machine has used up its share of forwards on the modem"),
    11: ("CANNOT_PROVIDE_EXTERNAL", "the modem cannot give this external port (another machine "
                                    "holds it)"),
    12: ("ADDRESS_MISMATCH", "the modem sees this machine under another address than the one in "
                             "the request"),
    13: ("EXCESSIVE_REMOTE_PEERS", "the modem refuses more remote peers"),
}


def _exchange(gateway: str, request: bytes, deadline: float, accept, source_ip: str | None,
              notes: list[str], what: str):
    """Send *request* to the gateway until *accept(answer)* returns non-None or time runs out.
    Answers refused are noted (capped); at the deadline the last refusal is said."""
    bad = BadAnswers(notes, what)
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        if source_ip:
            s.bind((source_ip, 0))
        s.connect((gateway, PORT))  # connected: ICMP "port unreachable" ends the wait at once
        wait = 0.25
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                if bad.last:
                    raise NoAnswer(f"no usable answer from {gateway}:{PORT} (the last one: "
                                   f"{bad.last})")
                raise NoAnswer(f"no answer from {gateway}:{PORT}")
            s.send(request)
            until = time.monotonic() + min(wait, left)
            wait *= 2
            while True:
                left = until - time.monotonic()
                if left <= 0:
                    break
                s.settimeout(left)
                try:
                    data = s.recv(1100)
                except TimeoutError:
                    break
                try:
                    got = accept(data)
                except HostileAnswer as exc:
                    bad.add(f"{exc}; ignored")
                    continue
                if got is not None:
                    return got
    except ConnectionRefusedError:
        raise NoAnswer(f"{gateway}:{PORT} is closed (the modem does not speak it)") from None
    except OSError as exc:
        raise NoAnswer(f"{gateway}:{PORT}: {exc.strerror or exc}") from None
    finally:
        s.close()
        bad.close()


def _refused(protocol: str, table: dict, code: int) -> Refused:
    name, words = table.get(code, ("unknown", f"the modem refused with code {code}"))
    return Refused(protocol, code, name, words)


def _confirms(asked_s: int, given_s: int, what: str) -> None:
    """A success answers the request only when its lifetime says the same thing: 0 for a
    delete (a late copy of the mapping's own answer, lifetime > 0, is not a confirmation), more
    than 0 for a forward (lifetime 0 is no forward at all)."""
    if asked_s == 0 and given_s != 0:
        raise HostileAnswer(f"a {what} answer to a delete with a lifetime of {given_s} s (a late "
                            "answer to the forward, not the delete)")
    if asked_s and not given_s:
        raise HostileAnswer(f"a {what} 'success' with a lifetime of 0 s: no forward was made")


# --------------------------------------------------------------------------- NAT-PMP
def natpmp_external(gateway: str, deadline: float, *, source_ip: str | None = None,
                    notes: list[str] | None = None) -> tuple[str, int]:
    """(external address, epoch seconds). Result 3 (no address) raises Refused."""
    def accept(d: bytes):
        if len(d) < 2 or d[0] != 0 or d[1] != 128:
            return None  # not an answer to this request (another opcode, or PCP)
        if len(d) != 12:
            raise HostileAnswer(f"a NAT-PMP address answer of {len(d)} bytes (12 expected)")
        _v, _op, result, epoch = struct.unpack("!BBHI", d[:8])
        if result:
            raise _refused("natpmp", NATPMP_RESULTS, result)
        return socket.inet_ntoa(d[8:12]), epoch

    return _exchange(gateway, b"\x00\x00", deadline, accept, source_ip,
                     notes if notes is not None else [], "NAT-PMP")


def natpmp_map(gateway: str, protocol: str, internal_port: int, external_port: int,
               lease_s: int, deadline: float, *, source_ip: str | None = None,
               notes: list[str] | None = None) -> tuple[int, int]:
    """Map (or with lease 0, delete) a port; (external port given, lease given)."""
    op = 2 if protocol == "TCP" else 1
    req = struct.pack("!BBHHHI", 0, op, 0, internal_port, external_port, lease_s)

    def accept(d: bytes):
        if len(d) < 2 or d[0] != 0 or d[1] != 128 + op:
            return None
        if len(d) != 16:
            raise HostileAnswer(f"a NAT-PMP mapping answer of {len(d)} bytes (16 expected)")
        _v, _op, result, _epoch, iport, eport, life = struct.unpack("!BBHIHHI", d)
        if result:
            raise _refused("natpmp", NATPMP_RESULTS, result)
        if iport != internal_port:
            raise HostileAnswer(f"a NAT-PMP answer for port {iport}, not {internal_port}")
        _confirms(lease_s, life, "NAT-PMP")
        return eport, life

    return _exchange(gateway, req, deadline, accept, source_ip,
                     notes if notes is not None else [], "NAT-PMP")


# --------------------------------------------------------------------------- PCP
def _v6(ip: str) -> bytes:
    return ipaddress.IPv6Address(f"::ffff:{ip}").packed


def _from_v6(b: bytes) -> str:
    a = ipaddress.IPv6Address(b)
    if a.ipv4_mapped is None:
        return ""  # an IPv6 address, or all zeros (none given)
    return str(a.ipv4_mapped)


@dataclass
class PcpAnswer:
    lifetime: int
    epoch: int
    external_ip: str
    external_port: int


def pcp_announce(gateway: str, client_ip: str, deadline: float, *,
                 notes: list[str] | None = None) -> int:
    """Whether the gateway speaks PCP, without changing anything: ANNOUNCE; its epoch."""
    req = struct.pack("!BBHI", 2, 0, 0, 0) + _v6(client_ip)

    def accept(d: bytes):
        if len(d) < 4 or d[0] != 2 or d[1] != 0x80:
            if len(d) >= 4 and d[0] == 0 and d[1] >= 0x80 and d[3] == 1:
                raise NoAnswer("the modem speaks NAT-PMP only")
            return None
        if len(d) != 24:
            raise HostileAnswer(f"a PCP ANNOUNCE answer of {len(d)} bytes (24 expected)")
        if d[3]:
            raise _refused("pcp", PCP_RESULTS, d[3])
        return struct.unpack("!I", d[8:12])[0]

    return _exchange(gateway, req, deadline, accept, client_ip,
                     notes if notes is not None else [], "PCP")


def new_nonce() -> bytes:
    return os.urandom(12)


def pcp_map(gateway: str, client_ip: str, protocol: str, internal_port: int,
            external_port: int, lease_s: int, nonce: bytes, deadline: float, *,
            notes: list[str] | None = None) -> PcpAnswer:
    """MAP (or with lease 0, delete) a port for *client_ip*, which must be this machine's address
    towards the gateway (the request leaves from it)."""
    if len(nonce) != 12:
        raise ValueError("a PCP nonce is 12 bytes")
    header = struct.pack("!BBHI", 2, 1, 0, lease_s) + _v6(client_ip)
    body = nonce + struct.pack("!B3xHH", PROTO_NUM[protocol], internal_port, external_port) + \
        _v6("0.0.0.0")
    req = header + body

    def accept(d: bytes):
        if len(d) < 4 or d[0] != 2 or d[1] != 0x81:
            if len(d) >= 4 and d[0] == 0 and d[1] >= 0x80 and d[3] == 1:
                raise NoAnswer("the modem speaks NAT-PMP only")
            return None
        if len(d) < 60 or (len(d) - 60) % 4:
            raise HostileAnswer(f"a PCP MAP answer of {len(d)} bytes (60 expected)")
        result, life, epoch = d[3], *struct.unpack("!II", d[4:12])
        if d[24:36] != nonce:
            return None  # another request's answer
        proto, iport, eport = struct.unpack("!B3xHH", d[36:44])
        if proto != PROTO_NUM[protocol] or iport != internal_port:
            raise HostileAnswer("a PCP answer for another protocol or port")
        if result:
            raise _refused("pcp", PCP_RESULTS, result)
        _confirms(lease_s, life, "PCP")
        return PcpAnswer(life, epoch, _from_v6(d[44:60]), eport)

    return _exchange(gateway, req, deadline, accept, client_ip,
                     notes if notes is not None else [], "PCP")
