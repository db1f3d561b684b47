"""The settings model's rules (rosnet_tui/core/config/settings_model.py), stated one by one at the
layer every reader shares: each validator's refusals and edges, and each key Settings.problems()
names. The TOML loader (tests/test_settings.py, tests/test_hardening_settings.py) adds line numbers;
values TOML cannot hold in a well-typed file (a port that is true, a table that is a number) reach
the model from the set-up screen and from code, so they are tested here."""

from __future__ import annotations

import dataclasses

import pytest

from rosnet_tui.core.addresses import KIND_WORDS
from rosnet_tui.core.config import settings_model as M
from rosnet_tui.core.config.settings_model import (
    FIELD_SHOWN_CHARS,
    Gap,
    Peer,
    RelaySettings,
    RosSettings,
    Settings,
    SettingsError,
    ThisComponent,
)

KEY = "ed25519:" + "A" * 43 + "="


def base() -> Settings:
    """A complete ROS 1 master with one member peer: no problems."""
    return Settings(this=ThisComponent(name="turtlebot", role="master", local_ip="10.10.10.1"),
                    peers=[Peer("sami", local_ip="192.168.1.10", public_ip="198.51.100.2")],
                    ros=RosSettings(master="turtlebot"))


def problems(s: Settings) -> dict[str, list[str]]:
    out: dict[str, list[str]] = {}
    for key, why in s.problems():
        out.setdefault(key, []).append(why)
    return out


def test_the_base_is_complete():
    s = base()
    assert s.problems() == [] and s.complete


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


# --------------------------------------------------------------------------- Settings helpers
def test_who_is_the_master_and_who_runs_rosbridge():
    s = base()
    assert s.is_master and s.master_name == "turtlebot" and not s.ros2 and not s.relayed
    assert s.peer("sami") is s.peers[0] and s.peer("Sami") is None and s.peer("x") is None
    s.ros.master = ""
    assert s.master_name == "turtlebot"                 # a master is its own master
    s.this.role = "member"
    assert not s.is_master and s.master_name == ""
    s.ros.master = "sami"
    assert s.master_name == "sami" and s.rosbridge_host == "sami"
    s.ros.version = 2
    assert s.ros2
    s.relay.host = "relay"
    assert s.relayed and s.relay.enabled and not RelaySettings().enabled


def test_rosbridge_runs_here_only_when_enabled_and_named_so():
    s = base()
    assert s.rosbridge_host == "turtlebot" and not s.hosts_rosbridge      # not enabled
    s.rosbridge.enabled = True
    assert s.hosts_rosbridge
    s.rosbridge.host = "sami"
    assert s.rosbridge_host == "sami" and not s.hosts_rosbridge
    s.rosbridge.host = "TurtleBot"
    assert s.hosts_rosbridge                                               # names ignore case
    s.this.name = ""
    s.rosbridge.host = ""
    s.ros.master = ""
    assert s.rosbridge_host == "" and not s.hosts_rosbridge


# --------------------------------------------------------------------------- problems
def test_blank_names_and_missing_addresses_are_gaps_the_loader_lets_through():
    s = base()
    s.this.name = ""
    s.ros.master = ""
    s.peers.append(Peer("ghost"))
    p = problems(s)
    assert set(p) == {"this.name", "peer[2].public_ip"}
    assert s.errors(allow=(Gap.BLANK,)) == [
        ("peer[2].public_ip", "give the peer a local IP, a public IP, or both")]
    assert s.errors(allow=(Gap.BLANK, Gap.NO_ADDRESS)) == []
    assert s.errors(allow=(Gap.NO_ADDRESS,)) == [("this.name", "a name is required")]
    assert s.errors() == s.problems() and not s.complete


