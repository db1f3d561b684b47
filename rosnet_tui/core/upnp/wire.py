"""What crosses the LAN to the modem: SSDP discovery, a bounded HTTP client, guarded XML.

Everything here assumes the modem may be broken or hostile. Every exchange has a deadline for the
whole exchange (not per read), answers are read up to a fixed size and refused beyond it, XML with
a DOCTYPE or entities is refused before parsing, and an address a modem hands us (LOCATION, a
control URL) must point at the modem that answered, never at another host.
"""

from __future__ import annotations

import select
import socket
import time
import xml.etree.ElementTree as ET
import xml.parsers.expat
from dataclasses import dataclass
from urllib.parse import urljoin, urlsplit

from rosnet_tui.core.addresses import parse_ip
from rosnet_tui.core.printable import printable

SSDP_ADDR = ("239.255.255.250", 1900)
IGD_TYPES = ("urn:schemas-upnp-org:device:InternetGatewayDevice:2",
             "urn:schemas-upnp-org:device:InternetGatewayDevice:1")
MAX_DATAGRAM = 2048        # an SSDP answer is a few hundred bytes
MAX_HEADERS = 8 * 1024     # HTTP status line and headers
MAX_BODY = 64 * 1024       # a root description is 2-8 KiB; a SOAP answer well under 2 KiB
MAX_TEXT = 256             # any single value read from the modem (a description, an address)
MAX_NOTES = 4              # notes kept per exchange about answers refused; the rest are counted


class ModemError(Exception):
    """Talking to the modem did not give a usable answer (nothing changed because of it)."""


class NoAnswer(ModemError):
    """Nothing answered in time (no modem, or not this protocol)."""


class HostileAnswer(ModemError):
    """The modem's answer is malformed, too large, of the wrong type, or points elsewhere: it was
    refused as it stands and nothing was done with it."""


class Refused(ModemError):
    """The modem understood and said no. ``code`` is its own error number, ``name`` its own name
    for it, ``words`` our explanation."""

    def __init__(self, protocol: str, code: int, name: str, words: str) -> None:
        self.protocol, self.code, self.name, self.words = protocol, code, name, words
        super().__init__(f"{label(protocol)} error {code} ({name}): {words}")


def label(protocol: str) -> str:
    return {"upnp": "UPnP IGD", "natpmp": "NAT-PMP", "pcp": "PCP"}.get(protocol, protocol)


def lan_ipv4(text: str) -> str | None:
    """*text* as a dotted IPv4 address when it is one, else None (no names, no IPv6)."""
    a = parse_ip(text.strip())
    return str(a) if a is not None and a.version == 4 else None


def ascii_number(text: str | None, what: str, *, digits: int = 10) -> int:
    """*text* as a whole number written in ASCII digits only (``"¹"`` is a digit to Python, not to
    a modem's protocol), at most *digits* long; HostileAnswer otherwise."""
    v = (text or "").strip()
    if not v or len(v) > digits or not v.isascii() or not v.isdigit():
        raise HostileAnswer(f"the modem's {what} is not a number ({shown(v, 20)!r})")
    return int(v)


def shown(value: str, limit: int = MAX_TEXT) -> str:
    """*value* fit to be shown to a person: control characters (C0, DEL and C1: a terminal acts
    on them) each become "?", and at most *limit* characters are kept."""
    return printable(value, limit)


def clean_text(value: str | None, what: str, *, limit: int = MAX_TEXT) -> str:
    """A value from the modem as plain text: refused when too long; control characters (C0 and
    C1) each become "?" (a forward's description is any LAN host's to set: one bad entry must
    not make the list unreadable)."""
    if value is None:
        return ""
    if len(value) > limit:
        raise HostileAnswer(f"the modem's {what} is {len(value)} characters long (more than "
                            f"{limit}): refused")
    return shown(value.strip(), limit)


class BadAnswers:
    """Notes about the answers an exchange refused: the first MAX_NOTES as they are, the rest
    counted in one line by :meth:`close` (any LAN host can send thousands of datagrams)."""

    def __init__(self, notes: list[str], what: str) -> None:
        self.notes, self.what, self.count, self.last = notes, what, 0, ""

    def add(self, why: str) -> None:
        self.count += 1
        self.last = why
        if self.count <= MAX_NOTES:
            self.notes.append(f"{self.what}: {why}")

    def close(self) -> None:
        if self.count > MAX_NOTES:
            self.notes.append(f"{self.what}: {self.count - MAX_NOTES} more unusable answers "
                              "ignored")
        self.count = min(self.count, MAX_NOTES)


