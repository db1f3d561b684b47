"""Settings: the documented schema round-trips; bad files fail with line and key, never a traceback."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from rosnet_tui.core.config.settings_model import (
    Peer,
    Settings,
    SettingsError,
    validate_ip,
    validate_name,
    validate_port,
)
from rosnet_tui.core.saved.settings import (
    load_settings,
    parse_settings,
    render_settings,
    save_settings,
)

DOC_EXAMPLE = """\
[this]
name = "turtlebot"        # this component's network name
role = "master"           # "master" | "member"
connection = "telecom"    # "corporate" | "home" | "telecom"
profile = "remote"        # "remote" | "office" | "portable": which hosts set is in effect
[[peer]]
name = "sami"
local_ip = "192.168.1.10"
public_ip = "198.51.100.2"
ssh_user = "ops"          # optional; enables checks run from the peer's side
[ros]
master = "turtlebot"      # name of the component that runs roscore
port = 11311
[probe]
port = 12345              # test port, 1024-65000
public_ip_urls = ["https://ifconfig.co/ip"]   # each answers the caller's IP as plain text
port_check_url = "https://ifconfig.co"         # echoip protocol: GET {url}/port/N -> {"ip","port","reachable"}
"""


def test_documented_example_parses_and_is_complete():
    s = parse_settings(DOC_EXAMPLE)
    assert s.this.name == "turtlebot" and s.this.role == "master"
    assert s.this.connection == "telecom" and s.this.profile == "remote"
    assert s.peers == [Peer("sami", "192.168.1.10", "198.51.100.2", "ops")]
    assert s.ros.master == "turtlebot" and s.ros.port == 11311
    assert s.probe.port == 12345
    assert s.probe.public_ip_urls == ["https://ifconfig.co/ip"]
    assert s.probe.port_check_url == "https://ifconfig.co"
    assert s.complete


def test_round_trip_keeps_values_and_user_comments(tmp_path: Path):
    path = tmp_path / "config.toml"
    path.write_text(DOC_EXAMPLE)
    s = load_settings(path)
    s.peers.append(Peer("operator2", local_ip="192.168.1.11", public_ip="198.51.100.7"))
    s.probe.port = 23456
    save_settings(s, path)
    text = path.read_text()
    assert "# name of the component that runs roscore" in text  # the user's comment survives
    again = load_settings(path)
    assert again == s
    assert [p.name for p in again.peers] == ["sami", "operator2"]


def test_fresh_file_round_trips(tmp_path: Path):
    s = Settings()
    s.this.name, s.this.role, s.ros.master = "sami", "member", "turtlebot"
    s.peers = [Peer("turtlebot", "10.10.10.1", "203.0.113.2", "root")]
    path = tmp_path / "sub" / "config.toml"
    save_settings(s, path)
    assert load_settings(path) == s
    assert oct(path.stat().st_mode & 0o777) == "0o600"
    assert not [p for p in path.parent.iterdir() if p.name.startswith(".")]  # no temp files left


def test_missing_file_is_none(tmp_path: Path):
    assert load_settings(tmp_path / "nope.toml") is None


@pytest.mark.parametrize("text, line, key, words", [
    ('[this]\nname = "turtle bot"\n', 2, "this.name", "spaces"),
    ('[this]\nname = "x"\n[[peer]]\nname = "sami"\npublic_ip = "300.1.2.3"\n', 5,
     "peer.public_ip", "not an IP"),
    ('[this]\nname = "x"\n[probe]\nport = 80\n', 4, "probe.port", "between 1024 and 65000"),
    ('[this]\nnmae = "x"\n', 2, "this.nmae", "unknown key"),
    ('[this]\nname = "x"\n[ros]\nport = "11311"\n', 4, "ros.port", "whole number"),
    ('[this]\nname = "x"\nrole = "boss"\n', 3, "this.role", "master, member"),
    ('[weird]\na = 1\n', 1, "weird", "unknown section"),
    ('[this]\nname = "x\n', 2, None, "not valid TOML"),
    ('[this]\nname = "x"\n[[peer]]\nname = "sami"\npublic_ip = "203.0.113.2"\n'
     'ssh_user = "ops\\n"\n', 6, "peer.ssh_user", "not a valid user name"),
    ('[this]\nname = "x"\n[[peer]]\nname = "sami"\npublic_ip = "203.0.113.2"\n'
     'sync_key = "ed25519:' + "A" * 43 + '=\\n"\n', 6, "peer.sync_key", "not a sync key"),
])
def test_malformed_files_name_line_and_key(tmp_path: Path, text, line, key, words):
    path = tmp_path / "config.toml"
    path.write_text(text)
    with pytest.raises(SettingsError) as info:
        load_settings(path)
    err = info.value
    assert err.line == line
    assert err.key == key
    assert words in str(err)
    assert str(path) in str(err)


def test_save_refuses_to_clobber_a_malformed_file(tmp_path: Path):
    path = tmp_path / "config.toml"
    path.write_text("[this\nname = oops\n")
    with pytest.raises(SettingsError):
        save_settings(Settings(), path)
    assert path.read_text() == "[this\nname = oops\n"


def test_non_utf8_file_is_a_clear_error(tmp_path: Path):
    path = tmp_path / "config.toml"
    path.write_bytes(b"\xff\xfe[this]")
    with pytest.raises(SettingsError, match="UTF-8"):
        load_settings(path)


def test_incomplete_settings_say_what_is_missing():
    s = parse_settings('[this]\nrole = "member"\n')
    keys = [k for k, _ in s.problems()]
    assert "this.name" in keys and "ros.master" in keys
    assert not s.complete


def test_render_is_stable():
    s = parse_settings(DOC_EXAMPLE)
    once = render_settings(s)
    assert render_settings(parse_settings(once), once) == once


@pytest.mark.parametrize("value, ok", [("turtlebot", True), ("sami-laptop", True),
                                       ("robot.lab", True), ("turtle bot", False), ("", False),
                                       ("-x", False), ("1234", False), ("a_b", False)])
def test_validate_name(value, ok):
    assert (validate_name(value) is None) == ok


@pytest.mark.parametrize("value, ok", [("10.10.10.1", True), ("203.0.113.2", True),
                                       ("10.10.10", False), ("::1", False), ("0.0.0.0", False),
                                       ("abc", False)])
def test_validate_ip(value, ok):
    assert (validate_ip(value) is None) == ok


@pytest.mark.parametrize("value, ok", [(1024, True), ("65000", True), (1023, False),
                                       (65001, False), ("x", False)])
def test_validate_port(value, ok):
    assert (validate_port(value) is None) == ok


def test_xdg_config_home_is_honoured(monkeypatch, tmp_path):
    from rosnet_tui.core.config.paths import default_config_path

    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path))
    assert default_config_path() == tmp_path / "rosnet-tui" / "config.toml"
    assert os.fspath(default_config_path()).startswith(str(tmp_path))
