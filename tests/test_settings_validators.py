"""The settings model's validators (rosnet_tui/core/config/settings_model.py), one by one: each
refusal with its reason and each edge that is accepted, at the layer every reader shares (the
loader, the set-up screen, the sync records). The keys Settings.problems() names:
tests/test_settings_rules.py."""

from __future__ import annotations

import dataclasses

import pytest

from rosnet_tui.core.addresses import KIND_WORDS
from rosnet_tui.core.config import settings_model as M
from rosnet_tui.core.config.settings_model import (
    FIELD_SHOWN_CHARS,
    RosSettings,
    SettingsError,
)

KEY = "ed25519:" + "A" * 43 + "="


# --------------------------------------------------------------------------- shown, echoed
@pytest.mark.parametrize("c", ["\n", "\x07", "\x7f", "\u200b", "\u2028", "\u2029", "\ud800"])
def test_shown_escapes_line_breaks_and_invisible_characters(c):
    out = M.shown("a" + c + "b")
    assert c not in out and out.startswith("a\\") and out.endswith("b")
    assert out == "a" + c.encode("unicode_escape").decode() + "b"


def test_shown_keeps_ordinary_text_and_cuts_at_the_limit_saying_the_length():
    assert M.shown("caf\u00e9 \u00e0 r\u00f4bot 1") == "caf\u00e9 \u00e0 r\u00f4bot 1"
    assert M.shown("x" * M.SHOWN_VALUE_CHARS) == "x" * M.SHOWN_VALUE_CHARS
    long = "x" * (M.SHOWN_VALUE_CHARS + 1)
    assert M.shown(long) == "x" * M.SHOWN_VALUE_CHARS + f"... ({M.SHOWN_VALUE_CHARS + 1} characters)"
    assert M.shown("abcdef", 3) == "abc... (6 characters)"
    assert M.shown("abc", 3) == "abc"


def test_shown_names_a_huge_number_instead_of_printing_it():
    assert M.shown(10**30) == "a huge number" and M.shown(-(10**30)) == "a huge number"
    assert M.shown(10**30 - 1) == "9" * 30
    assert M.shown(-5) == "-5" and M.shown(2.5) == "2.5"


def test_echoed_keeps_a_field_value_on_one_short_line():
    assert M.echoed("a" * FIELD_SHOWN_CHARS) == "a" * FIELD_SHOWN_CHARS
    cut = M.echoed("a" * (FIELD_SHOWN_CHARS + 1))
    assert cut == "a" * (FIELD_SHOWN_CHARS - 3) + "..." and len(cut) == FIELD_SHOWN_CHARS
    assert M.echoed("a\nb") == "a\\nb"
    assert M.echoed("\n" * 100).startswith("\\n") and len(M.echoed("\n" * 100)) == FIELD_SHOWN_CHARS


def test_a_settings_error_says_where_then_why_on_one_line():
    e = SettingsError("bad\nvalue", path=M.Path("/c.toml"), line=3, key="this.name")
    assert str(e) == "/c.toml, line 3, key 'this.name': bad\\nvalue"
    assert (e.line, e.key, e.message) == (3, "this.name", "bad\\nvalue")
    assert str(SettingsError("why")) == "why"
    assert str(SettingsError("why", line=0)) == "line 0: why"
    assert str(SettingsError("why", key="k")) == "key 'k': why"
    assert SettingsError("why").key is None
    assert str(SettingsError("why", path=M.Path("/p"))) == "/p: why"


def test_a_settings_error_carries_its_line_as_its_argument():
    e = SettingsError("why", line=2)
    assert e.args == ("line 2: why",)


def test_a_port_too_big_to_print_is_out_of_range():
    assert M.validate_port(10**5000) == "the port must be between 1024 and 65000"


def test_a_settings_error_cuts_its_message_and_key():
    e = SettingsError("m" * 1000, key="k" * 1000)
    assert e.message.startswith("m" * 300 + "... (1000") and e.key.startswith("k" * 80 + "... (")
    assert len(str(e)) < 450


# --------------------------------------------------------------------------- names
@pytest.mark.parametrize("value, words", [
    ("", "required"), ("turtle bot", "spaces"), ("turtle\tbot", "spaces"), (" x", "spaces"),
    ("a_b", "letters, digits"), ("-x", "letters, digits"), ("x-", "letters, digits"),
    ("a..b", "letters, digits"), ("a" * 64, "letters, digits"),
    ("1.2.3.4", "only digits"), ("1234", "only digits"), ("10.0.0.1", "only digits"),
    ("localhost", "reserved"), ("BroadcastHost", "reserved"), ("ip6-allrouters", "reserved"),
    ("IP6-x", "reserved"), ("localhost.localdomain", "reserved"),
])
def test_a_name_is_refused_with_the_reason(value, words):
    assert words in (M.validate_name(value) or ""), value


