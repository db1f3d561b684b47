"""[relay] (issue 30): parsed, validated, saved back with [relay.tunnels]; refused under ROS 1
and wherever a value cannot work, with the line, the key and the reason (exit 2 at the CLI)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from rosnet_tui.core.config.settings_model import RelaySettings, SettingsError
from rosnet_tui.core.saved.settings import load_settings, parse_settings, save_settings

BASE = """\
[this]
name = "turtlebot"
role = "master"
[[peer]]
name = "sami"
local_ip = "192.168.1.10"
[ros]
version = 2
master = "turtlebot"
"""
RELAY = """\
[relay]
host = "relay"          # the public server's name
ssh_user = "root"
ssh_port = 22
zenoh_port = 7447
[relay.tunnels]         # the relay's loopback port of each component's sshd
turtlebot = 2201
sami = 2202
"""


def test_the_issue_example_parses():
    s = parse_settings(BASE + RELAY)
    assert s.relay == RelaySettings(host="relay", ssh_user="root", ssh_port=22, zenoh_port=7447,
                                    tunnels={"turtlebot": 2201, "sami": 2202})
    assert s.relayed and s.complete


def test_no_relay_section_is_no_relay():
    s = parse_settings(BASE)
    assert s.relay == RelaySettings() and not s.relayed


def test_saved_back_with_its_tunnels_and_comments(tmp_path: Path):
    path = tmp_path / "config.toml"
    path.write_text(BASE + RELAY)
    s = load_settings(path)
    s.relay.tunnels = {"sami": 2203}
    s.relay.zenoh_port = 7448
    save_settings(s, path)
    text = path.read_text()
    assert "# the public server's name" in text and "[relay.tunnels]" in text
    again = load_settings(path)
    assert again.relay.tunnels == {"sami": 2203} and again.relay.zenoh_port == 7448


def test_a_fresh_file_gets_relay_and_tunnels_tables(tmp_path: Path):
    s = parse_settings(BASE + RELAY)
    path = tmp_path / "new.toml"
    save_settings(s, path)
    assert load_settings(path).relay == s.relay
    s.relay.tunnels = {}
    save_settings(s, path)
    assert "tunnels" not in path.read_text() and load_settings(path).relay.host == "relay"


def refusal(text: str) -> SettingsError:
    with pytest.raises(SettingsError) as info:
        parse_settings(text)
    return info.value


def test_refused_under_ros_1_with_the_reason():
    err = refusal(BASE.replace("version = 2", "version = 1") + RELAY)
    assert err.key == "relay.host" and err.line == 11
    assert "ROS 2 only" in err.message and "version = 2" in err.message


def test_refused_under_ros_1_taken_from_the_environment(monkeypatch):
    monkeypatch.delenv("ROS_VERSION", raising=False)
    err = refusal(BASE.replace("version = 2\n", "") + RELAY)
    assert err.key == "relay.host" and "ROS 2 only" in err.message


@pytest.mark.parametrize("old,new,key,words", [
    ('host = "relay"', 'host = "turtlebot"', "relay.host", "component's name"),
    ('host = "relay"', 'host = "re lay"', "relay.host", "spaces"),
    ('host = "relay"', 'host = ""', "relay.host", "required"),
    ("zenoh_port = 7447", "zenoh_port = 80", "relay.zenoh_port", "between"),
    ("zenoh_port = 7447", 'zenoh_port = "7447"', "relay.zenoh_port", "whole number"),
    ("ssh_port = 22", "ssh_port = 70000", "relay.ssh_port", "between"),
    ('ssh_user = "root"', 'ssh_user = "r t"', "relay.ssh_user", "user name"),
    ("sami = 2202", "sami = 2201", "relay.tunnels.sami", "one port per component"),
    ("sami = 2202", "sami = 22", "relay.tunnels.sami", "between"),
    ("sami = 2202", 'sami = "2202"', "relay.tunnels.sami", "port number"),
    ("sami = 2202", "sami = true", "relay.tunnels.sami", "port number"),
    ("sami = 2202", "robby = 2202", "relay.tunnels.robby", "neither this component nor a peer"),
    ('ssh_user = "root"', 'user = "root"', "relay.user", "unknown key"),
])
def test_bad_values_name_the_line_and_key(old, new, key, words):
    text = BASE + RELAY.replace(old, new)
    err = refusal(text)
    assert err.key == key and words in err.message, err
    assert err.line == text.split("\n").index(next(
        ln for ln in text.split("\n") if ln.startswith(new.split(" = ")[0] + " ="))) + 1


def test_tunnels_must_be_a_table():
    err = refusal(BASE + '[relay]\nhost = "relay"\ntunnels = 5\n')
    assert err.key == "relay.tunnels" and "table" in err.message


def test_a_relay_takes_fleet_certificates_only():
    err = refusal(BASE.replace("master = \"turtlebot\"", "master = \"turtlebot\"\n"
                               "security = \"none\"") + RELAY)
    assert err.key == "ros.security" and "mtls" in err.message


def test_cli_refuses_ros_1_relay_settings_with_exit_2(tmp_path: Path):
    cfg = tmp_path / "c.toml"
    cfg.write_text(BASE.replace("version = 2", "version = 1") + RELAY)
    out = subprocess.run([sys.executable, "-m", "rosnet_tui", "--config", str(cfg), "hosts",
                          "show"], capture_output=True, text=True, timeout=60,
                         stdin=subprocess.DEVNULL)
    assert out.returncode == 2, out.stdout + out.stderr
    assert "relay.host" in out.stderr and "ROS 2 only" in out.stderr
    assert "Traceback" not in out.stderr
