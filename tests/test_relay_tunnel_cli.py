"""`rosnet-tui relay tunnel`'s refusals (the tunnel itself: tests/test_ssh_jump.py)."""

from __future__ import annotations

import argparse
import subprocess
import sys

from rosnet_tui.cli.relay_tunnel import unit_text
from tests.builders import ROBOT_CONFIG


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "rosnet_tui", *args], capture_output=True,
                          text=True, timeout=60, stdin=subprocess.DEVNULL)


def test_no_tunnel_in_the_settings_is_refused_with_exit_2(tmp_path):
    cfg = tmp_path / "c.toml"
    cfg.write_text(ROBOT_CONFIG)
    out = run("relay", "tunnel", "--config", str(cfg))
    assert out.returncode == 2 and "Traceback" not in out.stderr
    assert "no tunnel for turtlebot" in out.stderr and "[relay.tunnels]" in out.stderr


def test_a_bad_sshd_port_is_refused_with_exit_2(tmp_path):
    out = run("relay", "tunnel", "--sshd-port", "70000", "--config", str(tmp_path / "c.toml"))
    assert out.returncode == 2 and "--sshd-port" in out.stderr


def test_relay_without_a_command_is_a_usage_error():
    out = run("relay")
    assert out.returncode == 2


def test_the_unit_runs_this_same_command_and_restarts(tmp_path):
    text = unit_text(argparse.Namespace(config=tmp_path / "c.toml", sshd_port=2222))
    start = next(line for line in text.splitlines() if line.startswith("ExecStart="))
    assert start.endswith(f"--config {tmp_path / 'c.toml'} relay tunnel --sshd-port 2222")
    assert "Restart=always" in text and "User=" in text
