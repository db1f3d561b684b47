"""The situations of issue 14 on the network lab: the real checks, the real CLI, and the first
advice naming the real cause and its step.

- the robot's modem does not forward, seen from both seats (a modem that refuses, one that drops);
- the robot got a new local IP from DHCP, its modem still forwards to the old one (settings with
  local_ip, and the documented settings without it, where only the history tells);
- a travel router of the user's own between the robot and its correctly forwarding modem;
- a LAN profile: nothing to forward, the port test skips with the reason;
- the robot's sshd on another port than the settings say.
"""

from __future__ import annotations

import dataclasses
import json

import pytest

from rosnet_tui.core.saved.settings import atomic_write_text, render_settings
from tests.advisor_support import explain_report, first_failure_in, lab_report

pytestmark = pytest.mark.lab

T1 = "table1.listener_up_closed"


def _env(lab, host: str, state) -> dict:
    return dict(lab.ros_env(host), XDG_STATE_HOME=str(state))


def config(lab, host: str, path, **this) -> str:
    """*host*'s settings with some [this] values changed, written to *path*."""
    s = lab.settings(host)
    s = dataclasses.replace(s, this=dataclasses.replace(s.this, **this))
    atomic_write_text(path, render_settings(s), mode=0o644)
    return str(path)


def report(lab, host: str, state, *args: str, cfg: str | None = None) -> dict:
    return lab_report(lab, host, cfg or lab.config_path(host), _env(lab, host, state), *args,
                      timeout=120)


def check(lab, host: str, state, *args: str, cfg: str | None = None) -> dict[str, dict]:
    r = lab.rosnet(host, "check", "--json", "-q", "--config", cfg or str(lab.config_path(host)),
                   *args, env=_env(lab, host, state), timeout=120)
    assert r.stdout.strip(), r.stderr
    return {c["id"]: c for c in json.loads(r.stdout)["checks"]}


# --------------------------------------------------------------------------- no forwarding
def test_refusing_modem_seen_from_the_robot_router_step(ros1_lab, tmp_path):
    """The wizard's Router step on the robot (telecom): only router.* ran. Refused at the public
    address: the forwarding comes first, not the carrier."""
    with ros1_lab.variant("no_forwarding", refuse=True):
        checks = check(ros1_lab, "robot", tmp_path, "--step", "router")
    po = checks["router.port_open"]
    assert po["status"] == "fail"
    assert po["data"]["ports"][0]["answer"] == "refused"
    assert po["data"]["public_ip_ping"] is True
    first = po["advice"][0]
    assert first["rule"] == f"{T1}.forwarding" and first["goto_step"] == "router", po["advice"]
    assert "was refused" in first["meaning"] and "the modem is online" in first["meaning"]


def test_refusing_modem_seen_from_the_laptop(ros1_lab, tmp_path):
    with ros1_lab.variant("no_forwarding", refuse=True):
        doc = report(ros1_lab, "laptop", tmp_path)
    first = first_failure_in(doc)
    assert first["rule"] == "linux.ssh.refused" and first["goto_step"] == "router", explain_report(doc)
    assert "refuses the ROS master's port 11311 as well" in first["meaning"]
    assert first["actions"][0].startswith("Check that turtlebot's modem forwards TCP 22")


def test_dropping_modem_seen_from_both_seats(ros1_lab, tmp_path):
    with ros1_lab.variant("no_forwarding"):
        robot = report(ros1_lab, "robot", tmp_path / "robot")
        laptop = report(ros1_lab, "laptop", tmp_path / "laptop")
    first = first_failure_in(robot)
    assert first["rule"] == f"{T1}.forwarding" and first["goto_step"] == "router", explain_report(robot)
    assert "answers ping: the modem is online and drops it" in first["meaning"]
    first = first_failure_in(laptop)
    assert first["rule"] == "linux.peer.unreachable" and first["goto_step"] == "router", \
        explain_report(laptop)
    assert "modem is online" in first["meaning"]


# --------------------------------------------------------------------------- stale DHCP address
def test_new_dhcp_lease_with_local_ip_in_the_settings(ros1_lab, tmp_path):
    with ros1_lab.variant("stale_dhcp"):
        doc = report(ros1_lab, "robot", tmp_path)
    checks = {c["id"]: c for c in doc["checks"]}
    # our listener is up on the address the robot has now: Table 1 reads "up, Closed"
    assert checks["router.listener"]["status"] == "pass", explain_report(doc)
    first = first_failure_in(doc)
    assert first["rule"] == f"{T1}.forwarding" and first["goto_step"] == "router", explain_report(doc)
    assert "from 10.10.10.1 to 10.10.10.5" in " ".join(first["actions"])


