"""Names a technician cannot give a component (issue 12): refused by the core, so the wizard, the
headless commands and a hand-edited file all say the same."""

from __future__ import annotations

import pytest

from rosnet_tui.core.config.settings_model import shown, validate_ip, validate_name
from tests.builders import named_settings as settings


@pytest.mark.parametrize("name", ["localhost", "LocalHost", "ip6-localhost", "ip6-allnodes",
                                  "localhost.localdomain"])
def test_names_the_hosts_file_gives_this_machine_are_reserved(name):
    assert "reserved" in (validate_name(name) or "")


@pytest.mark.parametrize("name", ["turtlebot", "sami-laptop", "ip6", "mylocalhost"])
def test_ordinary_names_pass(name):
    assert validate_name(name) is None


def test_names_equal_but_for_case_are_refused():
    problems = dict(settings("sami", "SAMI").problems())
    assert "ignore case" in problems["peer[2].name"]
    problems = dict(settings("TurtleBot").problems())
    assert "own name" in problems["peer[1].name"]
    assert not settings("sami", "ops").problems()


def test_values_echoed_in_messages_are_cut():
    why = validate_ip("9" * 5000) or ""
    assert len(why) < 100 and "..." in why
    assert shown("abc") == "abc"
    assert len(validate_name("localhost" + "-x" * 100 + ".localdomain") or "") < 120