def test_a_blank_peer_name_is_a_gap_not_a_name_used_twice():
    """Blank names are not yet names: a second blank peer, or one beside a blank name of this
    component, is not "used twice" (the loader lets blanks through for the wizard)."""
    s = base()
    s.this.name = s.ros.master = ""
    s.peers += [Peer("", public_ip="203.0.113.3"), Peer("", public_ip="203.0.113.4")]
    p = problems(s)
    assert set(p) == {"this.name", "peer[2].name", "peer[3].name"}, p
    assert p["peer[2].name"] == p["peer[3].name"] == ["a name is required"]
    assert s.errors(allow=(Gap.BLANK,)) == []


def test_a_peer_with_one_address_of_either_kind_is_enough():
    s = base()
    s.peers = [Peer("sami", local_ip="192.168.1.10"), Peer("ops", public_ip="203.0.113.9")]
    assert s.problems() == []


def test_a_member_needs_its_master_named_and_that_is_a_gap():
    s = base()
    s.this.role = "member"
    s.ros.master = ""
    assert problems(s) == {"ros.master": ["a member needs the name of the master"]}
    assert s.errors(allow=(Gap.BLANK,)) == []
    s.this.role = "master"
    assert s.problems() == []


@pytest.mark.parametrize("field_, value, key, words", [
    ("role", "boss", "this.role", "master, member"),
    ("connection", "cable", "this.connection", "corporate, home, telecom"),
    ("profile", "away", "this.profile", "remote, office, portable"),
    ("name", "bad name", "this.name", "spaces"),
    ("local_ip", "300.1.1.1", "this.local_ip", "not an IP"),
    ("public_ip", "224.0.0.1", "this.public_ip", "multicast"),
    ("office_ip", "x", "this.office_ip", "not an IP"),
    ("portable_ip", "0.0.0.0", "this.portable_ip", "no address"),
])
def test_this_components_values(field_, value, key, words):
    s = base()
    setattr(s.this, field_, value)
    p = problems(s)
    assert any(words in w for w in p.get(key, [])), p


@pytest.mark.parametrize("field_", ["role", "connection", "profile"])
def test_every_choice_of_this_component_is_accepted(field_):
    choices = {"role": M.ROLES, "connection": M.CONNECTIONS, "profile": M.PROFILES}[field_]
    for choice in choices:
        s = base()
        setattr(s.this, field_, choice)
        if field_ == "role" and choice == "member":
            s.ros.master = "sami"
        assert s.problems() == [], choice


@pytest.mark.parametrize("field_, value, key, words", [
    ("local_ip", "300.1.1.1", "peer[1].local_ip", "not an IP"),
    ("public_ip", "255.255.255.255", "peer[1].public_ip", "broadcast"),
    ("office_ip", "x", "peer[1].office_ip", "not an IP"),
    ("portable_ip", "2001:db8::1", "peer[1].portable_ip", "IPv4"),
    ("sync_key", "ed25519:x", "peer[1].sync_key", "sync key"),
    ("ssh_user", "r t", "peer[1].ssh_user", "user name"),
    ("ssh_port", 0, "peer[1].ssh_port", "between 1 and 65535"),
    ("ssh_port", 65536, "peer[1].ssh_port", "between 1 and 65535"),
    ("name", "bad name", "peer[1].name", "spaces"),
])
def test_a_peers_values(field_, value, key, words):
    s = base()
    setattr(s.peers[0], field_, value)
    p = problems(s)
    assert any(words in w for w in p.get(key, [])), p


def test_a_peers_ssh_port_may_be_any_port_and_its_key_pinned():
    for port in (1, 22, 2222, 65535):
        s = base()
        s.peers[0].ssh_port = port
        s.peers[0].sync_key = KEY
        assert s.problems() == [], port


def test_a_peer_named_as_this_component_or_as_another_peer_is_refused():
    s = base()
    s.peers.append(Peer("TurtleBot", public_ip="203.0.113.3"))
    s.peers.append(Peer("SAMI", public_ip="203.0.113.4"))
    s.peers.append(Peer("ops", public_ip="203.0.113.5"))
    p = problems(s)
    assert p["peer[2].name"] == ["the name 'TurtleBot' is this component's own name "
                                 "(used twice; names ignore case)"]
    assert p["peer[3].name"] == ["the name 'SAMI' is used twice (names ignore case)"]
    assert "peer[1].name" not in p and "peer[4].name" not in p