# --------------------------------------------------------------------------- HTTP
@dataclass
class HttpAnswer:
    status: int
    headers: dict[str, str]
    body: bytes


def _left(deadline: float) -> float:
    left = deadline - time.monotonic()
    if left <= 0:
        raise NoAnswer("the modem did not answer in time")
    return left


def check_url(url: str, host: str) -> tuple[str, int, str]:
    """(host, port, path) of *url*, which must be plain http to *host* itself, written in
    printable ASCII (an HTTP request line is bytes: anything else is refused, not encoded)."""
    if not url.isascii() or not url.isprintable() or " " in url:
        raise HostileAnswer(f"the modem gave an address with characters outside printable ASCII "
                            f"({shown(url, 80)!r}): refused")
    try:
        parts = urlsplit(url)
        port = parts.port or 80
    except ValueError as exc:
        raise HostileAnswer(f"the modem gave an unusable address {url[:80]!r}: {exc}") from None
    if parts.scheme != "http":
        raise HostileAnswer(f"the modem gave a {parts.scheme or 'schemeless'} address "
                            f"({url[:80]!r}); only plain http on the LAN is followed")
    target = lan_ipv4(parts.hostname or "")
    if target is None or target != host:
        raise HostileAnswer(f"the modem at {host} points to another host ({url[:80]!r}): "
                            "refused, rosnet-tui only talks to the modem that answered")
    path = parts.path or "/"
    if parts.query:
        path += "?" + parts.query
    return target, port, path


def http_request(method: str, url: str, host: str, deadline: float, *, body: bytes = b"",
                 headers: dict[str, str] | None = None, source_ip: str | None = None
                 ) -> HttpAnswer:
    """One HTTP/1.1 exchange with the modem *host*, bounded in time and size; no redirects."""
    target, port, path = check_url(url, host)
    lines = [f"{method} {path} HTTP/1.1", f"Host: {target}:{port}", "Connection: close",
             "User-Agent: rosnet-tui", f"Content-Length: {len(body)}"]
    lines += [f"{k}: {v}" for k, v in (headers or {}).items()]
    request = ("\r\n".join(lines) + "\r\n\r\n").encode("latin-1") + body
    try:
        sock = socket.create_connection((target, port), timeout=_left(deadline),
                                        source_address=(source_ip, 0) if source_ip else None)
    except TimeoutError:
        raise NoAnswer(f"{target}:{port} did not accept a connection in time") from None
    except OSError as exc:
        raise NoAnswer(f"{target}:{port}: {exc.strerror or exc}") from None
    data = bytearray()
    try:
        sock.settimeout(_left(deadline))
        sock.sendall(request)
        while True:
            sock.settimeout(_left(deadline))
            chunk = sock.recv(8192)
            if not chunk:
                break
            data += chunk
            if len(data) > MAX_HEADERS + MAX_BODY:
                raise HostileAnswer(f"the modem's answer to {method} {path} is larger than "
                                    f"{(MAX_HEADERS + MAX_BODY) // 1024} KiB: refused")
            if _complete(data):
                break
    except TimeoutError:
        raise NoAnswer(f"{target}:{port} did not finish answering in time") from None
    except OSError as exc:
        raise NoAnswer(f"{target}:{port}: {exc.strerror or exc}") from None
    finally:
        sock.close()
    return parse_http(bytes(data))


def _complete(data: bytearray) -> bool:
    """Whether the answer is all here: its Content-Length read, or its last chunk (otherwise it
    ends when the modem closes, or at the deadline)."""
    end = data.find(b"\r\n\r\n")
    if end < 0:
        return False
    for line in bytes(data[:end]).split(b"\r\n")[1:]:
        name, _, value = line.partition(b":")
        if name.strip().lower() == b"transfer-encoding" and value.strip().lower() == b"chunked":
            return data.endswith(b"\r\n0\r\n\r\n")
        if name.strip().lower() == b"content-length" and value.strip().isdigit() and \
                len(value.strip()) <= 10:
            return len(data) - end - 4 >= int(value.strip())
    return False


