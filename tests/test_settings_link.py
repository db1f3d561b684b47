"""[[link.topic]] (issue 31): what the robot's link must carry, parsed, validated (the line, the
key and the reason; exit 2 at the CLI), saved back, and summed as the check compares it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from rosnet_tui.core.config.settings_model import LinkTopic, SettingsError
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
LINK = """\
[[link.topic]]            # the camera, compressed
name = "/camera/image/compressed"
bytes = 50000
hz = 10

[[link.topic]]
name = "/points"
bytes = 200000
hz = 10
max_hz = 2
"""


def test_the_issue_example_parses_and_sums_bits_per_second():
    s = parse_settings(BASE + LINK)
    assert s.link.topics == [LinkTopic("/camera/image/compressed", 50000, 10),
                             LinkTopic("/points", 200000, 10, 2)]
    # 50 kB x 10 Hz x 8 = 4.0 Mbit/s; the cloud counts at max_hz: 200 kB x 2 x 8 = 3.2 Mbit/s
    assert s.link.need_bps() == 4_000_000 + 3_200_000 and s.complete


def test_no_link_section_needs_nothing():
    s = parse_settings(BASE)
    assert s.link.topics == [] and s.link.need_bps() == 0


def test_saved_back_with_its_comments_and_new_values(tmp_path: Path):
    path = tmp_path / "config.toml"
    path.write_text(BASE + LINK)
    s = load_settings(path)
    save_settings(s, path)
    assert "# the camera, compressed" in path.read_text()
    s.link.topics[1].max_hz = None
    save_settings(s, path)
    again = load_settings(path)
    assert again.link.topics[1] == LinkTopic("/points", 200000, 10, None)
    s.link.topics = []
    save_settings(s, path)
    assert "link" not in path.read_text() and load_settings(path).link.topics == []


def test_a_fresh_file_gets_its_link_topics(tmp_path: Path):
    s = parse_settings(BASE + LINK)
    path = tmp_path / "new.toml"
    save_settings(s, path)
    assert load_settings(path).link == s.link


def refusal(text: str) -> SettingsError:
    with pytest.raises(SettingsError) as info:
        parse_settings(text)
    return info.value


@pytest.mark.parametrize("old,new,key,words", [
    ("bytes = 50000", "bytes = 0", "link.topic.bytes", "whole number of bytes"),
    ("bytes = 50000", "bytes = 5.5", "link.topic.bytes", "whole number"),
    ("bytes = 50000", 'bytes = "50 kB"', "link.topic.bytes", "whole number"),
    ("hz = 10\n\n", "hz = 0\n\n", "link.topic.hz", "above 0"),
    ("hz = 10\n\n", "hz = -1\n\n", "link.topic.hz", "above 0"),
    ("hz = 10\n\n", "hz = nan\n\n", "link.topic.hz", "above 0"),
    ("hz = 10\n\n", "hz = true\n\n", "link.topic.hz", "a number"),
    ("max_hz = 2", "max_hz = 0", "link.topic.max_hz", "above 0"),
    ("max_hz = 2", "max_hz = inf", "link.topic.max_hz", "above 0"),
    ('name = "/points"', 'name = "/po ints"', "link.topic.name", "not a ROS topic name"),
    ('name = "/points"', 'name = "/points/"', "link.topic.name", "not a ROS topic name"),
    ('name = "/points"', 'name = "/1points"', "link.topic.name", "not a ROS topic name"),
    ('name = "/points"', 'topic = "/points"', "link.topic.topic", "unknown key"),
])
def test_bad_values_name_the_line_and_key(old, new, key, words):
    text = BASE + LINK.replace(old, new)
    err = refusal(text)
    assert err.key == key and words in err.message, err
    first = new.split(" = ")[0]
    lines = text.split("\n")
    assert err.line is not None and lines[err.line - 1].startswith(first + " ="), err


def test_a_topic_without_its_rate_is_refused():
    err = refusal(BASE + '[[link.topic]]\nname = "/scan"\nbytes = 3000\n')
    assert err.key == "link.topic.hz" and "needs hz" in err.message and err.line == 10


def test_link_written_as_a_single_table_is_refused():
    err = refusal(BASE + '[link.topic]\nname = "/scan"\nbytes = 3000\nhz = 5\n')
    assert err.key == "link.topic" and "[[link.topic]]" in err.message
    err = refusal(BASE + '[link]\nspeed = 5\n')
    assert err.key == "link.speed" and "unknown key" in err.message


def test_cli_refuses_a_bad_need_with_exit_2(tmp_path: Path):
    cfg = tmp_path / "c.toml"
    cfg.write_text(BASE + LINK.replace("hz = 10\n\n", "hz = 0\n\n"))
    out = subprocess.run([sys.executable, "-m", "rosnet_tui", "--config", str(cfg), "hosts",
                          "show"], capture_output=True, text=True, timeout=60,
                         stdin=subprocess.DEVNULL)
    assert out.returncode == 2, out.stdout + out.stderr
    assert "link.topic.hz" in out.stderr and "above 0" in out.stderr
    assert "Traceback" not in out.stderr


def test_max_hz_becomes_downsampling_on_the_routers_tls_link_only():
    """`ros apply` writes the router's config from router_config: a topic with max_hz is cut down
    to that rate on what leaves the router over TLS (the router-to-router link), and a real Zenoh
    router takes the rules as written."""
    import json

    import zenoh

    from rosnet_tui.core.ros import ros2
    from tests.builders import ros2_member as member

    s = member()
    s.link.topics = [LinkTopic("/camera/image/compressed", 50000, 10, 2),
                     LinkTopic("/scan", 3000, 20)]
    cfg = ros2.router_config(s)
    assert cfg["downsampling"] == [{
        "id": "wan_max_hz", "link_protocols": ["tls"], "flows": ["egress"], "messages": ["put"],
        "rules": [{"key_expr": "0/camera/image/compressed/**", "freq": 2.0}]}]
    assert '"downsampling"' in ros2.render_router_config(s)
    check = {"mode": "router", "listen": {"endpoints": ["tcp/127.0.0.1:0"]},
             "scouting": {"multicast": {"enabled": False}}, "downsampling": cfg["downsampling"]}
    zenoh.open(zenoh.Config.from_json5(json.dumps(check))).close()
    # no max_hz, or no mutual TLS (the WAN link cannot be told from the local ones): none
    assert "downsampling" not in ros2.router_config(member())
    s = member(security="none")
    s.link.topics = [LinkTopic("/camera/image/compressed", 50000, 10, 2)]
    assert "downsampling" not in ros2.router_config(s)
