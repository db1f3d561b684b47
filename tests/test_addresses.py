"""The one address classification (rosnet_tui/core/addresses.py) and the guards built on it. Each
range is pinned at its edges, so a range cut short or widened (issue 36's survivors: 172.16.0.0/12
treated as public, link-local counted as public, multicast accepted as a component address,
`1.2.3.4` accepted as a host name, a peer with no address accepted) fails here."""

from __future__ import annotations

import ipaddress

import pytest

from rosnet_tui.core import addresses as A
from rosnet_tui.core.checks import isp
from rosnet_tui.core.config.settings_model import Peer, validate_ip, validate_name
from rosnet_tui.core.exposure.public_ip import parse_ip
from rosnet_tui.core.saved.sync_records import address_problem
from rosnet_tui.core.upnp.forwards import wan_kind
from tests.builders import laptop_settings

KINDS = [
    ("0.0.0.0", "unspecified"), ("0.1.2.3", "unspecified"), ("::", "unspecified"),
    ("127.0.0.1", "loopback"), ("127.255.255.254", "loopback"), ("::1", "loopback"),
    ("169.254.0.1", "link-local"), ("169.254.255.254", "link-local"), ("fe80::1%eth0", "link-local"),
    ("224.0.0.1", "multicast"), ("239.255.255.250", "multicast"), ("ff02::1", "multicast"),
    ("255.255.255.255", "broadcast"),
    ("240.0.0.1", "reserved"), ("255.255.255.254", "reserved"), ("198.18.0.1", "reserved"),
    ("10.0.0.1", "private"), ("10.255.255.255", "private"),
    ("172.16.0.1", "private"), ("172.20.1.1", "private"), ("172.31.255.255", "private"),
    ("192.168.0.1", "private"), ("192.168.255.255", "private"), ("fd12::1", "private"),
    ("100.64.0.1", "shared"), ("100.127.255.254", "shared"),
    ("192.0.2.1", "documentation"), ("198.51.100.7", "documentation"),
    ("203.0.113.2", "documentation"), ("2001:db8::1", "documentation"),
    ("172.15.255.255", "public"), ("172.32.0.1", "public"), ("100.63.255.255", "public"),
    ("100.128.0.1", "public"), ("11.0.0.1", "public"), ("169.253.1.1", "public"),
    ("223.255.255.254", "public"), ("8.8.8.8", "public"), ("2606:4700::1111", "public"),
    ("::ffff:10.1.2.3", "private"), ("::ffff:8.8.8.8", "public"),
    ("", "invalid"), ("robot", "invalid"), ("1.2.3", "invalid"), (" 1.2.3.4", "invalid"),
    ("1.2.3.4\u00b9", "invalid"), ("\u0661.2.3.4", "invalid"), ("01.2.3.4", "invalid"),
]


@pytest.mark.parametrize("ip,kind", KINDS)
def test_every_range_at_its_edges(ip, kind):
    assert A.address_kind(ip) == kind


@pytest.mark.parametrize("ip,kind", KINDS)
def test_public_means_the_internet_or_the_documentation_ranges_the_lab_uses(ip, kind):
    v4 = A.is_ipv4(ip)
    assert A.is_public_v4(ip) == (v4 and kind in ("public", "documentation"))
    assert A.is_private(ip) == (kind == "private")
    assert A.is_shared(ip) == (kind == "shared")


@pytest.mark.parametrize("ip", ["172.16.0.1", "172.31.255.255", "10.9.8.7", "192.168.1.1"])
def test_the_private_ranges_are_never_public_anywhere(ip):
    assert not A.is_public_v4(ip)
    assert wan_kind(ip) == "private"
    assert address_problem(ip, public=True) is not None
    assert address_problem(ip) is None                     # a fine local address


@pytest.mark.parametrize("ip", ["169.254.1.1", "127.0.0.1", "0.0.0.0", "224.0.0.1", "240.0.0.1",
                                "255.255.255.255"])
def test_special_addresses_are_never_public(ip):
    assert not A.is_public_v4(ip)
    assert wan_kind(ip) == "none"
    status, _summary, _ = isp.judge_wan(ip, None)
    assert status.value != "pass"