def parse_http(data: bytes) -> HttpAnswer:
    end = data.find(b"\r\n\r\n")
    if end < 0 or end > MAX_HEADERS:
        raise HostileAnswer("the modem's answer is not HTTP (no complete header)")
    head = data[:end].decode("latin-1").split("\r\n")
    parts = head[0].split(" ", 2)
    if len(parts) < 2 or not parts[0].startswith("HTTP/1.") or len(parts[1]) != 3 or \
            not parts[1].isascii() or not parts[1].isdigit():
        raise HostileAnswer(f"the modem's answer is not HTTP ({shown(head[0], 60)!r})")
    headers: dict[str, str] = {}
    for line in head[1:]:
        name, sep, value = line.partition(":")
        if not sep:
            raise HostileAnswer(f"the modem sent a broken HTTP header ({shown(line, 60)!r})")
        headers[name.strip().lower()] = value.strip()
    body = data[end + 4:]
    if headers.get("transfer-encoding", "").lower() == "chunked":
        body = _dechunk(body)
    elif "content-length" in headers:
        n = ascii_number(headers["content-length"], "announced body length")
        if n > MAX_BODY:
            raise HostileAnswer(f"the modem announces a body of {n} bytes: refused")
        if len(body) < n:
            raise HostileAnswer("the modem closed the connection before the end of its answer")
        body = body[:n]
    if len(body) > MAX_BODY:
        raise HostileAnswer(f"the modem's answer is larger than {MAX_BODY // 1024} KiB: refused")
    return HttpAnswer(int(parts[1]), headers, body)


HEX = frozenset(b"0123456789abcdefABCDEF")


def _dechunk(body: bytes) -> bytes:
    """The body of a chunked answer. Each chunk size must be 1-8 ASCII hex digits and each chunk
    end where it says (CRLF after it): every round moves forward, so the loop ends with the
    body (a size such as "-6" once made it go back for ever)."""
    out, pos = bytearray(), 0
    while pos < len(body):
        nl = body.find(b"\r\n", pos)
        if nl < 0:
            break
        size_text = body[pos:nl].split(b";")[0].strip()
        if not 1 <= len(size_text) <= 8 or not set(size_text) <= HEX:
            raise HostileAnswer("the modem's chunked answer is malformed (a chunk size "
                                f"{shown(size_text.decode('latin-1'), 20)!r})")
        size = int(size_text, 16)
        if size == 0:
            return bytes(out)
        end = nl + 2 + size
        if body[end:end + 2] != b"\r\n":
            break
        out += body[nl + 2:end]
        if len(out) > MAX_BODY:
            raise HostileAnswer(f"the modem's answer is larger than {MAX_BODY // 1024} KiB: "
                                "refused")
        pos = end + 2
    raise HostileAnswer("the modem's chunked answer is cut short")


# --------------------------------------------------------------------------- XML
class _Declared(Exception):
    pass


def _refuse_declarations(*_args) -> None:
    raise _Declared


def parse_xml(body: bytes, what: str) -> ET.Element:
    """Parse the modem's XML, refusing DOCTYPEs and entity declarations outright, in whatever
    encoding the document names (expat reads UTF-16 too: a byte search for "<!DOCTYPE" does not
    see it there)."""
    head = body[:MAX_BODY].lower()
    if b"<!doctype" in head or b"<!entity" in head:
        raise HostileAnswer(f"the modem's {what} declares a DOCTYPE or entities: refused")
    scan = xml.parsers.expat.ParserCreate()
    scan.StartDoctypeDeclHandler = _refuse_declarations
    scan.EntityDeclHandler = _refuse_declarations
    scan.ExternalEntityRefHandler = _refuse_declarations
    try:
        scan.Parse(body, True)
    except _Declared:
        raise HostileAnswer(f"the modem's {what} declares a DOCTYPE or entities: refused") \
            from None
    except xml.parsers.expat.ExpatError as exc:
        raise HostileAnswer(f"the modem's {what} is not well-formed XML ({exc})") from None
    try:
        return ET.fromstring(body)
    except ET.ParseError as exc:
        raise HostileAnswer(f"the modem's {what} is not well-formed XML ({exc})") from None


