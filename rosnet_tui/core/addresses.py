"""What kind of address an IP is: the one place that knows every special range.

:func:`address_kind` names the range an address lies in; the questions the product asks (is it a
component's public address? a LAN's? loopback?) are answered from it. The documentation ranges
(192.0.2.0/24, 198.51.100.0/24, 203.0.113.0/24, 2001:db8::/32) are kept apart as
``"documentation"`` and count as public: no real network uses them, and the lab uses them as its
internet, so a check that passes in the lab must pass there too.
"""

from __future__ import annotations

import ipaddress

IpNetwork = ipaddress.IPv4Network | ipaddress.IPv6Network

_NETS = {
    "unspecified": ("0.0.0.0/8",),                     # "this network": never a host's address
    "loopback": ("127.0.0.0/8",),
    "link-local": ("169.254.0.0/16", "fe80::/10"),
    "multicast": ("224.0.0.0/4", "ff00::/8"),
    "broadcast": ("255.255.255.255/32",),
    "reserved": ("240.0.0.0/4",),
    "private": ("10.0.0.0/8", "172.16.0.0/12", "192.168.0.0/16", "fc00::/7"),
    "shared": ("100.64.0.0/10",),                      # the carriers' NAT (RFC 6598)
    "documentation": ("192.0.2.0/24", "198.51.100.0/24", "203.0.113.0/24", "2001:db8::/32"),
}
_ORDER = tuple((kind, ipaddress.ip_network(n)) for kind, nets in _NETS.items() for n in nets)
PUBLIC_KINDS = ("public", "documentation")
LAN_KINDS = ("private", "link-local")      # the blocks a LAN may be numbered from
KIND_WORDS = {
    "unspecified": "no address at all", "loopback": "a loopback address",
    "link-local": "a link-local address", "multicast": "a multicast address",
    "broadcast": "the broadcast address", "reserved": "a reserved address",
    "private": "a private (LAN) address", "shared": "an address of the carriers' shared range "
    "100.64.0.0/10 (carrier-grade NAT)", "documentation": "a documentation address",
    "public": "a public address", "invalid": "not an IP address",
}


def parse_ip(text: str) -> ipaddress.IPv4Address | ipaddress.IPv6Address | None:
    """*text* as an address (an IPv6 zone such as %eth0 dropped), or None when it is not one
    (no spaces around it, ASCII digits only)."""
    if not isinstance(text, str) or not text.isascii():
        return None
    try:
        return ipaddress.ip_address(text.split("%", 1)[0] if ":" in text else text)
    except ValueError:
        return None


def address_kind(text: str) -> str:
    """One of: invalid, unspecified, loopback, link-local, multicast, broadcast, reserved,
    private, shared, documentation, public. IPv4-mapped IPv6 is classed as its IPv4 address."""
    a = parse_ip(text)
    if a is None:
        return "invalid"
    if isinstance(a, ipaddress.IPv6Address) and a.ipv4_mapped is not None:
        a = a.ipv4_mapped
    if a.is_unspecified:
        return "unspecified"
    if a.is_loopback:
        return "loopback"
    for kind, net in _ORDER:
        if a.version == net.version and a in net:
            return kind
    # Anything else outside the global internet (IETF protocol assignments, benchmarking, ...).
    return "public" if a.is_global else "reserved"


def is_ip(text: str) -> bool:
    """True when *text* is an IPv4 or IPv6 address, not a name."""
    return parse_ip(text) is not None


def is_ipv4(text: str) -> bool:
    a = parse_ip(text)
    return a is not None and a.version == 4


def is_loopback(host: str) -> bool:
    """True for loopback names and addresses (localhost, 127.0.0.0/8, ::1)."""
    if host in ("localhost", "ip6-localhost", "ip6-loopback"):
        return True
    return address_kind(host) == "loopback"


def is_loopback_ip(text: str) -> bool:
    """A loopback IP address (names such as localhost do not count)."""
    return address_kind(text) == "loopback"


def is_public_v4(text: str) -> bool:
    """An IPv4 address of the internet (documentation ranges included: the lab's internet)."""
    return is_ipv4(text) and address_kind(text) in PUBLIC_KINDS


def is_private(text: str) -> bool:
    """A home or office LAN address (10/8, 172.16/12, 192.168/16, fc00::/7)."""
    return address_kind(text) == "private"


def is_shared(text: str) -> bool:
    """An address of the carriers' shared range 100.64.0.0/10 (carrier-grade NAT)."""
    return address_kind(text) == "shared"


def is_lan_network(net: IpNetwork) -> bool:
    """True when *net* lies inside a private, link-local or unique-local block."""
    return any(kind in LAN_KINDS and net.version == block.version
               and net.subnet_of(block)  # type: ignore[arg-type]
               for kind, block in _ORDER)

