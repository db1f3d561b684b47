"""`rosnet-tui sync pin`: a fleet whose sync keys are not pinned yet gets them over the SSH the
product trusts (issue 35, finding 4's follow-up): a real sshd on 127.0.0.1 serves a peer whose
home has rosnet-tui installed the README's way (pipx layout, tests/lab/readme_install.py; the
session's PATH without the development interpreter, as the lab's), and this component's CLI asks
it for its key. Records the service refused (no key pinned) then count; a changed key is never
replaced without an explicit yes; a bad peer beside a good one fails alone; the settings file
keeps its comments."""

from __future__ import annotations

import difflib
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from rosnet_tui.core.config.paths import Paths
from rosnet_tui.core.saved.settings import parse_settings
from rosnet_tui.core.sync import SyncService, load_status
from rosnet_tui.core.sync.pin import key_of
from rosnet_tui.core.sync.signing import fingerprint, sign_record
from rosnet_tui.core.sync.watcher import LocalAddress, PublicLookup
from tests.builders import sync_key, sync_key_text, write_sync_key
from tests.lab import readme_install
from tests.lab.topology import SSH_SESSION_PATH
from tests.plugins.ssh import Sshd, keygen
from tests.prompts import run_answering

REPO = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.lab      # root: a mount namespace for the CLI's /etc/hosts

SETTINGS = """\
# sami's settings: hand-written, keep my notes
[this]
name = "sami"          # the laptop
role = "member"
profile = "remote"
local_ip = "192.168.1.10"
public_ip = "198.51.100.2"

[[peer]]
name = "turtlebot"     # the robot
local_ip = "10.10.10.1"
public_ip = "203.0.113.7"
ssh_user = "root"
ssh_port = {port}
{pinned}
# the rover: not built yet
[[peer]]
name = "rover.invalid"
local_ip = "10.10.20.1"
ssh_user = "root"

[ros]
master = "turtlebot"

[probe]
public_ip_urls = ["http://127.0.0.1:9/ip"]

[sync]
store = "folder"
folder = "{folder}"
"""


@pytest.fixture(scope="module")
def robot(tmp_path_factory):
    """A peer: sshd on 127.0.0.1 whose sessions get a home with rosnet-tui installed there
    (pipx layout) and the robot's sync key beside its default settings."""
    root = tmp_path_factory.mktemp("robot")
    home = root / "home"
    home.mkdir()
    readme_install.install(home)
    write_sync_key(home / ".config" / "rosnet-tui" / "config.toml", "turtlebot")
    d = Sshd(root / "sshd", extra_config=f"SetEnv HOME={home} PATH={SSH_SESSION_PATH}\n")
    d.start()
    yield d
    d.stop()


class Seat:
    """This component (sami): its home (~/.ssh trusting the robot), settings, shared folder."""

    def __init__(self, tmp_path: Path, robot: Sshd, pinned: str = "") -> None:
        self.home = tmp_path / "home"
        ssh = self.home / ".ssh"
        ssh.mkdir(parents=True, mode=0o700)
        robot.authorized.write_text(keygen(ssh / "id_ed25519") + "\n")
        (ssh / "known_hosts").write_text(
            f"[turtlebot]:{robot.port} {robot.host_pub.rsplit(' ', 1)[0]}\n")
        self.folder = tmp_path / "shared"
        self.folder.mkdir()
        self.config = tmp_path / "config.toml"
        self.config.write_text(SETTINGS.format(
            port=robot.port, folder=self.folder,
            pinned=f'sync_key = "{pinned}"   # pinned by hand\n' if pinned else ""))
        write_sync_key(self.config, "sami")
        self.tmp = tmp_path

    def pin(self, *args: str, answers: list[str] | None = None) -> tuple[int, str]:
        return self.run("sync", "pin", *args, answers=answers)

    def run(self, *args: str, answers: list[str] | None = None) -> tuple[int, str]:
        # turtlebot is 127.0.0.1 for this process alone: its own /etc/hosts, bound over the
        # real one in a mount namespace of its own.
        hosts = self.tmp / "etc_hosts"
        hosts.write_text("127.0.0.1\tlocalhost\n127.0.0.1\tturtlebot\n127.0.0.1\trover\n")
        argv = ["unshare", "-m", "sh", "-c", 'mount --bind "$0" /etc/hosts && exec "$@"',
                str(hosts), sys.executable, "-m", "rosnet_tui", *args, "--config",
                str(self.config)]
        env = {**os.environ, "HOME": str(self.home), "PYTHONPATH": str(REPO)}
        if answers is not None:
            return run_answering(argv, answers, env=env, cwd=REPO, timeout=60)
        r = subprocess.run(argv, capture_output=True, text=True, env=env, cwd=REPO,
                           stdin=subprocess.DEVNULL, timeout=60)
        return r.returncode, r.stdout + r.stderr

    def service(self) -> SyncService:
        paths = Paths(config_path=self.config, state_dir=self.tmp / "state",
                      hosts_path=self.tmp / "hosts")
        (self.tmp / "hosts").write_text("127.0.0.1\tlocalhost\n")
        return SyncService(paths, run_checks=False, netlink=False, watch_folder=False,
                           save_learned=False,
                           local_source=lambda s: LocalAddress("eth0", "192.168.1.10",
                                                               "192.168.1.254"),
                           public_source=lambda s: PublicLookup("198.51.100.2", "test"))


