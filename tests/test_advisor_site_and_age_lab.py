"""Issue 21's two advisor defects on the network lab: real checks, the real CLI, the first advice.

1. ROS 2, from the member (sami): the master's Zenoh port refused and its SSH refused or
   unanswered. Two ways to get there: the robot's modem forwarding nothing and resetting every
   TCP connection; and the robot behind the carrier's NAT, the carrier resetting TCP 7447 and
   dropping the rest (what the issue saw). First advice: the master's modem or provider, worded
   as what was seen; never "No Zenoh router runs on turtlebot".
2. ROS 1, from the laptop: the robot's modem drops everything from outside (ping too). The
   settings file written minutes ago (or a sync record of turtlebot's of 3 min ago) dates the
   address: the modem's forwarding / firewall leads, with the age. Settings of 40 days ago and
   no sync record: the stale address still leads, with its age.

The lab is changed only from here (iptables rules in the lab's own namespaces, removed in a
finally); tests/lab/*.py is not touched.
"""

from __future__ import annotations

import os
import re
import time

import pytest

from tests.advisor_support import explain_report, first_failure_in, lab_report
from tests.lab.ros2 import Ros2World
from tests.lab.topology import ADDR

pytestmark = pytest.mark.lab
DAY = 86400.0


def rules(lab, ns: str, add: list[str]):
    """Insert iptables *add* rules (``-I ...`` argument strings) in *ns*; returns the undo."""
    for a in add:
        lab._in_ns(ns, f"iptables {a}")

    def undo() -> None:
        for a in add:
            lab._in_ns(ns, "iptables " + a.replace("-I ", "-D ", 1), check=False)
    return undo


# --------------------------------------------------------------------------- 1. ROS 2
def addr_of(how: str) -> str:
    return ADDR.ROBOT_PUBLIC if how == "modem_resets" else ADDR.CARRIER_PUBLIC


def laptop_config(ros2_world: Ros2World, tmp_path, robot_public: str):
    """sami's ROS 2 settings, turtlebot at *robot_public* (its hosts line says the same)."""
    from dataclasses import replace

    from rosnet_tui.core.saved.settings import atomic_write_text, render_settings

    s = ros2_world.settings("laptop")
    s = replace(s, peers=[replace(p, public_ip=robot_public) for p in s.peers])
    path = tmp_path / "config.toml"
    atomic_write_text(path, render_settings(s), mode=0o644)
    return path


@pytest.mark.parametrize("how", ["modem_resets", "carrier_nat"])
def test_zenoh_port_refused_and_ssh_shut_out_leads_with_the_masters_modem_or_isp(ros2_world, how,
                                                                               tmp_path):
    lab = ros2_world.lab
    ros2_world.healthy()
    undo = None
    try:
        if how == "modem_resets":
            ros2_world.forward(robot="refuse")
            said = "refused too"
        else:
            lab._set_cgnat(True)
            lab.write_hosts("laptop", lab.hosts_path("laptop").read_text().replace(
                ADDR.ROBOT_PUBLIC, ADDR.CARRIER_PUBLIC))
            undo = rules(lab, "carrier", ["-I INPUT -p tcp --dport 7447 -j REJECT "
                                          "--reject-with tcp-reset"])
            said = "did not answer either"
        env = dict(ros2_world.env("laptop"), XDG_STATE_HOME=str(tmp_path))
        doc = lab_report(lab, "laptop", laptop_config(ros2_world, tmp_path, addr_of(how)), env)
    finally:
        if undo:
            undo()
        if how == "carrier_nat":
            lab._set_cgnat(False)
        ros2_world.healthy()
    checks = {c["id"]: c for c in doc["checks"]}
    assert checks["ros2.router"]["data"]["failure"] == "refused", explain_report(doc)
    first = first_failure_in(doc)
    assert first["rule"] == "ros2.port.not_forwarded" and first["goto_step"] == "router", \
        explain_report(doc)
    addr = addr_of(how)
    assert first["meaning"].startswith(
        f"turtlebot's Zenoh port ({addr}:7447) refused sami's connection and its SSH port 22 "
        f"{said}: "), explain_report(doc)
    assert "modem or its provider" in first["meaning"] and "carrier-grade NAT" in first["meaning"]
    assert "isp.cgnat" in first["actions"][0]
    everything = " ".join(f["meaning"] for f in doc["findings"])
    assert "No Zenoh router runs" not in everything and "most likely sshd" not in everything


