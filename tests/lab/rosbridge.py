"""The lab with web clients (issue 24): a rosbridge stand-in on the robot, bridging to its roscore.

No rosbridge installs here (Debian has none; the PyPI rosbridge servers need a ROS 2 install), so
``tests/lab/rosbridge_scripts/bridge.py`` stands in for ``rosbridge_websocket``: written from the
rosbridge v2 protocol specification, it speaks the WebSocket and the JSON operations a browser's
first steps use, and bridges them to the lab's real roscore through rospy. ``--no-rosapi`` leaves
out the rosapi part (``/rosapi/topics`` then answers as rosbridge does for a missing service).

The robot's modem forwards TCP 9090 in the ``bridge`` forwarding mode (TCP 22 and 9090 only), and
in the healthy mode (ROS 1's range covers 9090).
"""

from __future__ import annotations

import subprocess
from dataclasses import replace
from pathlib import Path

from .lab import ROS_PYTHON, Lab
from .topology import ROSBRIDGE_PORT

BRIDGE = Path(__file__).resolve().parent / "rosbridge_scripts" / "bridge.py"


def start_bridge(lab: Lab, *, rosapi: bool = True, port: int = ROSBRIDGE_PORT,
                 timeout: float = 20.0) -> subprocess.Popen:
    """Start the stand-in on the robot (roscore must run) and wait, bounded, until it listens."""
    log = open(lab.log_path("rosbridge"), "w")  # noqa: SIM115
    argv = [ROS_PYTHON, str(BRIDGE), "--port", str(port)] + ([] if rosapi else ["--no-rosapi"])
    proc = lab.spawn("robot", argv, env=lab.ros_env("robot"), stdout=log,
                     stderr=subprocess.STDOUT)
    log.close()
    if not lab.wait_listening("robot", port, timeout=timeout, proc=proc):
        lab.kill(proc)
        raise RuntimeError("the rosbridge stand-in did not start: "
                           + lab.log_path("rosbridge").read_text(errors="replace")[-2000:])
    return proc


def settings(lab: Lab, host: str, version: int = 1, **bridge):
    """*host*'s settings with [rosbridge] enabled (the master, turtlebot, runs it)."""
    from rosnet_tui.core.config.settings_model import RosbridgeSettings

    s = lab.settings(host)
    return replace(s, ros=replace(s.ros, version=version),
                   rosbridge=RosbridgeSettings(enabled=True, **bridge))


def config_path(lab: Lab, host: str, version: int = 1, **bridge) -> Path:
    from rosnet_tui.core.saved.settings import atomic_write_text, render_settings

    path = lab.home(host) / ".config" / "rosnet-tui" / "config.toml"
    atomic_write_text(path, render_settings(settings(lab, host, version, **bridge)), mode=0o644)
    return path
