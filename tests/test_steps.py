"""The configuration text of each step is tailored to the connection type and the role."""

from __future__ import annotations

import re

import pytest

from rosnet_tui.core.wizard.steps import STEP_BY_ID, STEPS
from tests.builders import seat_settings as settings


def test_four_steps_in_procedure_order():
    assert [s.id for s in STEPS] == ["isp", "router", "linux", "ros"]
    assert [s.number for s in STEPS] == [1, 2, 3, 4]
    for s in STEPS:
        assert s.expected and s.check_ids


@pytest.mark.parametrize("connection, words", [
    ("corporate", ["network administrator", "Wi-Fi router"]),
    ("home", ["nobody to ask", "modem restarts"]),
    ("telecom", ["networking", "100.64.0.0/10", "coverage"]),
])
def test_isp_text_per_connection(connection, words):
    text = STEP_BY_ID["isp"].configure(settings(connection=connection))
    for w in words:
        assert w in text
    others = {"corporate": "network administrator", "home": "nobody to ask",
              "telecom": "100.64.0.0/10"}
    for c, w in others.items():
        if c != connection:
            assert w not in text


def test_router_text_names_this_components_address_and_port():
    s = settings()
    s.probe.port = 23456
    text = STEP_BY_ID["router"].configure(s)
    assert "1024-65000" in text and "10.10.10.1" in text and "23456" in text
    assert "DMZ" in text and "DHCP" in text
    assert "no authentication" in text
    assert "administrator does this step" in STEP_BY_ID["router"].configure(
        settings(connection="corporate"))


def has_entry(text: str, ip: str, name: str) -> bool:
    return re.search(rf"^{re.escape(ip)}\s+{re.escape(name)}$", text, re.M) is not None


def test_linux_text_holds_this_components_hosts_entries():
    master = STEP_BY_ID["linux"].configure(settings("master"))
    assert has_entry(master, "10.10.10.1", "turtlebot")
    assert has_entry(master, "198.51.100.2", "sami")
    member = STEP_BY_ID["linux"].configure(settings("member"))
    assert has_entry(member, "192.168.1.10", "sami")
    assert has_entry(member, "203.0.113.2", "turtlebot")
    office = STEP_BY_ID["linux"].configure(settings("member", profile="office"))
    assert has_entry(office, "172.16.0.5", "turtlebot") and "203.0.113.2" not in office


def test_ros_text_per_role():
    master = STEP_BY_ID["ros"].configure(settings("master"))
    assert "export ROS_MASTER_URI=http://turtlebot:11311" in master
    assert "never its public IP" in master and "roscore" in master
    member = STEP_BY_ID["ros"].configure(settings("member"))
    assert "export ROS_MASTER_URI=http://turtlebot:11311" in member
    assert "is a member" in member
    for text in (master, member):
        assert "ROS_IP" in text and "ROS_HOSTNAME" in text


def _variants():
    """Every combination that changes which checks run: ROS version, role, profile, rosbridge,
    security."""
    for version in (1, 2):
        for role in ("master", "member"):
            for profile in ("remote", "office"):
                for bridge in (False, True):
                    for security in ("", "none"):
                        s = settings(role, profile=profile)
                        s.ros.version = version
                        s.rosbridge.enabled = bridge
                        if security:
                            s.ros.security = security
                        yield s


def test_each_step_lists_exactly_the_checks_the_runner_runs():
    """Issue 29 §4 row 5: a step's list (shown before its checks are loaded) is the runner's
    pick for the settings: under ROS 2 the Linux step listed linux.firewall, which the runner
    never runs there."""
    from rosnet_tui.core.checks.runner import select
    from rosnet_tui.core.wizard.steps import step_for

    for s in _variants():
        for step in STEPS:
            listed = step_for(step.id, s).check_ids
            assert len(set(listed)) == len(listed)
            assert set(listed) == {c.id for c in select([step.id], settings=s)}, \
                (step.id, s.ros, s.rosbridge)


def test_the_steps_declare_each_check_as_it_registers():
    """What a step says of each check (its step, ROS version, switch) is what the check
    registered: the two declarations cannot drift apart."""
    from rosnet_tui.core.checks import REGISTRY, load_builtin_checks
    from rosnet_tui.core.wizard.steps import STEP_CHECKS

    load_builtin_checks()
    declared = {cid: (step, ros, switch) for step, checks in STEP_CHECKS.items()
                for cid, ros, switch in checks}
    assert declared == {c.id: (c.step, c.ros, c.switch) for c in REGISTRY.values()}


def test_the_affected_tables_name_registered_checks_of_the_right_ros():
    """core/affected.py is the one table of which checks a write affects: every id it names is
    a registered check, and the sync service's ROS 2 row names ROS 2 checks only."""
    from rosnet_tui.core import affected
    from rosnet_tui.core.checks import REGISTRY, load_builtin_checks

    load_builtin_checks()
    rows = (affected.HOSTS, affected.ROS_ENV, affected.ROS2_ENV, affected.ROS2_TLS,
            affected.FORWARD, affected.FIREWALL, affected.UNDO, affected.SYNC,
            affected.SYNC_ROS2, affected.ros2_write(True), affected.ros2_write(False))
    assert {i for row in rows for i in row} <= set(REGISTRY)
    assert all(REGISTRY[i].ros != 1 for i in affected.SYNC_ROS2)
    assert affected.SYNC_ROS2 == ("linux.hosts", "linux.resolve", "linux.ssh", "ros2.router")