@pytest.mark.parametrize("role, master, words", [
    ("master", "nobody", "'nobody' is neither this component nor a peer"),
    ("master", "sami", "this component is the master"),
    ("member", "turtlebot", "this component is a member"),
    ("master", "bad name", "spaces"),
    ("master", "Turtlebot", "neither this component nor a peer"),     # ros.master is exact
])
def test_ros_master_names_the_right_component(role, master, words):
    s = base()
    s.this.role, s.ros.master = role, master
    assert any(words in w for w in problems(s).get("ros.master", [])), problems(s)


def test_a_member_naming_a_peer_as_master_is_fine():
    s = base()
    s.this.role, s.ros.master = "member", "sami"
    assert s.problems() == []


@pytest.mark.parametrize("section, field_, value, key, words", [
    ("ros", "port", 0, "ros.port", "between 1 and 65535"),
    ("ros", "port", 65536, "ros.port", "between 1 and 65535"),
    ("ros", "version", 3, "ros.version", "must be 1"),
    ("ros", "zenoh_port", 1023, "ros.zenoh_port", "between 1024 and 65000"),
    ("ros", "zenoh_port", 65001, "ros.zenoh_port", "between 1024 and 65000"),
    ("ros", "domain_id", 233, "ros.domain_id", "between 0 and 232"),
    ("ros", "security", "mtls", "ros.security", "mutual TLS is for ROS 2"),
    ("ros", "security", "tls", "ros.security", "must be"),
    ("probe", "port", 80, "probe.port", "between 1024 and 65000"),
    ("probe", "port", 11311, "probe.port", "must differ from ros.port (11311)"),
    ("probe", "public_ip_urls", ["https://a", "ftp://b"], "probe.public_ip_urls", "URL"),
    ("probe", "port_check_url", "x", "probe.port_check_url", "URL"),
    ("checks", "timeout_s", 0.09, "checks.timeout_s", "between 0.1 and 120"),
    ("checks", "timeout_s", 121, "checks.timeout_s", "between 0.1 and 120"),
    ("checks", "timeout_s", True, "checks.timeout_s", "between 0.1 and 120"),
    ("rosbridge", "enabled", "yes", "rosbridge.enabled", "true or false"),
    ("rosbridge", "port", 0, "rosbridge.port", "between 1 and 65535"),
    ("rosbridge", "host", "nobody", "rosbridge.host", "'nobody' is neither this component nor a "
     "peer"),
    ("rosbridge", "host", "bad name", "rosbridge.host", "spaces"),
    ("firewall", "allow", ["203.0.113.7", "0.0.0.0/0"], "firewall.allow", "whole internet"),
    ("sync", "store", "s3", "sync.store", "folder, dns"),
    ("sync", "interval_s", 0.5, "sync.interval_s", "between 1 and 86400"),
    ("sync", "interval_s", 86401, "sync.interval_s", "between 1 and 86400"),
    ("sync", "dns_server", "ns1", "sync.dns_server", "not an IP"),
    ("sync", "zone", "bad zone", "sync.zone", "spaces"),
    ("sync", "zone", ".", "sync.zone", "a zone name is required"),
])
def test_each_sections_value_is_checked(section, field_, value, key, words):
    s = base()
    setattr(getattr(s, section), field_, value)
    p = problems(s)
    assert any(words in w for w in p.get(key, [])), p
    assert set(p) == {key}, p


def test_a_zone_of_only_dots_is_a_gap_but_a_wrong_zone_is_not():
    s = base()
    s.sync.zone = "."
    assert s.errors(allow=(Gap.BLANK,)) == []
    s.sync.zone = "bad zone"
    assert s.errors(allow=(Gap.BLANK,)) != []