# --------------------------------------------------------------------------- 2. ROS 1
SILENT_MODEM = ["-I INPUT -i wan0 -m conntrack --ctstate NEW -j DROP",
                "-I FORWARD -i wan0 -m conntrack --ctstate NEW -j DROP"]


def silent_robot_seen_from_the_laptop(lab, tmp_path, *, settings_age_s: float = 0.0,
                                      sync_age_s: float | None = None) -> dict:
    lab.reset()
    cfg = lab.config_path("laptop")
    if settings_age_s:
        then = time.time() - settings_age_s
        os.utime(cfg, (then, then))
    state = tmp_path / "state"
    if sync_age_s is not None:
        from rosnet_tui.core.saved.sync_applied import save_applied
        from rosnet_tui.core.saved.sync_records import new_record
        save_applied(state / "rosnet-tui", {"turtlebot": new_record(
            "turtlebot", local_ip=ADDR.ROBOT_LOCAL, public_ip=ADDR.ROBOT_PUBLIC, role="master",
            now=time.time() - sync_age_s)})
    undo = rules(lab, "robot_modem", SILENT_MODEM)
    try:
        doc = lab_report(lab, "laptop", cfg, dict(lab.ros_env("laptop"), XDG_STATE_HOME=str(state)))
    finally:
        undo()
        lab.reset()
    checks = {c["id"]: c for c in doc["checks"]}
    ping = checks["linux.ping"]["data"]["peers"]["turtlebot"]
    assert ping["icmp"] is False and ping["tcp"] == "timeout", explain_report(doc)
    return doc


def test_silent_modem_with_an_address_saved_minutes_ago_leads_with_forwarding(ros1_lab, tmp_path):
    doc = silent_robot_seen_from_the_laptop(ros1_lab, tmp_path, settings_age_s=180)
    first = first_failure_in(doc)
    assert first["rule"] == "linux.peer.unreachable" and first["goto_step"] == "router", \
        explain_report(doc)
    assert ("most likely turtlebot's modem does not forward port 22 to turtlebot (or its "
            "firewall drops it)") in first["meaning"], first
    assert re.search(r"203\.0\.113\.2 was confirmed [34] min ago \(settings saved\)",
                     first["meaning"]), first
    assert first["actions"][0].startswith("Check that turtlebot's modem forwards TCP 22")


def test_silent_modem_with_a_fresh_sync_record_leads_with_forwarding(ros1_lab, tmp_path):
    doc = silent_robot_seen_from_the_laptop(ros1_lab, tmp_path, settings_age_s=40 * DAY,
                                            sync_age_s=180)
    first = first_failure_in(doc)
    assert first["goto_step"] == "router", explain_report(doc)
    assert re.search(r"203\.0\.113\.2 was confirmed [34] min ago \(turtlebot's own sync "
                     r"record\)", first["meaning"]), first


def test_silent_modem_with_an_old_address_leads_with_the_address(ros1_lab, tmp_path):
    doc = silent_robot_seen_from_the_laptop(ros1_lab, tmp_path, settings_age_s=40 * DAY)
    first = first_failure_in(doc)
    assert first["rule"] == "linux.peer.unreachable" and first["goto_step"] == "linux", \
        explain_report(doc)
    assert "most likely 203.0.113.2 is not turtlebot's address any more" in first["meaning"]
    assert "203.0.113.2 was last confirmed 40 days ago (settings saved)" in first["meaning"]