def one_round(svc: SyncService) -> None:
    p = svc.publisher
    p.next_fetch = p.next_publish = svc.applier.next_apply = 0.0
    svc.round()


def robot_record():
    from rosnet_tui.core.saved.sync_records import new_record

    return sign_record(new_record("turtlebot", local_ip="10.10.10.1", public_ip="203.0.113.9",
                                  role="master", seq=5), sync_key("turtlebot"))


def test_an_unpinned_fleet_gets_pinned_over_ssh_and_its_records_then_count(tmp_path, robot):
    seat = Seat(tmp_path, robot)
    (seat.folder / "turtlebot.json").write_text(robot_record().to_text())
    svc = seat.service()
    one_round(svc)
    why = load_status(tmp_path / "state")["refused"][-1]["why"]
    assert "no sync key of turtlebot is pinned" in why and "rosnet-tui sync pin" in why, why

    before = seat.config.read_text()
    rc, out = seat.pin("--dry-run")
    assert rc == 1 and seat.config.read_text() == before, out     # rover fails; nothing written
    assert "Dry run" in out and fingerprint(sync_key_text("turtlebot")) in out, out

    rc, out = seat.pin("--yes")
    print(out)
    assert rc == 1, out                          # the bad peer fails, alone, and says why
    assert f"turtlebot: {sync_key_text('turtlebot')}" in out, out
    assert "rover.invalid: failed: SSH failed" in out and "resolve" in out, out
    after = seat.config.read_text()
    added = [ln for ln in difflib.ndiff(before.splitlines(), after.splitlines())
             if ln[:1] in "+-"]
    assert added == [f'+ sync_key = "{sync_key_text("turtlebot")}"'], added   # comments kept
    assert after.index("sync_key") < after.index("# the rover: not built yet")
    assert parse_settings(after).peers[0].sync_key == sync_key_text("turtlebot")

    one_round(seat.service())                     # the robot's record counts now
    assert re.search(r"^203\.0\.113\.9\s+turtlebot\b", (tmp_path / "hosts").read_text(), re.M)
    assert load_status(tmp_path / "state")["peers"]["turtlebot"]["address"] == "203.0.113.9"

    rc, out = seat.pin("turtlebot")               # again: nothing to do, no question
    assert rc == 0 and "already pinned" in out and seat.config.read_text() == after, out


def test_a_changed_key_is_never_replaced_without_an_explicit_yes(tmp_path, robot):
    old = sync_key_text("impostor")
    seat = Seat(tmp_path, robot, pinned=old)
    before = seat.config.read_text()
    rc, out = seat.pin("turtlebot")               # no terminal, no --yes
    assert rc == 1 and "KEY CHANGED" in out and "Not replacing" in out, out
    assert seat.config.read_text() == before
    rc, out = seat.pin("turtlebot", answers=["n"])     # asked on a terminal: no
    assert rc == 1 and "Replace the pinned sync key of turtlebot" in out, out
    assert seat.config.read_text() == before
    rc, out = seat.pin("turtlebot", "--yes")
    assert rc == 0 and "--yes: replacing turtlebot's pinned key" in out, out
    after = seat.config.read_text()
    assert after == before.replace(old, sync_key_text("turtlebot"))   # its comment kept too


def test_a_new_key_is_asked_for_on_a_terminal(tmp_path, robot):
    seat = Seat(tmp_path, robot)
    before = seat.config.read_text()
    rc, out = seat.pin("turtlebot", answers=["n"])
    assert rc == 1 and seat.config.read_text() == before, out
    rc, out = seat.pin("turtlebot", answers=["y"])
    assert rc == 0 and "Pinned the sync key of turtlebot" in out, out
    assert sync_key_text("turtlebot") in seat.config.read_text()