@pytest.mark.parametrize("ip", ["192.0.2.10", "198.51.100.2", "203.0.113.2"])
def test_the_documentation_ranges_stay_usable_as_public_addresses(ip):
    assert A.is_public_v4(ip) and wan_kind(ip) == "public"
    assert address_problem(ip, public=True) is None
    assert validate_ip(ip) is None
    assert parse_ip(ip) == ip
    assert isp.judge_wan(ip, None)[0].value == "pass"


@pytest.mark.parametrize("ip", ["224.0.0.5", "239.1.2.3", "255.255.255.255", "0.0.0.0"])
def test_multicast_broadcast_and_unspecified_are_not_a_components_address(ip):
    assert validate_ip(ip) is not None
    assert address_problem(ip) is not None


@pytest.mark.parametrize("ip", ["169.254.9.9", "127.0.0.1", "240.1.2.3"])
def test_a_records_address_is_never_link_local_loopback_or_reserved(ip):
    assert address_problem(ip) is not None


@pytest.mark.parametrize("name", ["1.2.3.4", "10.0.0.1", "1234"])
def test_an_address_or_a_number_is_not_a_host_name(name):
    assert validate_name(name) is not None


def test_a_peer_with_no_address_is_refused():
    s = laptop_settings()
    assert not [k for k, _ in s.problems() if k.startswith("peer[")]
    s.peers.append(Peer(name="ghost"))
    keys = [k for k, _ in s.problems()]
    assert f"peer[{len(s.peers)}].public_ip" in keys


def test_lan_networks_are_private_or_link_local_blocks():
    for net in ("10.1.0.0/16", "172.16.0.0/12", "172.31.0.0/24", "192.168.5.0/24",
                "169.254.0.0/16", "fe80::/64", "fd00::/8"):
        assert A.is_lan_network(ipaddress.ip_network(net)), net
    for net in ("172.0.0.0/8", "172.32.0.0/16", "100.64.0.0/10", "192.0.2.0/24", "8.8.8.0/24",
                "224.0.0.0/4", "127.0.0.0/8"):
        assert not A.is_lan_network(ipaddress.ip_network(net)), net


def test_loopback_names_and_addresses():
    for host in ("localhost", "127.0.0.1", "127.1.2.3", "::1"):
        assert A.is_loopback(host)
    assert not A.is_loopback_ip("localhost") and A.is_loopback_ip("127.0.0.1")
    for host in ("robot", "10.0.0.1", "0.0.0.0", ""):
        assert not A.is_loopback(host)


def test_an_ipv6_zone_is_dropped_from_the_address():
    """The zone (%eth0) names this machine's interface, not part of the address: it is dropped,
    everything after the first '%' with it, so the address compares and prints bare."""
    for text in ("fe80::1%eth0", "fe80::1%", "fe80::1%a%b"):
        a = A.parse_ip(text)
        assert a == ipaddress.ip_address("fe80::1") and str(a) == "fe80::1", text
    assert A.address_kind("fe80::1%a%b") == "link-local"


@pytest.mark.parametrize("text", ["1.2.3.4%eth0", "10.0.0.1%", "fe80::1%eth\u00e9", None, 5,
                                  b"1.2.3.4"])
def test_an_ipv4_zone_a_non_ascii_zone_or_a_non_text_value_is_not_an_address(text):
    assert A.parse_ip(text) is None
    assert not A.is_ip(text) and not A.is_ipv4(text)
    assert A.address_kind(text) == "invalid"


def test_is_ip_is_any_address_and_is_ipv4_only_ipv4():
    for text in ("203.0.113.2", "10.0.0.1", "2001:db8::1", "::1", "fe80::1%eth0"):
        assert A.is_ip(text), text
    assert A.is_ipv4("203.0.113.2") and not A.is_ipv4("2001:db8::1")
    for text in ("robot", "localhost", "", "203.0.113", "203.0.113.2.1"):
        assert not A.is_ip(text), text


@pytest.mark.parametrize("host", ["localhost", "ip6-localhost", "ip6-loopback"])
def test_the_loopback_names_of_the_hosts_file_are_loopback_but_not_loopback_ips(host):
    assert A.is_loopback(host)
    assert not A.is_loopback_ip(host)
