"""Two runs at once on one component (issue 34): nine `rosnet-tui check --json` started together on
the healthy two-site lab, six on the laptop and three on the robot (two technicians, or the wizard
and a script). Runs of rosnet-tui share the test port on a component and its peer's: none may
blame the port or the forwarding for another run; the later ones wait for the test port (and
say so), then pass."""

from __future__ import annotations

import json
import subprocess
import sys
import time

import pytest

from tests.lab.firewall import secured

pytestmark = pytest.mark.lab

STEPS = ("--step", "router", "--step", "linux")
# Nine runs start at once on a small machine: a little more time than the default 3 s, so that
# a slow start is not taken for the defect (which is no matter of time: a refused bind).
TIMEOUT = ("--timeout", "5")
RUNS = {"laptop": 6, "robot": 3}
# The checks that use the test port (here, or the peer's over SSH).
PORT_CHECKS = ("router.port_free", "router.listener", "router.port_open", "linux.chat_in",
               "linux.chat_out")


def table(checks: dict[str, dict]) -> str:
    return "\n".join(f"{c['status']:4} {c['id']} ({c['duration_s']:.1f}/{c['timeout_s']:g} s): "
                     f"{c['summary']} {c['evidence']}" for c in checks.values())


def test_nine_runs_at_once_all_pass(lab, tmp_path):
    lab.reset()
    config = {h: lab.config_path(h) for h in RUNS}
    with secured(lab):                     # ROS 1 as the product sets it up: every check passes
        outs, took = _nine_runs(lab, config, tmp_path)
    bad: list[str] = []
    waited: list[str] = []
    for n, (host, code, out, err) in enumerate(outs):
        assert out.strip(), err
        checks = {c["id"]: c for c in json.loads(out)["checks"]}
        for c in checks.values():
            assert c["duration_s"] <= c["timeout_s"] + 0.5, c   # bad news in time, waits too
        waited += [e for c in PORT_CHECKS for e in checks[c]["evidence"] if "another check run" in e]
        if code != 0 or any(c["status"] != "pass" for c in checks.values()):
            bad.append(f"run {n} on {host} (exit {code}):\n{table(checks)}")
    assert not bad, "\n\n".join(bad)
    assert waited                  # the later runs said how they came by the port
    assert took < 90, took


def _nine_runs(lab, config, tmp_path):
    runs: list[tuple[str, subprocess.Popen]] = []
    t0 = time.monotonic()
    try:
        for i in range(max(RUNS.values())):          # interleaved: both sides start together
            for host, n in RUNS.items():
                if i < n:
                    env = dict(lab.ros_env(host), XDG_STATE_HOME=str(tmp_path / f"{host}{i}"))
                    runs.append((host, lab.spawn(
                        host, [sys.executable, "-m", "rosnet_tui", "check", "--json", "-q", *STEPS, *TIMEOUT,
                               "--config", str(config[host])], env=env,
                        stdout=subprocess.PIPE, stderr=subprocess.PIPE)))
        outs = []
        for host, proc in runs:
            out, err = proc.communicate(timeout=120)
            outs.append((host, proc.returncode, out, err))
    finally:
        for _, proc in runs:
            lab.kill(proc, grace=0.2)
    return outs, time.monotonic() - t0
