"""Fixture (a pytest plugin, loaded by tests/conftest.py): a real roscore on loopback.

The ROS 1 tools are the Debian packages and run under /usr/bin/python3; the roscore runs on
127.0.0.1:<free port> with its own ROS_HOME and is killed at the end of the session.
"""

from __future__ import annotations

import os
import signal
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

import pytest

from rosnet_tui.core.peer import rosproto
from tests.builders import free_port

ROSCORE = Path("/usr/bin/roscore")
ROS_PYTHON = Path("/usr/bin/python3")


@dataclass
class RosCore:
    uri: str
    port: int
    env: dict[str, str]
    home: Path


def kill_group(proc: subprocess.Popen, grace: float = 5.0) -> None:
    if proc.poll() is not None:
        return
    try:
        os.killpg(proc.pid, signal.SIGINT)
        proc.wait(grace)
    except (ProcessLookupError, subprocess.TimeoutExpired):
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        proc.wait(5)


@pytest.fixture(scope="session")
def roscore(tmp_path_factory: pytest.TempPathFactory):
    """A real roscore on 127.0.0.1:<free port> with its own ROS_HOME; killed at the end."""
    if not ROSCORE.exists() or not ROS_PYTHON.exists():
        pytest.skip("roscore is not installed (Debian packages ros-core, python3-rospy)")
    home = tmp_path_factory.mktemp("roshome")
    port = free_port()
    uri = f"http://127.0.0.1:{port}"
    env = {"PATH": "/usr/bin:/bin", "HOME": str(home), "ROS_HOME": str(home),
           "ROS_LOG_DIR": str(home / "log"), "ROS_MASTER_URI": uri, "ROS_IP": "127.0.0.1",
           "LANG": "C.UTF-8"}
    log = open(home / "roscore.out", "wb")
    proc = subprocess.Popen([str(ROSCORE), "-p", str(port)], env=env, stdout=log,
                            stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                            start_new_session=True)
    try:
        deadline = time.monotonic() + 30
        while True:
            try:
                rosproto.MasterClient(uri, "/wait", 0.5).get_system_state()
                break
            except Exception:
                if proc.poll() is not None or time.monotonic() > deadline:
                    log.flush()
                    pytest.fail("roscore did not come up: "
                                + (home / "roscore.out").read_text(errors="replace")[-2000:])
                time.sleep(0.1)
        yield RosCore(uri, port, env, home)
    finally:
        kill_group(proc)
        log.close()