def local_name(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def child_text(el: ET.Element, name: str) -> str | None:
    for c in el:
        if local_name(c.tag) == name:
            if len(c):
                raise HostileAnswer(f"the modem's <{name}> holds elements, not text")
            return c.text or ""
    return None


def resolve(base: str, ref: str, host: str) -> str:
    """*ref* (absolute or relative to *base*) as a URL on *host*; refused when it leaves it."""
    url = urljoin(base, clean_text(ref, "URL", limit=512))
    check_url(url, host)
    return url


# --------------------------------------------------------------------------- SSDP
@dataclass
class SsdpAnswer:
    sender: str
    location: str
    st: str
    usn: str
    server: str


def parse_ssdp(data: bytes, sender: str) -> SsdpAnswer:
    if len(data) > MAX_DATAGRAM:
        raise HostileAnswer(f"an SSDP answer from {sender} is {len(data)} bytes: refused")
    lines = data.decode("latin-1").split("\r\n")
    if not lines[0].upper().startswith("HTTP/1.1 200"):
        raise HostileAnswer(f"{sender} sent an SSDP answer that is not '200 OK'")
    fields: dict[str, str] = {}
    for line in lines[1:]:
        name, sep, value = line.partition(":")
        if sep:
            fields[name.strip().lower()] = value.strip()
    location = fields.get("location", "")
    if not location:
        raise HostileAnswer(f"{sender} sent an SSDP answer without LOCATION")
    check_url(location, sender)
    return SsdpAnswer(sender, clean_text(location, "LOCATION", limit=512),
                      clean_text(fields.get("st"), "ST"), clean_text(fields.get("usn"), "USN"),
                      clean_text(fields.get("server"), "SERVER"))


SSDP_CLOSED_GRACE_S = 0.15   # after the gateway's SSDP port said "closed": a last look


def ssdp_search(timeout: float, *, gateway: str, source_ip: str | None = None,
                notes: list[str] | None = None) -> SsdpAnswer | None:
    """M-SEARCH for an internet gateway; the first valid answer from *gateway* (others noted and
    ignored: a forward only helps on the modem traffic leaves through).

    The unicast search to the gateway goes from a socket of its own, connected: when the gateway
    answers it with "port unreachable" (a modem without UPnP, the usual case), the search ends
    after a short last look instead of waiting out the window (issue 32)."""
    bad = BadAnswers(notes if notes is not None else [], "SSDP")
    deadline = time.monotonic() + timeout
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    uni = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 2)
        if source_ip:
            s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton(source_ip))
            s.bind((source_ip, 0))
            uni.bind((source_ip, 0))
        for st in IGD_TYPES:
            msg = (f"M-SEARCH * HTTP/1.1\r\nHOST: {SSDP_ADDR[0]}:{SSDP_ADDR[1]}\r\n"
                   f"MAN: \"ssdp:discover\"\r\nMX: 1\r\nST: {st}\r\n\r\n")
            s.sendto(msg.encode(), SSDP_ADDR)
        # Unicast to the gateway too: it answers even where multicast routing is missing.
        uni.connect((gateway, SSDP_ADDR[1]))
        uni.send((f"M-SEARCH * HTTP/1.1\r\nHOST: {SSDP_ADDR[0]}:{SSDP_ADDR[1]}\r\n"
                  f"MAN: \"ssdp:discover\"\r\nMX: 1\r\nST: {IGD_TYPES[1]}\r\n\r\n").encode())
        waiting = [s, uni]
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            ready, _w, _x = select.select(waiting, [], [], left)
            if not ready:
                return None
            for sock in ready:
                try:
                    data, (ip, _port) = sock.recvfrom(MAX_DATAGRAM + 1)
                except ConnectionRefusedError:   # the gateway: nothing listens on its SSDP port
                    waiting.remove(uni)
                    bad.notes.append(f"SSDP: {gateway} does not listen for UPnP searches (port "
                                     f"{SSDP_ADDR[1]} closed)")
                    deadline = min(deadline, time.monotonic() + SSDP_CLOSED_GRACE_S)
                    continue
                except BlockingIOError:
                    continue
                try:
                    answer = parse_ssdp(data, ip)
                except HostileAnswer as exc:
                    bad.add(str(exc))
                    continue
                if ip != gateway:
                    bad.add(f"{ip} answered too, but it is not the default gateway ({gateway}): "
                            "ignored")
                    continue
                return answer
    except OSError as exc:
        bad.notes.append(f"SSDP: cannot search the LAN ({exc.strerror or exc})")
        return None
    finally:
        s.close()
        uni.close()
        bad.close()