def test_a_reserved_name_is_quoted_in_the_refusal():
    assert "'localhost'" in M.validate_name("localhost")


@pytest.mark.parametrize("value", ["a", "turtlebot", "sami-laptop", "robot.lab", "r2d2", "1a",
                                   "a" * 63, "ip6", "localhost2", "mylocalhost"])
def test_a_name_is_accepted(value):
    assert M.validate_name(value) is None


def test_a_name_is_at_most_253_characters():
    label = "a" * 63
    ok = ".".join([label] * 3 + ["a" * 61])          # 253
    assert len(ok) == 253 and M.validate_name(ok) is None
    assert M.validate_name(ok + "a") is not None     # 254, every label still fine


# --------------------------------------------------------------------------- sync key
def test_a_sync_key_is_ed25519_and_32_bytes_or_empty():
    assert M.validate_sync_key("") is None and M.validate_sync_key(KEY) is None
    for bad in ("ed25519:" + "A" * 43, "ssh-ed25519 " + "A" * 43 + "=", KEY + "x", "x" + KEY,
                "ed25519:" + "A" * 42 + "B=", "ed25519:" + "A" * 42 + "==", KEY + "\n"):
        assert "sync key" in (M.validate_sync_key(bad) or ""), bad


# --------------------------------------------------------------------------- addresses
@pytest.mark.parametrize("value", ["10.10.10.1", "172.16.0.1", "192.168.1.10", "203.0.113.2",
                                   "100.64.0.1", "169.254.3.4", "127.0.0.1"])
def test_a_component_address_may_be_any_unicast_ipv4(value):
    assert M.validate_ip(value) is None


@pytest.mark.parametrize("value, kind", [
    ("0.0.0.0", "unspecified"), ("224.0.0.5", "multicast"), ("239.255.255.250", "multicast"),
    ("255.255.255.255", "broadcast"),
])
def test_a_component_address_is_never_unspecified_multicast_or_broadcast(value, kind):
    assert M.validate_ip(value) == f"{value} cannot be a component's address ({KIND_WORDS[kind]})"


@pytest.mark.parametrize("value, words", [
    ("2001:db8::1", "use an IPv4 address"), ("::ffff:10.0.0.1", "use an IPv4 address"),
    ("abc", "'abc' is not an IP address"), ("10.10.10", "'10.10.10' is not an IP address"),
])
def test_a_component_address_is_ipv4(value, words):
    assert words in (M.validate_ip(value) or "")


def test_an_empty_address_is_refused_only_when_required():
    assert "required" in M.validate_ip("")
    assert M.validate_ip("", required=False) is None
    assert M.validate_ip("abc", required=False) is not None


# --------------------------------------------------------------------------- ports
@pytest.mark.parametrize("value, lo, hi, ok", [
    (1024, 1024, 65000, True), (65000, 1024, 65000, True), (1023, 1024, 65000, False),
    (65001, 1024, 65000, False), (" 2000 ", 1024, 65000, True), ("2000", 1024, 65000, True),
    (1, 1, 65535, True), (65535, 1, 65535, True), (0, 1, 65535, False), (65536, 1, 65535, False),
    ("x", 1, 65535, False), ("", 1, 65535, False), ("2.5", 1, 65535, False),
])
def test_a_port_is_a_whole_number_within_its_bounds(value, lo, hi, ok):
    assert (M.validate_port(value, lo=lo, hi=hi) is None) == ok


def test_the_port_bounds_default_to_the_forwarding_range_and_are_said():
    assert M.validate_port(1023) == "the port must be between 1024 and 65000"
    assert M.validate_port(1) == M.validate_port(65001) != None     # noqa: E711
    assert M.validate_port(80, lo=1, hi=100) is None
    assert "'x'" in M.validate_port("x") and "not a port number" in M.validate_port("x")


@pytest.mark.parametrize("value", [True, False])
def test_a_port_is_not_true_or_false(value):
    """TOML holds a boolean where a port goes only in a file the loader refuses by type; the set-up
    screen and code hand the model any value, and True is 1 to int()."""
    assert "true/false" in M.validate_port(value, lo=0, hi=65535)


# --------------------------------------------------------------------------- [firewall] allow
@pytest.mark.parametrize("value", ["203.0.113.7", "203.0.113.0/24", " 203.0.113.7 ",
                                   "2001:db8::/48", "2001:db8::1", "10.0.0.0/8", "192.0.2.0/32",
                                   "1.0.0.0/8"])
def test_an_allow_entry_is_an_address_or_a_network(value):
    assert M.validate_network(value) is None