def test_bad_usage_is_exit_2(tmp_path, robot):
    seat = Seat(tmp_path, robot)
    rc, out = seat.pin("nobody")
    assert rc == 2 and "nobody is no peer" in out, out
    seat.config.write_text("[this\n")
    rc, out = seat.pin()
    assert rc == 2 and "Traceback" not in out, out


def test_what_a_peer_answers_is_read_strictly():
    good = sync_key_text("turtlebot")
    assert key_of(f'sync_key = "{good}"\n', "", 0) == (good, "")
    assert key_of('ROSNET_SYNC_KEY {"error": "no_install"}\n', "", 4)[1].startswith("no rosnet")
    assert "no `sync key`" in key_of("", "error: argument ACTION: invalid choice: 'key'", 2)[1]
    assert key_of('sync_key = "ed25519:AAAA"\n', "", 0)[0] == ""
    assert "exit status 1" in key_of("", "boom\x1b[2J", 1)[1]


MEMBER = """\
# sami, a ROS 2 member
[this]
name = "sami"
role = "member"
profile = "remote"
local_ip = "192.168.1.10"
public_ip = "198.51.100.2"

[[peer]]
name = "turtlebot"   # the master
public_ip = "203.0.113.7"
ssh_user = "root"
ssh_port = {port}
{pinned}
[ros]
version = 2
master = "turtlebot"
"""

MASTER = """\
[this]
name = "turtlebot"
role = "master"
local_ip = "10.10.10.1"
public_ip = "203.0.113.7"

[[peer]]
name = "sami"
public_ip = "198.51.100.2"

[ros]
version = 2
master = "turtlebot"
"""


def test_ros_pair_pins_the_masters_sync_key_in_the_same_session(tmp_path, robot):
    """Under ROS 2 mutual TLS, `ros pair` on a member gets the master's sync key with its
    certificate (the master's own `ros pair --serve`): pinned when none is; a different one is
    never replaced there."""
    master_cfg = robot.root.parent / "home" / ".config" / "rosnet-tui" / "config.toml"
    master_cfg.write_text(MASTER)
    try:
        seat = Seat(tmp_path, robot)
        seat.config.write_text(MEMBER.format(port=robot.port, pinned=""))
        before = seat.config.read_text()
        rc, out = seat.run("ros", "pair")
        assert rc == 0 and "Paired with turtlebot's fleet CA" in out, out
        key = sync_key_text("turtlebot")
        assert f"Pinned turtlebot's sync key ({fingerprint(key)})" in out, out
        assert seat.config.read_text() == before.replace(
            f"ssh_port = {robot.port}\n", f'ssh_port = {robot.port}\nsync_key = "{key}"\n')
        old = sync_key_text("impostor")
        seat.config.write_text(MEMBER.format(port=robot.port, pinned=f'sync_key = "{old}"'))
        before = seat.config.read_text()
        rc, out = seat.run("ros", "pair", "--renew")
        assert rc == 0 and "KEY CHANGED" in out and "not replaced" in out, out
        assert seat.config.read_text() == before
    finally:
        master_cfg.unlink()


def test_a_silent_peer_fails_within_its_time_and_the_others_are_pinned(tmp_path, robot):
    """A peer whose port takes the connection and never speaks (a wedged sshd) gets a verdict
    within --timeout; the good peer, asked at the same time, is pinned."""
    import socket

    quiet = socket.socket()
    quiet.bind(("127.0.0.1", 0))
    quiet.listen(8)                   # the kernel completes the handshake; nothing ever speaks
    try:
        seat = Seat(tmp_path, robot)
        text = seat.config.read_text().replace('name = "rover.invalid"', 'name = "rover"')
        seat.config.write_text(text.replace('ssh_user = "root"\n\n[ros]',
                                            f'ssh_user = "root"\nssh_port = '
                                            f'{quiet.getsockname()[1]}\n\n[ros]'))
        rc, out = seat.run("sync", "pin", "--yes", "--timeout", "2")
        assert rc == 1 and "rover: failed: SSH failed" in out, out
        assert "Pinned the sync key of turtlebot" in out, out
        assert sync_key_text("turtlebot") in seat.config.read_text()
    finally:
        quiet.close()