@pytest.mark.parametrize("section, field_, value", [
    ("ros", "port", 1), ("ros", "port", 65535), ("ros", "version", 2), ("ros", "zenoh_port", 1024),
    ("ros", "zenoh_port", 65000), ("ros", "domain_id", 232), ("ros", "security", "none"),
    ("probe", "port", 1024), ("probe", "port", 65000), ("probe", "public_ip_urls", []),
    ("checks", "timeout_s", 0.1), ("checks", "timeout_s", 120), ("checks", "timeout_s", 3),
    ("rosbridge", "enabled", True), ("rosbridge", "port", 65535), ("rosbridge", "host", "SAMI"),
    ("rosbridge", "host", "turtlebot"), ("firewall", "allow", ["203.0.113.0/24"]),
    ("sync", "store", "dns"), ("sync", "interval_s", 1), ("sync", "interval_s", 86400),
    ("sync", "dns_server", "192.0.2.53"), ("sync", "zone", "robots.example."),
    ("sync", "zone", "X."), ("sync", "zone", "X"),
])
def test_each_sections_edge_values_are_accepted(section, field_, value):
    s = base()
    setattr(getattr(s, section), field_, value)
    assert s.problems() == []


def test_the_probe_port_equal_to_the_ros_port_is_refused_only_when_it_is_a_probe_port():
    s = base()
    s.probe.port = s.ros.port = 2000
    assert problems(s) == {"probe.port": ["must differ from ros.port (2000): the test port is "
                                          "open to anyone on the internet, the ROS master's port "
                                          "is not"]}
    s.probe.port = s.ros.port = 80          # out of the probe's range: that is said, once
    assert problems(s) == {"probe.port": ["the port must be between 1024 and 65000"]}


@pytest.mark.parametrize("value, lo, hi, ok", [
    (1, 1, 2, True), (2, 1, 2, True), (1.5, 1, 2, True), (0.99, 1, 2, False), (2.01, 1, 2, False),
    (10**400, 1, 2, False), (True, 0, 2, False), (float("nan"), 0, 2, False),
    (float("inf"), 0, float("inf"), False), ("1", 0, 2, False), (None, 0, 2, False),
])
def test_a_number_within_bounds_is_a_real_finite_number(value, lo, hi, ok):
    assert M.number_within(value, lo, hi) == ok


# --------------------------------------------------------------------------- [relay]
def relayed() -> Settings:
    s = base()
    s.ros.version = 2
    s.relay = RelaySettings(host="relay", tunnels={"turtlebot": 2201, "sami": 2202})
    return s


def test_a_relay_with_its_tunnels_is_fine_and_no_relay_is_nothing_to_check():
    assert relayed().problems() == []
    s = base()
    s.ros.version = 2
    assert s.problems() == [] and s.relay == RelaySettings()


def test_a_relay_under_ros_1_is_refused_alone():
    s = relayed()
    s.ros.version = 1
    s.ros.security = "firewall"
    s.relay.ssh_port = 0                      # not said: the relay itself is the problem
    p = problems(s)
    assert list(p) == ["relay.host"] and "ROS 2 only" in p["relay.host"][0]


@pytest.mark.parametrize("change, key, words", [
    (dict(host=""), "relay.host", "relay's name is required"),
    (dict(host="bad name"), "relay.host", "spaces"),
    (dict(host="SAMI"), "relay.host", "'SAMI' is a component's name"),
    (dict(ssh_user="r t"), "relay.ssh_user", "user name"),
    (dict(ssh_port=0), "relay.ssh_port", "between 1 and 65535"),
    (dict(zenoh_port=1023), "relay.zenoh_port", "between 1024 and 65000"),
    (dict(tunnels=5), "relay.tunnels", "table of component name = port"),
    (dict(tunnels={"turtlebot": 2201, "Sami": 2201}), "relay.tunnels.Sami", "port 2201 is "
     "turtlebot's too"),
    (dict(tunnels={"robby": 2201}), "relay.tunnels.robby", "neither this component nor a peer"),
    (dict(tunnels={"bad name": 2201}), "relay.tunnels.bad name", "spaces"),
    (dict(tunnels={"sami": 1023}), "relay.tunnels.sami", "between 1024 and 65535"),
    (dict(tunnels={"sami": True}), "relay.tunnels.sami", "true/false"),
    (dict(tunnels={"sami": "x"}), "relay.tunnels.sami", "not a port number"),
])
def test_a_relays_values(change, key, words):
    s = relayed()
    for k, v in change.items():
        setattr(s.relay, k, v)
    p = problems(s)
    assert any(words in w for w in p.get(key, [])), p
    assert set(p) == {key}, p


