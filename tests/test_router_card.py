"""The router card: exact values for the modem's web page, warnings, and an 80-column rendering."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import uuid
from dataclasses import asdict
from pathlib import Path

import pytest

from rosnet_tui.core.exposure.router_card import build_router_card, render_router_card
from rosnet_tui.core.net.netinfo import LocalNet
from tests.builders import ROBOT_NET as NET
from tests.builders import card_robot as robot

REPO = Path(__file__).resolve().parent.parent
def test_card_values_forward_range_to_local_ip_and_reserve_it_for_the_mac():
    card = build_router_card(robot(), NET)
    tcp = card.forwards[0]
    assert (tcp.protocol, tcp.external_ports, tcp.internal_ip, tcp.internal_ports, tcp.required) \
        == ("TCP", "1024-65000", "10.10.10.1", "1024-65000", True)
    assert card.forwards[1].protocol == "UDP" and not card.forwards[1].required
    assert card.dmz_host == "10.10.10.1"
    assert (card.reservation_ip, card.reservation_mac) == ("10.10.10.1", "02:00:0a:0a:0a:01")
    assert card.modem_page == "http://10.10.10.254/"
    assert card.warnings == [] and card.missing == []
    json.dumps(asdict(card))  # plain data, ready for the UI or a report


def test_exposure_warning_names_the_master_port_ssh_and_the_allowed_sources():
    text = " ".join(build_router_card(robot(), NET).exposure_warning)
    assert "no authentication" in text and "11311" in text and "SSH" in text
    assert "198.51.100.2 (sami)" in text and "keys only" in text


@pytest.mark.parametrize("connection, words", [
    ("corporate", ["administrator"]),
    ("telecom", ["carrier-grade NAT", "100.64.0.0/10"]),
    ("home", ["http://10.10.10.254/", "Port forwarding"]),
])
def test_connection_notes(connection, words):
    text = " ".join(build_router_card(robot(connection), NET).connection_notes)
    for w in words:
        assert w in text


def test_settings_that_disagree_with_the_machine_are_flagged():
    card = build_router_card(robot(local_ip="10.10.10.7"), NET)
    assert card.forwards[0].internal_ip == "10.10.10.7"
    assert any("10.10.10.1" in w and "10.10.10.7" in w for w in card.warnings)


def test_missing_facts_say_how_to_find_them():
    card = build_router_card(robot(interface="eth9"), LocalNet(interface="eth9"))
    text = " ".join(card.missing)
    assert "ip link show eth9" in text and "default via" in text


@pytest.mark.parametrize("markdown", [False, True])
@pytest.mark.parametrize("connection", ["corporate", "home", "telecom"])
def test_rendering_fits_80_columns_and_carries_every_value(markdown, connection):
    card = build_router_card(robot(connection, local_ip="192.168.100.200"),
                             LocalNet("enx00e04c680001", "192.168.100.201", "192.168.100.1",
                                      "00:e0:4c:68:00:01", "255.255.255.0"))
    out = render_router_card(card, markdown=markdown)
    assert max(len(x) for x in out.splitlines()) <= 80
    for value in ("1024-65000", "192.168.100.200", "00:e0:4c:68:00:01", "http://192.168.100.1/",
                  "DMZ", "11311"):
        assert value in out
    if markdown:
        assert "| TCP | 1024-65000 | 192.168.100.200 | 1024-65000 | required |" in out


@pytest.mark.skipif(os.geteuid() != 0 or not shutil.which("ip"),
                    reason="an interface in a private namespace needs root and ip(8)")
def test_mac_is_read_from_the_real_interface():
    """An interface with a known MAC (a veth pair with both ends inside a namespace of the
    test's own, so nothing touches the root namespace)."""
    ns = f"rosnet-card-{uuid.uuid4().hex[:8]}"
    if subprocess.run(["ip", "netns", "add", ns], capture_output=True, timeout=10).returncode:
        pytest.skip("cannot create a network namespace here")
    try:
        script = ("ip link add dummy7 address 02:42:ac:11:00:07 type veth peer name dummy7b && "
                  "ip addr add 10.77.0.5/24 dev dummy7 && ip link set dummy7 up")
        r = subprocess.run(["ip", "netns", "exec", ns, "sh", "-c", script], capture_output=True,
                           text=True, timeout=10)
        if r.returncode:
            pytest.skip(f"no veth interfaces here: {r.stderr.strip()}")
        code = ("from rosnet_tui.core.exposure.router_card import build_router_card;"
                "from rosnet_tui.core.config.settings_model import Settings, ThisComponent;"
                "s = Settings(this=ThisComponent(name='turtlebot', interface='dummy7'));"
                "c = build_router_card(s); print(c.mac, c.local_ip)")
        out = subprocess.run(["ip", "netns", "exec", ns, sys.executable, "-c", code],
                             capture_output=True, text=True, timeout=30, cwd=REPO,
                             env=dict(os.environ, PYTHONPATH=str(REPO)))
        assert out.stdout.split() == ["02:42:ac:11:00:07", "10.77.0.5"], out.stderr
    finally:
        subprocess.run(["ip", "netns", "delete", ns], capture_output=True, timeout=10)


# --------------------------------------------------------------------------- what is exposed
def _exposure(s) -> str:
    return " ".join(build_router_card(s, NET).exposure_warning)


def _ros2(security: str = "", role: str = "master"):
    s = robot()
    s.ros.version = 2
    if security:
        s.ros.security = security
    if role == "member":
        s.this.role, s.ros.master = "member", "sami"
    return s


def test_ros2_with_mutual_tls_says_only_fleet_certificates_get_in():
    """Issue 29 §4 row 3: under ROS 2 with mutual TLS (the default) the card said rmw_zenoh has
    no authentication and whoever reaches 7447 joins."""
    text = _exposure(_ros2())
    assert "certificate" in text and "7447" in text
    assert "no authentication" not in text and "joins" not in text


def test_ros2_without_tls_warns_of_the_opt_out():
    text = _exposure(_ros2("none"))
    assert 'security = "none"' in text and "no authentication" in text and "7447" in text


def test_a_ros2_member_exposes_no_ros_port():
    text = _exposure(_ros2(role="member"))
    assert "7447" not in text and "joins" not in text and "keys only" in text


def test_ros1_with_the_firewall_says_who_gets_in():
    """ROS 1's default: the peers-only firewall decides who reaches the range, not the forward."""
    text = _exposure(robot())
    assert "peers-only firewall" in text and "addresses you allow" in text
    assert "firewall apply" in text and "whole internet" not in text


def test_ros1_without_the_firewall_exposes_everything_to_everyone():
    s = robot()
    s.ros.security = "none"
    text = _exposure(s)
    assert "whole internet" in text and 'security = "none"' in text
    assert "addresses you allow" not in text
