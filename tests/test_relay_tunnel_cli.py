"""`rosnet-tui relay tunnel`'s refusals (the tunnel itself: tests/test_ssh_jump.py)."""

from __future__ import annotations

import argparse
import getpass
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time

import pytest

from rosnet_tui.cli.relay_tunnel import unit_text
from tests.builders import ROBOT_CONFIG, free_port
from tests.plugins.ssh import keygen


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
    text = unit_text(argparse.Namespace(config=tmp_path / "c.toml", sshd_port=2222,
                                        ssh_dir=tmp_path / "keys"))
    start = next(line for line in text.splitlines() if line.startswith("ExecStart="))
    assert start.endswith(f"--config {tmp_path / 'c.toml'} relay tunnel --sshd-port 2222 "
                          f"--ssh-dir {tmp_path / 'keys'}")
    assert "Restart=always" in text and "User=" in text
    # a refusal of the settings (exit 2: see the test above, ROS 1 has no tunnel) is not
    # restarted every 5 s for ever
    assert "RestartPreventExitStatus=2" in text.splitlines()


SETTINGS = """\
[this]
name = "turtlebot"
role = "master"
[[peer]]
name = "sami"
local_ip = "192.168.1.10"
[ros]
version = 2
master = "turtlebot"
[relay]
host = "relay"
ssh_user = "{user}"
ssh_port = {relay_port}
[relay.tunnels]
turtlebot = {port}
"""


def _lines(proc: subprocess.Popen, out: list[str]) -> threading.Thread:
    def read() -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            out.append(line.rstrip("\n"))
    t = threading.Thread(target=read, daemon=True)
    t.start()
    return t


def _answers(port: int) -> bool:
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=0.5):
            return True
    except OSError:
        return False


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_the_tunnel_runs_in_the_foreground_and_ends_cleanly_on_a_signal(sshd, tmp_path, sig):
    if not shutil.which("ssh") or not shutil.which("unshare") or os.geteuid() != 0:
        pytest.skip("needs OpenSSH's client, and root for a hosts file of its own")
    dot = tmp_path / "dot_ssh"
    dot.mkdir(mode=0o700)
    pub = keygen(dot / "id_ed25519")
    port = free_port()
    sshd.authorized.write_text(f'restrict,port-forwarding,permitlisten="127.0.0.1:{port}" {pub}\n')
    (dot / "known_hosts").write_text(
        f"[relay]:{sshd.port} {sshd.host_pub.rsplit(' ', 1)[0]}\n")
    hosts = tmp_path / "hosts"            # 'relay' names the relay's sshd on loopback, for this
    hosts.write_text("127.0.0.1 localhost\n127.0.0.1 relay\n")      # command only
    cfg = tmp_path / "c.toml"
    cfg.write_text(SETTINGS.format(user=getpass.getuser(), relay_port=sshd.port, port=port))
    own_hosts = ["unshare", "-m", "sh", "-c", 'mount --bind "$0" /etc/hosts && exec "$@"',
                 str(hosts)]
    proc = subprocess.Popen([*own_hosts, sys.executable, "-m", "rosnet_tui", "relay", "tunnel",
                             "--config", str(cfg), "--ssh-dir", str(dot)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, stdin=subprocess.DEVNULL, text=True)
    out: list[str] = []
    reader = _lines(proc, out)
    try:
        end = time.monotonic() + 15
        while time.monotonic() < end and proc.poll() is None \
                and not any("tunnel up" in line for line in out):
            time.sleep(0.05)
        # the [relay] loader is merged: a refusal of the settings is a failure, never a skip
        assert any("tunnel up" in line for line in out), \
            (out, proc.stderr.read() if proc.poll() is not None else "")
        assert _answers(port)                     # the relay listens at the tunnel's port
        proc.send_signal(sig)
        assert proc.wait(5) == 0
        reader.join(2)
        assert out[-1] == "relay tunnel: tunnel closed", out
        end = time.monotonic() + 5
        while _answers(port) and time.monotonic() < end:
            time.sleep(0.05)
        assert not _answers(port)                 # the ssh it ran is gone, and its forward
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(5)