def test_a_relay_tunnel_port_edges():
    for port in (1024, 65535):
        s = relayed()
        s.relay.tunnels = {"sami": port}
        assert s.problems() == [], port


def test_a_relay_takes_only_mutual_tls():
    s = relayed()
    s.ros.security = "firewall"
    p = problems(s)
    assert list(p) == ["ros.security"] and "security must be \"mtls\"" in p["ros.security"][0]


# --------------------------------------------------------------------------- line breaks in values
LINE_BREAKS = ["\n", "\r", "\u2028", "\u2029", "\x85", "\x0b", "\x0c", "\x1c", "\x1d", "\x1e"]


@pytest.mark.parametrize("sep", LINE_BREAKS)
def test_a_line_break_in_a_typed_value_is_refused_in_one_line(sep):
    """A settings file cannot hold VT, FF or FS..RS at all (the loader refuses them as not valid
    TOML, tests/test_hardening_settings.py), but the set-up screen's fields and code hand the
    model any string: every field refuses them, and the refusal quotes the value on one line."""
    s = base()
    s.this.name = f"turtle{sep}bot"
    s.this.local_ip = f"10.10.10.1{sep}"
    s.peers[0].public_ip = f"{sep}198.51.100.2"
    s.peers[0].ssh_user = f"ops{sep}"
    s.peers[0].sync_key = KEY + sep
    s.probe.port_check_url = f"https://ifconfig.co{sep}"
    s.probe.public_ip_urls = [f"https://ifconfig.co/ip{sep}x"]
    s.firewall.allow = [f"203.0.113.7{sep}/24"]     # around an entry, white space is trimmed
    s.relay.host = f"relay{sep}"
    s.relay.tunnels = {f"sa{sep}mi": 2202, "turtlebot": 2202}
    s.ros.domain_id = f"1{sep}2"
    s.ros.version = 2
    s.ros.master = f"robot{sep}x"
    s.rosbridge.host = f"sa{sep}mi"
    p = problems(s)
    for key in ("this.name", "this.local_ip", "peer[1].public_ip", "peer[1].ssh_user",
                "peer[1].sync_key", "probe.port_check_url", "probe.public_ip_urls",
                "firewall.allow", "relay.host", "ros.master", "rosbridge.host",
                f"relay.tunnels.sa{sep}mi", "relay.tunnels.turtlebot", "ros.domain_id"):
        assert key in p, key
        for why in p[key]:
            assert not any(c in why for c in LINE_BREAKS), (key, why)
            assert why.splitlines() == [why], (key, why)


@pytest.mark.parametrize("value", ["https://ifconfig.co/ip x", "https://ifconfig.co\x07",
                                   "https://a/\u200b", "https://a b/ip"])
def test_a_url_is_refused_with_a_space_or_an_invisible_character_anywhere(value):
    assert "not an http:// or https:// URL" in M.validate_url(value)


def test_a_url_may_have_a_path_a_port_and_a_query():
    for value in ("https://ifconfig.co/ip", "http://192.0.2.1:8080/port/12345?x=1&y=%20",
                  "https://ifconfig.co/"):
        assert M.validate_url(value) is None, value


def test_a_wrong_name_is_an_error_the_loader_refuses_not_a_gap():
    for where in ("this", "peer", "master", "zone"):
        s = base()
        if where == "this":
            s.this.name = s.ros.master = "bad name"
        elif where == "peer":
            s.peers[0].name = "bad name"
        elif where == "master":
            s.this.role, s.ros.master = "member", "bad name"
        else:
            s.sync.zone = "bad zone."
        assert s.errors(allow=(Gap.BLANK, Gap.NO_ADDRESS)), where
