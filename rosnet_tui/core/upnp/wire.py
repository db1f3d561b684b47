"""What crosses the LAN to the modem: SSDP discovery, a bounded HTTP client, guarded XML.

Everything here assumes the modem may be broken or hostile. Every exchange has a deadline for the
whole exchange (not per read), answers are read up to a fixed size and refused beyond it, XML with
a DOCTYPE or entities is refused before parsing, and an address a modem hands us (LOCATION, a
control URL) must point at the modem that answered, never at another host.
"""

from __future__ import annotations

import ipaddress
import socket
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from urllib.parse import urljoin, urlsplit

SSDP_ADDR = ("239.255.255.250", 1900)
IGD_TYPES = ("urn:schemas-upnp-org:device:InternetGatewayDevice:2",
             "urn:schemas-upnp-org:device:InternetGatewayDevice:1")
MAX_DATAGRAM = 2048        # an SSDP answer is a few hundred bytes
MAX_HEADERS = 8 * 1024     # HTTP status line and headers
MAX_BODY = 64 * 1024       # a root description is 2-8 KiB; a SOAP answer well under 2 KiB
MAX_TEXT = 256             # any single value read from the modem (a description, an address)


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
    try:
        a = ipaddress.ip_address(text.strip())
    except ValueError:
        return None
    return str(a) if a.version == 4 else None


def clean_text(value: str | None, what: str, *, limit: int = MAX_TEXT) -> str:
    """A value from the modem as plain text: refused when too long or full of control bytes."""
    if value is None:
        return ""
    if len(value) > limit:
        raise HostileAnswer(f"the modem's {what} is {len(value)} characters long (more than "
                            f"{limit}): refused")
    if any(ord(c) < 32 and c not in "\t" for c in value):
        raise HostileAnswer(f"the modem's {what} holds control characters: refused")
    return value.strip()


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
    """(host, port, path) of *url*, which must be plain http to *host* itself."""
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
    """Whether a Content-Length answer is all here (chunked ones end when the modem closes)."""
    end = data.find(b"\r\n\r\n")
    if end < 0:
        return False
    for line in bytes(data[:end]).split(b"\r\n")[1:]:
        name, _, value = line.partition(b":")
        if name.strip().lower() == b"content-length" and value.strip().isdigit():
            return len(data) - end - 4 >= int(value.strip())
    return False


def parse_http(data: bytes) -> HttpAnswer:
    end = data.find(b"\r\n\r\n")
    if end < 0 or end > MAX_HEADERS:
        raise HostileAnswer("the modem's answer is not HTTP (no complete header)")
    head = data[:end].decode("latin-1").split("\r\n")
    parts = head[0].split(" ", 2)
    if len(parts) < 2 or not parts[0].startswith("HTTP/1.") or not parts[1].isdigit():
        raise HostileAnswer(f"the modem's answer is not HTTP ({head[0][:60]!r})")
    headers: dict[str, str] = {}
    for line in head[1:]:
        name, sep, value = line.partition(":")
        if not sep:
            raise HostileAnswer(f"the modem sent a broken HTTP header ({line[:60]!r})")
        headers[name.strip().lower()] = value.strip()
    body = data[end + 4:]
    if headers.get("transfer-encoding", "").lower() == "chunked":
        body = _dechunk(body)
    elif "content-length" in headers:
        n = headers["content-length"]
        if not n.isdigit() or int(n) > MAX_BODY:
            raise HostileAnswer(f"the modem announces a body of {n[:20]!r} bytes: refused")
        if len(body) < int(n):
            raise HostileAnswer("the modem closed the connection before the end of its answer")
        body = body[:int(n)]
    if len(body) > MAX_BODY:
        raise HostileAnswer(f"the modem's answer is larger than {MAX_BODY // 1024} KiB: refused")
    return HttpAnswer(int(parts[1]), headers, body)


def _dechunk(body: bytes) -> bytes:
    out, pos = bytearray(), 0
    while True:
        nl = body.find(b"\r\n", pos)
        if nl < 0:
            raise HostileAnswer("the modem's chunked answer is cut short")
        size_text = body[pos:nl].split(b";")[0].strip()
        try:
            size = int(size_text, 16)
        except ValueError:
            raise HostileAnswer("the modem's chunked answer is malformed") from None
        if size == 0:
            return bytes(out)
        out += body[nl + 2:nl + 2 + size]
        if len(out) > MAX_BODY:
            raise HostileAnswer(f"the modem's answer is larger than {MAX_BODY // 1024} KiB: "
                                "refused")
        pos = nl + 2 + size + 2


# --------------------------------------------------------------------------- XML
def parse_xml(body: bytes, what: str) -> ET.Element:
    """Parse the modem's XML, refusing DOCTYPEs and entity declarations outright."""
    head = body[:MAX_BODY].lower()
    if b"<!doctype" in head or b"<!entity" in head:
        raise HostileAnswer(f"the modem's {what} declares a DOCTYPE or entities: refused")
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


def ssdp_search(timeout: float, *, gateway: str, source_ip: str | None = None,
                notes: list[str] | None = None) -> SsdpAnswer | None:
    """M-SEARCH for an internet gateway; the first valid answer from *gateway* (others noted and
    ignored: a forward only helps on the modem traffic leaves through)."""
    notes = notes if notes is not None else []
    deadline = time.monotonic() + timeout
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 2)
        if source_ip:
            s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton(source_ip))
            s.bind((source_ip, 0))
        for st in IGD_TYPES:
            msg = (f"M-SEARCH * HTTP/1.1\r\nHOST: {SSDP_ADDR[0]}:{SSDP_ADDR[1]}\r\n"
                   f"MAN: \"ssdp:discover\"\r\nMX: 1\r\nST: {st}\r\n\r\n")
            s.sendto(msg.encode(), SSDP_ADDR)
        # Unicast to the gateway too: it answers even where multicast routing is missing.
        s.sendto((f"M-SEARCH * HTTP/1.1\r\nHOST: {SSDP_ADDR[0]}:{SSDP_ADDR[1]}\r\n"
                  f"MAN: \"ssdp:discover\"\r\nMX: 1\r\nST: {IGD_TYPES[1]}\r\n\r\n").encode(),
                 (gateway, SSDP_ADDR[1]))
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            s.settimeout(left)
            try:
                data, (ip, _port) = s.recvfrom(MAX_DATAGRAM + 1)
            except TimeoutError:
                return None
            try:
                answer = parse_ssdp(data, ip)
            except HostileAnswer as exc:
                notes.append(f"SSDP: {exc}")
                continue
            if ip != gateway:
                notes.append(f"SSDP: {ip} answered too, but it is not the default gateway "
                             f"({gateway}): ignored")
                continue
            return answer
    except OSError as exc:
        notes.append(f"SSDP: cannot search the LAN ({exc.strerror or exc})")
        return None
    finally:
        s.close()
