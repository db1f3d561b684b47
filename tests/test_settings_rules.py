"""The settings model's rules (rosnet_tui/core/config/settings_model.py), stated one by one at the
layer every reader shares: each key Settings.problems() names (each validator's refusals and
edges: tests/test_settings_validators.py). The TOML loader (tests/test_settings.py,
tests/test_hardening_settings.py) adds line numbers; values a well-typed TOML file cannot hold (a
port that is true, a table that is a number, a line break TOML refuses) reach the model from the
set-up screen and from code, so they are tested here."""

from __future__ import annotations

import pytest

from rosnet_tui.core.config import settings_model as M
from rosnet_tui.core.config.settings_model import (
    Gap,
    Peer,
    RelaySettings,
    RosSettings,
    Settings,
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