@pytest.mark.parametrize("value, words", [
    (7, "in quotes"), ("", "in quotes"), ("   ", "in quotes"), (None, "in quotes"),
    ("fe80::1%eth0", "without its zone"), ("robot", "not an address or a network"),
    ("203.0.113.0/33", "not an address or a network"),
    ("203.0.113.7/24", "bits set after the prefix: write the network 203.0.113.0/24"),
    ("0.0.0.0/0", "the whole internet"), ("::/0", "the whole internet"),
    ("224.0.0.0/4", "where a login comes from"), ("ff02::1", "where a login comes from"),
    ("127.0.0.1", "where a login comes from"), ("127.0.0.0/8", "where a login comes from"),
    ("::1", "where a login comes from"), ("0.0.0.0", "where a login comes from"),
    ("0.0.0.0/8", "where a login comes from"), ("::", "where a login comes from"),
])
def test_an_allow_entry_is_refused_with_the_reason(value, words):
    why = M.validate_network(value) or ""
    assert words in why, value
    if isinstance(value, str) and value.strip():
        assert why.startswith(f"'{value}'"), why          # the entry at fault is quoted


# --------------------------------------------------------------------------- users, urls
@pytest.mark.parametrize("value, ok", [
    ("", True), ("ops", True), ("Ops", True), ("_svc", True), ("a.b-c_1", True), ("a" * 32, True),
    ("a" * 33, False), ("1ops", False), ("r t", False), ("-x", False), ("ops\n", False),
    ("\u00e9", False),
])
def test_an_ssh_user_name(value, ok):
    assert (M.validate_ssh_user(value) is None) == ok


def test_a_refused_ssh_user_is_quoted():
    assert M.validate_ssh_user("r t") == "'r t' is not a valid user name"


@pytest.mark.parametrize("value, ok", [
    ("https://ifconfig.co", True), ("http://ifconfig.co/ip", True), ("HTTPS://x", False),
    ("ftp://x", False), ("https://", False), ("https:// x", False), ("", False), (None, False),
    ("xhttps://a", False),
])
def test_a_probe_url_is_http_or_https_with_a_host(value, ok):
    assert (M.validate_url(value) is None) == ok


# --------------------------------------------------------------------------- ROS
@pytest.mark.parametrize("env, version", [
    ({"ROS_VERSION": "2"}, 2), ({"ROS_VERSION": " 2\n"}, 2), ({"ROS_VERSION": "1"}, 1),
    ({"ROS_VERSION": "3"}, 1), ({"ROS_VERSION": ""}, 1), ({}, 1), ({"ROS_DISTRO": "jazzy"}, 1),
])
def test_the_default_ros_version_comes_from_the_environment(env, version):
    assert M.default_ros_version(env) == version
    assert M.new_settings(env).ros.version == version


def test_the_default_ros_version_reads_the_process_environment(monkeypatch):
    monkeypatch.setenv("ROS_VERSION", "2")
    assert M.default_ros_version() == 2 and M.new_settings().ros.version == 2
    monkeypatch.delenv("ROS_VERSION")
    assert M.default_ros_version() == 1 and M.new_settings().ros.version == 1


@pytest.mark.parametrize("value, ok", [(1, True), (2, True), ("2", True), (" 1 ", True),
                                       (0, False), (3, False), ("x", False), ("1.0", False)])
def test_a_ros_version_is_1_or_2(value, ok):
    assert (M.validate_ros_version(value) is None) == ok


@pytest.mark.parametrize("value, ok", [(0, True), (232, True), (" 7 ", True), (-1, False),
                                       (233, False), ("x", False)])
def test_a_domain_id_is_0_to_232(value, ok):
    assert (M.validate_domain_id(value) is None) == ok


def test_a_domain_id_refusal_says_why():
    assert M.validate_domain_id(233) == "must be between 0 and 232"
    assert M.validate_domain_id("x") == "'x' is not a whole number"


def test_security_defaults_to_mtls_for_ros_2_and_the_firewall_for_ros_1():
    assert M.default_security(2) == "mtls" and M.default_security(1) == "firewall"
    assert M.validate_security("mtls", 2) is None
    assert "ROS 2" in M.validate_security("mtls", 1)
    for v in (1, 2):
        assert M.validate_security("firewall", v) is None and M.validate_security("none", v) is None
        assert "must be" in M.validate_security("tls", v)
        assert M.validate_security("", v) is not None


def test_an_unchosen_security_follows_the_version():
    r = RosSettings(version=2)
    assert r.security == "mtls" and not r.security_chosen()
    r.version = 1
    assert r.security == "firewall" and not r.security_chosen()
    again = dataclasses.replace(RosSettings(version=2), version=1)   # passes the default back
    assert again.security == "firewall" and not again.security_chosen()
    assert RosSettings.security == ""


def test_a_chosen_security_stays_whatever_the_version():
    r = RosSettings(version=2, security="none")
    assert r.security == "none" and r.security_chosen()
    r.version = 1
    assert r.security == "none"
    assert dataclasses.replace(r, version=2).security == "none"
    r.security = "firewall"
    assert r.security == "firewall" and r.security_chosen()
