"""The real wizard, with the real checks, on the network lab: what a technician sees."""

from __future__ import annotations

import json
import sys

import pytest

from tests.lab.firewall import secured
from tests.lab.lab import REPO

pytestmark = pytest.mark.lab


def run_wizard(lab, host: str, tmp_path) -> dict:
    env = dict(lab.ros_env(host))
    env["PYTHONPATH"] = str(REPO)
    r = lab.run(host, [sys.executable, "-m", "tests.ui_support.drive_wizard",
                       str(lab.config_path(host)), str(tmp_path / f"state-{host}")],
                timeout=240, env=env)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-4000:]
    return json.loads(r.stdout.strip().splitlines()[-1])


def test_healthy_lab_every_check_passes_in_the_wizard(ros1_lab, healthy_lab, tmp_path):
    lab = healthy_lab
    with secured(lab, ["laptop"]):              # ROS 1 as the product sets it up
        seen = run_wizard(lab, "laptop", tmp_path)
    states = {cid: row["state"] for step in seen["steps"].values() for cid, row in step.items()}
    assert len(states) == 22                    # security.ssh_auth, security.outsider, ros.link
    not_passed = {cid: row for step in seen["steps"].values() for cid, row in step.items()
                  if row["state"] != "pass"}     # what they said, evidence and data too
    assert states["security.ssh_auth"] == states["security.outsider"] == "pass", \
        json.dumps(not_passed, indent=1)         # a str: pytest shows it whole
    assert {cid for cid, st in states.items() if st != "pass"} <= {"isp.cgnat"}, seen["steps"]
    assert states["isp.cgnat"] in ("pass", "skip")
    for step_id, label in seen["bar"].items():
        assert "[ok]" in label, (step_id, label)
    assert not [f for f in seen["findings"] if f["severity"] == "fail"]


def test_no_forwarding_shows_table_1_in_the_wizard(ros1_lab, healthy_lab, tmp_path):
    with healthy_lab.variant("no_forwarding"):
        seen = run_wizard(healthy_lab, "robot", tmp_path)
    router = seen["steps"]["router"]
    assert router["router.listener"]["state"] == "pass"
    assert router["router.port_open"]["state"] == "fail"
    assert "[x]" in seen["bar"]["router"]
    rules = [f["rule"] for f in seen["findings"] if f["severity"] == "fail"]
    assert any(r.startswith("table1.listener_up_closed") for r in rules), rules