def test_new_dhcp_lease_with_the_documented_settings_is_told_by_the_history(ros1_lab, tmp_path):
    cfg = config(ros1_lab, "robot", tmp_path / "config.toml", local_ip="", interface="")
    state = tmp_path / "state"
    check(ros1_lab, "robot", state, "--step", "router", cfg=cfg)     # a healthy run: 10.10.10.1
    with ros1_lab.variant("stale_dhcp"):
        doc = report(ros1_lab, "robot", state, cfg=cfg)
    checks = {c["id"]: c for c in doc["checks"]}
    li = checks["router.local_ip"]["data"]
    assert li["local_ip"] == "10.10.10.5" and li["previous_ip"] == "10.10.10.1" and li["changed"]
    first = first_failure_in(doc)
    assert first["rule"] == f"{T1}.forwarding" and first["goto_step"] == "router", explain_report(doc)
    assert "from 10.10.10.1 to 10.10.10.5" in " ".join(first["actions"])


def test_new_dhcp_lease_seen_from_the_laptop(ros1_lab, tmp_path):
    with ros1_lab.variant("stale_dhcp"):
        doc = report(ros1_lab, "laptop", tmp_path)
    first = first_failure_in(doc)
    assert first["rule"] == "linux.peer.unreachable" and first["goto_step"] == "router", \
        explain_report(doc)


# --------------------------------------------------------------------------- private double NAT
def test_travel_router_behind_the_modem_names_the_inner_router_first(ros1_lab, tmp_path):
    with ros1_lab.variant("double_nat"):
        doc = report(ros1_lab, "robot", tmp_path)
    checks = {c["id"]: c for c in doc["checks"]}
    assert checks["isp.cgnat"]["data"]["double_nat"] is True, explain_report(doc)
    first = first_failure_in(doc)
    assert first["rule"] == f"{T1}.forwarding" and first["goto_step"] == "router", explain_report(doc)
    assert first["actions"][0].startswith("On the inner router (10.10.10.254, turtlebot's "
                                          "gateway)"), first
    assert "to 10.10.10.1" in first["actions"][0] and "bridge" in first["actions"][0]
    assert first["actions"][1].startswith("On the outer router (192.168.0.1)")
    second = [f for f in doc["findings"] if f["rule"].startswith(T1)][1]
    assert second["rule"] == f"{T1}.isp"


# --------------------------------------------------------------------------- LAN profile
def test_lan_profile_skips_the_port_test_with_the_reason(ros1_lab, tmp_path):
    cfg = config(ros1_lab, "robot", tmp_path / "config.toml", profile="office",
                 office_ip="10.10.10.1")
    checks = check(ros1_lab, "robot", tmp_path, "--step", "router", cfg=cfg)
    po = checks["router.port_open"]
    assert po["status"] == "skip", po
    assert "on the office LAN profile every component is on the same LAN" in po["summary"]
    assert "hotspot cannot forward at all" in po["summary"]
    assert all(not c["advice"] for c in checks.values()), checks
    r = ros1_lab.rosnet("robot", "report", "--config", cfg, "--from-json", "-",
                    input=json.dumps({"checks": list(checks.values())}),
                    env=_env(ros1_lab, "robot", tmp_path))
    assert "1024-65000" not in r.stdout.split("## Settings")[0]


# --------------------------------------------------------------------------- sshd elsewhere
def test_sshd_on_another_port_says_so_and_names_ssh_port(ros1_lab, tmp_path):
    with ros1_lab.variant("sshd_port"):
        doc = report(ros1_lab, "laptop", tmp_path)
    checks = {c["id"]: c for c in doc["checks"]}
    ssh = checks["linux.ssh"]
    assert ssh["data"]["peers"]["turtlebot"]["tcp"] == "refused"
    assert "it may listen on another port" in ssh["summary"] and "ssh_port" in ssh["summary"]
    first = first_failure_in(doc)
    assert first["rule"] == "linux.ssh.refused" and first["goto_step"] == "linux", explain_report(doc)
    assert "ROS master answers at the same address" in first["meaning"]
    assert "ssh_port = N under the [[peer]] named turtlebot" in first["actions"][0]
