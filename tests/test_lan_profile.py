"""LAN profiles (office, portable): nothing is forwarded, and a phone hotspot cannot forward at
all. The Router step's text, the router card and router.port_open know it (issue 14)."""

from __future__ import annotations

import asyncio
import dataclasses

import pytest

from rosnet_tui.core.checks import REGISTRY, CheckContext, load_builtin_checks, run_check
from rosnet_tui.core.config.paths import Paths
from rosnet_tui.core.exposure.router_card import build_router_card, render_router_card
from rosnet_tui.core.results import Status
from rosnet_tui.core.ssh.options import SshOptions
from rosnet_tui.core.wizard.steps import STEP_BY_ID, step_for
from tests.builders import ROBOT_NET as NET
from tests.builders import card_robot as robot

load_builtin_checks()


def lan(profile: str):
    s = robot()
    return dataclasses.replace(s, this=dataclasses.replace(s.this, profile=profile))


@pytest.mark.parametrize("profile, where", [("office", "the office LAN"),
                                            ("portable", "the portable hotspot's LAN")])
def test_router_step_text_says_nothing_to_forward(profile, where):
    text = STEP_BY_ID["router"].configure(lan(profile))
    assert f"Nothing to forward on {where}" in text
    assert "A phone hotspot cannot forward ports at all" in text
    assert "1024-65000" not in text and "DMZ host" not in text
    assert "10.10.10.1" in text          # its LAN address must stay fixed
    remote = STEP_BY_ID["router"].configure(robot())
    assert "1024-65000" in remote and "Nothing to forward" not in remote


@pytest.mark.parametrize("markdown", [False, True])
def test_router_card_on_a_lan_profile_has_no_forwarding_and_no_exposure(markdown):
    card = build_router_card(lan("portable"), NET)
    assert card.forwards == [] and card.exposure_warning == [] and card.profile == "portable"
    assert any("hotspot cannot forward" in n for n in card.connection_notes)
    out = render_router_card(card, markdown=markdown)
    assert "none on the portable LAN" in out and "1024-65000" not in out
    assert "Exposure" not in out
    assert "Reserve IP 10.10.10.1" in out          # the reservation still matters
    assert max(len(line) for line in out.splitlines()) <= 80


@pytest.mark.parametrize("profile", ["office", "portable"])
def test_port_open_skips_with_the_reason_on_a_lan_profile(tmp_path, profile):
    ctx = CheckContext(settings=lan(profile), timeout_s=30.0, paths=Paths(state_dir=tmp_path),
                       upnp=False,
                       ssh_options=SshOptions(ssh_agent=False))
    r = asyncio.run(run_check(REGISTRY["router.port_open"], ctx))
    assert r.status is Status.SKIP
    assert f"on the {profile} LAN profile every component is on the same LAN" in r.summary
    assert "nothing needs forwarding" in r.summary and "hotspot cannot forward" in r.summary
    assert r.duration_s < 10.0          # nothing was sent: no wait for the 30 s timeout


# --------------------------------------------------------------------------- LAN and ROS 2
def lan2(profile: str, role: str = "master"):
    """A LAN profile under ROS 2 (rmw_zenoh): the robot as master, or the laptop as member."""
    s = lan(profile)
    this = dataclasses.replace(s.this, role=role, name="turtlebot" if role == "master" else "sami")
    return dataclasses.replace(s, this=this, ros=dataclasses.replace(s.ros, version=2))


@pytest.mark.parametrize("role", ["master", "member"])
def test_router_step_under_ros2_on_a_lan_profile_says_nothing_is_forwarded(role):
    s = lan2("portable", role)
    text = STEP_BY_ID["router"].configure(s)
    assert "Nothing to forward on the portable hotspot's LAN" in text
    assert "Forward **TCP 7447**" not in text and "no DMZ" in text
    assert "TCP **7447**" in text                  # the master's router port, across the LAN
    assert "a chat by name, both ways" not in text  # ROS 2 tests one way only
    expected = step_for("router", s).expected
    assert expected.startswith("Nothing to forward on the portable LAN"), expected
    # The remote profile keeps ROS 2's own text.
    remote = dataclasses.replace(s, this=dataclasses.replace(s.this, profile="remote"))
    assert ("Forward **TCP 7447**" in STEP_BY_ID["router"].configure(remote)) == (role == "master")


@pytest.mark.parametrize("markdown", [False, True])
def test_router_card_under_ros2_on_a_lan_profile_forwards_nothing(markdown):
    card = build_router_card(lan2("office"), NET)
    assert card.forwards == [] and card.dmz_host == "" and card.exposure_warning == []
    out = render_router_card(card, markdown=markdown)
    assert "none on the office LAN" in out and "7447" not in out
    assert "DMZ host" not in out and "Exposure" not in out
    assert "the master's router port" in out and "both ways" not in out
    assert max(len(line) for line in out.splitlines()) <= 80


@pytest.mark.parametrize("role", ["master", "member"])
def test_port_open_under_ros2_skips_for_the_lan_first(tmp_path, role):
    """The LAN skip comes before ROS 2's branch: a master on a LAN is not tested from outside,
    and a member on a LAN is skipped for the LAN's reason, not for being a member."""
    ctx = CheckContext(settings=lan2("office", role), timeout_s=30.0,
                       paths=Paths(state_dir=tmp_path),
                       upnp=False, ssh_options=SshOptions(ssh_agent=False))
    r = asyncio.run(run_check(REGISTRY["router.port_open"], ctx))
    assert r.status is Status.SKIP
    assert "on the office LAN profile every component is on the same LAN" in r.summary
    assert "ROS 2 member" not in r.summary
    assert r.duration_s < 10.0          # no wait for the 30 s timeout
