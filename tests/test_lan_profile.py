"""LAN profiles (office, portable): nothing is forwarded, and a phone hotspot cannot forward at
all. The Router step's text, the router card and router.port_open know it (issue 14)."""

from __future__ import annotations

import asyncio
import dataclasses

import pytest

from rosnet_tui.core.checks import REGISTRY, CheckContext, load_builtin_checks, run_check
from rosnet_tui.core.results import Status
from rosnet_tui.core.router_card import build_router_card, render_router_card
from rosnet_tui.core.ssh import SshOptions
from rosnet_tui.core.steps import STEP_BY_ID
from tests.test_router_card import NET, robot

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
    ctx = CheckContext(settings=lan(profile), timeout_s=1.0, state_dir=tmp_path, upnp=False,
                       ssh_options=SshOptions(ssh_agent=False))
    r = asyncio.run(run_check(REGISTRY["router.port_open"], ctx))
    assert r.status is Status.SKIP
    assert f"on the {profile} LAN profile every component is on the same LAN" in r.summary
    assert "nothing needs forwarding" in r.summary and "hotspot cannot forward" in r.summary
    assert r.duration_s < 0.5           # nothing was sent
