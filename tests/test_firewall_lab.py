"""`rosnet-tui firewall` on the network lab (ROS 1): the robot loads its peers-only table; the
laptop (a peer) still passes every Linux and ROS check, while an address that is no peer (the
lab internet's probe address, 192.0.2.10) is refused (a TCP reset, at once) at the master's port
and at a port of the range, and reaches the port checker's test port; `undo` removes our table and leaves a foreign table alone; the sync service follows a
peer's address change with the set.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import time

import pytest

from rosnet_tui.core.saved.sync_records import new_record
from rosnet_tui.core.sync.signing import sign_record
from tests.builders import sync_key
from tests.lab import ADDR, outsider
from tests.lab.firewall import secured
from tests.sync_support.bench import goal_s
from tests.sync_support.lab_sync import SyncRig, prepare_lab, wait_for

pytest_plugins = ["tests.lab.fixtures"]
pytestmark = pytest.mark.lab

OUTSIDER = ADDR.PROBE_IP          # the internet's probe address: no peer of anyone
RANGE_PORT = 40123
WAIT = 30.0


def tcp_try(source: str, host: str, port: int, timeout: float = 1.5) -> str:
    """One TCP connection attempt from *source*: connected, refused, timeout or the error."""
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.settimeout(timeout)
    try:
        s.bind((source, 0))
        s.connect((host, port))
        return "connected"
    except ConnectionRefusedError:
        return "refused"
    except TimeoutError:
        return "timeout"
    except OSError as exc:
        return f"error: {exc}"
    finally:
        s.close()


def tcp_try_any(host: str, port: int, timeout: float = 1.5) -> str:
    return tcp_try("0.0.0.0", host, port, timeout)


def listen(port: int) -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    s.bind(("0.0.0.0", port))
    s.listen(16)
    return s


def nft(lab, host: str, *args: str):
    return lab.run(host, ["nft", *args], timeout=10)


def fw(lab, host: str, state, *args: str, config=None, **extra: str):
    env = dict(lab.ros_env(host), XDG_STATE_HOME=str(state), **extra)
    return lab.rosnet(host, "--config", str(config or lab.config_path(host)), *args,
                      env=env, timeout=60)


def check(lab, host: str, state, *steps: str, **extra: str) -> dict[str, dict]:
    env = dict(lab.ros_env(host), XDG_STATE_HOME=str(state), **extra)
    argv = ["check", "--json", "-q"] + [a for s in steps for a in ("--step", s)]
    r = lab.rosnet(host, *argv, "--config", str(lab.config_path(host)), env=env, timeout=90)
    assert r.stdout.strip(), r.stderr
    return {c["id"]: c for c in json.loads(r.stdout)["checks"]}


def explain(results: dict[str, dict]) -> str:
    return "\n".join(f"{c['status']:4} {c['id']}: {c['summary']} {c['evidence']}"
                     for c in results.values())


@pytest.fixture
def fw_lab(lab):
    lab.reset()
    yield lab
    for host in ("robot", "laptop"):
        nft(lab, host, "delete", "table", "inet", "rosnet_tui")
        nft(lab, host, "delete", "table", "inet", "foreign_fw")
    lab.reset()
    lab.stop_roscore()


def test_only_the_peer_gets_through_and_undo_leaves_a_foreign_table(fw_lab, tmp_path):
    lab = fw_lab
    lab.start_roscore()
    # Someone else's table, which we must never touch.
    assert nft(lab, "robot", "add", "table", "inet", "foreign_fw").returncode == 0
    assert nft(lab, "robot", "add", "chain", "inet", "foreign_fw", "keep").returncode == 0
    foreign = nft(lab, "robot", "list", "table", "inet", "foreign_fw").stdout
    srv = lab.call_in("robot", listen, RANGE_PORT)
    try:
        # Before: the outsider reaches the master through the forward.
        assert lab.call_in("internet", tcp_try, OUTSIDER, ADDR.ROBOT_PUBLIC, 11311) == "connected"

        # The preview, then one transaction.
        r = fw(lab, "robot", tmp_path, "firewall", "apply", "--dry-run")
        assert r.returncode == 0, r.stderr
        assert "+table inet rosnet_tui {" in r.stdout and ADDR.LAPTOP_PUBLIC in r.stdout
        assert "Dry run: nothing was changed." in r.stdout
        assert nft(lab, "robot", "list", "table", "inet", "rosnet_tui").returncode != 0
        t0 = time.monotonic()
        r = fw(lab, "robot", tmp_path, "firewall", "apply", "--yes")
        print(f"firewall apply on the robot: {time.monotonic() - t0:.2f} s")
        assert r.returncode == 0, r.stdout + r.stderr
        assert "Loaded the table inet rosnet_tui (journal #" in r.stdout
        assert "PASS linux.firewall" in r.stdout, r.stdout       # the check re-run after it
        listing = nft(lab, "robot", "list", "table", "inet", "rosnet_tui").stdout
        assert ADDR.LAPTOP_PUBLIC in listing and "reject with tcp reset" in listing
        assert nft(lab, "robot", "list", "table", "inet", "foreign_fw").stdout == foreign

        # The outsider: the master's port and a port of the range are refused with a reset,
        # which arrives in one round trip: with a connect timeout of 10 s, "refused" (not
        # "timeout") proves the answer came, not a silence waited out (issue 32).
        for port in (11311, RANGE_PORT):
            got = lab.call_in("internet", tcp_try, OUTSIDER, ADDR.ROBOT_PUBLIC, port, 10.0)
            assert got == "refused", (port, got)
        # The one port open to anyone is the port checker's test port (probe.port, issue 36).
        probe = lab.settings("robot").probe.port
        probe_srv = lab.call_in("robot", listen, probe)
        try:
            assert lab.call_in("internet", tcp_try, OUTSIDER, ADDR.ROBOT_PUBLIC,
                               probe) == "connected"
        finally:
            lab.call_in("robot", probe_srv.close)
        # The peer still gets through, to the same ports.
        for port in (11311, RANGE_PORT):
            assert lab.call_in("laptop", tcp_try_any, ADDR.ROBOT_PUBLIC, port) == "connected"

        # From the peer, every Linux and ROS check passes; the robot's own check too.
        with secured(lab, ["laptop"]):   # the peer as the product sets it up: its own too
            laptop = check(lab, "laptop", tmp_path / "l", "linux", "ros")
        laptop_bad = {k: c for k, c in laptop.items() if c["status"] != "pass"}
        assert not laptop_bad, explain(laptop)
        robot = check(lab, "robot", tmp_path, "linux")
        assert robot["linux.firewall"]["status"] == "pass", explain(robot)
        d = robot["linux.firewall"]["data"]
        assert d["present"] and d["allowed"] == [ADDR.LAPTOP_PUBLIC] and d["rules_match"]

        # undo: our table gone, the foreign one as it was, the outsider back in.
        r = fw(lab, "robot", tmp_path, "undo", "--yes")
        assert r.returncode == 0, r.stdout + r.stderr
        assert "the firewall table inet rosnet_tui: removed (rosnet-tui created it)" in r.stdout
        assert nft(lab, "robot", "list", "table", "inet", "rosnet_tui").returncode != 0
        assert nft(lab, "robot", "list", "table", "inet", "foreign_fw").stdout == foreign
        assert lab.call_in("internet", tcp_try, OUTSIDER, ADDR.ROBOT_PUBLIC, 11311) == "connected"
        robot = check(lab, "robot", tmp_path, "linux")
        assert robot["linux.firewall"]["status"] == "warn", explain(robot)
        assert "rosnet-tui firewall apply" in robot["linux.firewall"]["summary"]
    finally:
        lab.call_in("robot", srv.close)


TECHNICIAN = ADDR.OUTSIDER_IP     # the technician's mobile line: on the internet, no peer
LAN_HOST = ADDR.ROBOT_GW          # the robot's modem, a host on the robot's own LAN


def test_the_technician_who_applies_it_over_ssh_and_the_lan_still_get_in(fw_lab, tmp_path):
    """Issue 29: ROS 1 settings with one peer; `firewall apply` runs in an SSH session from an
    address that is no peer. After it, a real SSH connection from that address still reaches
    sshd through the forward (SSH only), a host on the robot's LAN reaches SSH and ROS, the
    stranger is still dropped and the peer still gets in."""
    lab = fw_lab
    s = lab.settings("robot")
    assert s.ros.version == 1 and [p.public_ip for p in s.peers] == [ADDR.LAPTOP_PUBLIC]
    session = {"SSH_CONNECTION": f"{TECHNICIAN} 50022 {ADDR.ROBOT_LOCAL} 22"}
    srv = lab.call_in("robot", listen, RANGE_PORT)
    try:
        assert outsider.ssh_auth_none(lab, ADDR.ROBOT_PUBLIC).get("methods"), "no SSH before"
        r = fw(lab, "robot", tmp_path, "firewall", "apply", "--yes", "--no-checks", **session)
        assert r.returncode == 0, r.stdout + r.stderr
        preview = r.stdout.split("Loaded the table")[0]
        assert (f"  this SSH session, {TECHNICIAN} (to sshd port 22; SSH_CONNECTION): SSH "
                "only, until the next `rosnet-tui firewall apply`") in preview, r.stdout
        assert "  this machine's LAN (SSH and ROS): 10.10.10.0/24" in preview, r.stdout
        listing = nft(lab, "robot", "list", "table", "inet", "rosnet_tui").stdout
        assert f"elements = {{ {TECHNICIAN} . 22 }}" in listing, listing
        assert "elements = { 10.10.10.0/24 }" in listing, listing

        # The technician: a real SSH connection through the robot's modem, after the table.
        got = outsider.ssh_auth_none(lab, ADDR.ROBOT_PUBLIC)
        assert got.get("methods"), got
        # ... and SSH only: the master's port and the range stay shut to that address.
        for port in (11311, RANGE_PORT):
            assert lab.call_in("outsider", tcp_try, TECHNICIAN, ADDR.ROBOT_PUBLIC,
                               port, 10.0) == "refused", port
        # A host on the robot's LAN: SSH and ROS.
        for port in (22, RANGE_PORT):
            assert lab.call_in("robot_modem", tcp_try, LAN_HOST, ADDR.ROBOT_LOCAL,
                               port) == "connected", port
        # The stranger: refused at SSH and at the range. The peer: in.
        for port in (22, RANGE_PORT):
            assert lab.call_in("internet", tcp_try, OUTSIDER, ADDR.ROBOT_PUBLIC,
                               port, 10.0) == "refused", port
            assert lab.call_in("laptop", tcp_try_any, ADDR.ROBOT_PUBLIC, port) == "connected"

        # linux.firewall, run by that session: passes, says who gets in and that it does.
        got = check(lab, "robot", tmp_path, "linux", **session)["linux.firewall"]
        assert got["status"] == "pass", got
        d = got["data"]
        assert d["sessions"] == [f"{TECHNICIAN} . 22"]
        # The robot's LAN: its eth0 network (and eth0's IPv6 link-local one, where the kernel
        # gave it one); the modem's public side is no LAN of the robot's.
        assert d["lan"] == d["expected_lan"] and d["lan"][0] == "10.10.10.0/24"
        assert set(d["lan"][1:]) <= {"fe80::/64"}, d["lan"]
        assert d["client"] == TECHNICIAN
        assert d["client_in"] == "the SSH session that loaded the table"
        ev = "\n".join(got["evidence"])
        assert f"peers (SSH and ROS): {ADDR.LAPTOP_PUBLIC}" in ev
        assert f"this machine's LAN (SSH and ROS): {', '.join(d['lan'])}" in ev
        assert f"(SSH, until the next firewall apply): {TECHNICIAN} (port 22)" in ev
        # Run over SSH from another address that is no peer: a warning naming it.
        other = {"SSH_CONNECTION": f"{OUTSIDER} 50022 {ADDR.ROBOT_LOCAL} 22"}
        got = check(lab, "robot", tmp_path, "linux", **other)["linux.firewall"]
        assert got["status"] == "warn", got
        assert got["summary"].startswith(f"{OUTSIDER}, where this check runs from over SSH, "
                                         "would not get in again"), got["summary"]
        assert got["data"]["client_in"] == ""

        # The next apply, from the console (no SSH session), drops the session's entry.
        r = fw(lab, "robot", tmp_path, "firewall", "apply", "--yes", "--no-checks")
        assert r.returncode == 0 and "no SSH session runs this" in r.stdout, r.stdout + r.stderr
        assert outsider.ssh_auth_none(lab, ADDR.ROBOT_PUBLIC, timeout=1.5).get("error")
        # ... unless [firewall] allow keeps it for good.
        cfg = tmp_path / "allow.toml"
        cfg.write_text(lab.config_path("robot").read_text()
                       + f'\n[firewall]\nallow = ["{TECHNICIAN}"]\n')
        r = fw(lab, "robot", tmp_path, "firewall", "apply", "--yes", "--no-checks", config=cfg)
        assert r.returncode == 0 and f"[firewall] allow (SSH): {TECHNICIAN}" in r.stdout, r.stderr
        assert outsider.ssh_auth_none(lab, ADDR.ROBOT_PUBLIC).get("methods")
        assert lab.call_in("outsider", tcp_try, TECHNICIAN, ADDR.ROBOT_PUBLIC,
                           11311, 10.0) == "refused"
    finally:
        lab.call_in("robot", srv.close)


def test_a_peer_at_a_new_address_is_refused_at_once_and_told_it_is_the_firewall(fw_lab,
                                                                                 tmp_path):
    """Issue 32: the laptop's table holds the robot's address; the robot's modem restarts with a
    new one (no sync service running). The robot's connections to the laptop's forwarded ports
    are refused at once (a reset, not a wait), and the robot's advice reads the refusal as the
    laptop's firewall not knowing its new address, not as the laptop's forwarding."""
    lab = fw_lab
    r = fw(lab, "laptop", tmp_path / "fw", "firewall", "apply", "--yes", "--no-checks")
    assert r.returncode == 0, r.stdout + r.stderr
    new_ip = "203.0.113.78"
    with lab.set_robot_wan(new_ip):
        assert lab.call_in("robot", tcp_try_any, ADDR.LAPTOP_PUBLIC, 22, 10.0) == "refused"
        got = check(lab, "robot", tmp_path, "isp", "linux")
        assert got["isp.public_ip"]["data"]["public_ip"] == new_ip, explain(got)
        ssh = got["linux.ssh"]
        assert ssh["status"] == "fail", ssh
        assert ssh["data"]["peers"]["sami"]["tcp"] == "refused", ssh["data"]
        first = ssh["advice"][0]
        assert first["rule"] == "linux.ssh.refused" and first["goto_step"] == "linux", first
        assert "sami's peers-only firewall does not know this machine's address" in \
            first["meaning"], first
        assert first["actions"][0].startswith(f"Give sami's firewall this machine's address "
                                              f"{new_ip}"), first["actions"]


def test_firewall_undo_then_undo_loads_it_again_and_bad_input_exits_2(fw_lab, tmp_path):
    lab = fw_lab
    assert fw(lab, "robot", tmp_path, "firewall", "apply", "--yes", "--no-checks").returncode == 0
    before = nft(lab, "robot", "list", "table", "inet", "rosnet_tui").stdout
    r = fw(lab, "robot", tmp_path, "firewall", "undo", "--yes", "--no-checks")
    assert r.returncode == 0 and "Removed the table inet rosnet_tui" in r.stdout, r.stderr
    assert nft(lab, "robot", "list", "table", "inet", "rosnet_tui").returncode != 0
    r = fw(lab, "robot", tmp_path, "undo", "--yes", "--no-checks")
    assert r.returncode == 0, r.stdout + r.stderr
    assert nft(lab, "robot", "list", "table", "inet", "rosnet_tui").stdout == before
    # Bad input: a refusal with exit 2, never a traceback, and nothing loaded.
    bad = tmp_path / "bad.toml"
    bad.write_text(lab.config_path("robot").read_text().replace(
        f'public_ip = "{ADDR.LAPTOP_PUBLIC}"', 'public_ip = "not-an-ip"'))
    for argv in (("firewall", "apply", "--yes", "--profile", "nowhere"),
                 ("firewall", "apply", "--yes"), ("firewall", "frobnicate")):
        r = fw(lab, "robot", tmp_path, *argv, config=bad)
        assert r.returncode == 2, (argv, r.stdout, r.stderr)
        assert "Traceback" not in r.stderr
    assert nft(lab, "robot", "list", "table", "inet", "rosnet_tui").stdout == before


def test_the_set_follows_a_peers_address_change_within_the_sync_latency(lab, tmp_path):
    """The laptop's table allows the robot; the robot's modem restarts with a new public
    address; the laptop's sync service replaces the set (one transaction) within the sync
    latency, and the outsider-facing rules stay."""
    prepare_lab(lab)
    folder = tmp_path / "shared"
    folder.mkdir()
    rig = SyncRig(lab, tmp_path, "folder", folder=folder)
    rig.configure()
    try:
        r = fw(lab, "laptop", tmp_path / "fw", "firewall", "apply", "--yes", "--no-checks",
               config=rig.configs["laptop"])
        assert r.returncode == 0, r.stdout + r.stderr

        def allowed() -> str:
            return nft(lab, "laptop", "list", "set", "inet", "rosnet_tui", "peers4").stdout

        assert ADDR.ROBOT_PUBLIC in allowed()
        rig.start()
        assert rig.published("robot", ADDR.ROBOT_PUBLIC, WAIT), rig.log("robot")
        new_ip = "203.0.113.78"
        t0 = time.monotonic()
        lab.set_robot_wan(new_ip)
        assert wait_for(lambda: new_ip in allowed(), WAIT), rig.log("laptop")[-3000:]
        took = time.monotonic() - t0
        print(f"the laptop's firewall set followed the robot's new address in {took:.2f} s")
        # No longer than the sync latency (the hosts file's budget, tests/sync_support/bench.py),
        # plus the polling of this wait.
        assert took <= goal_s("folder", rig.interval_s) + 0.5, took
        assert ADDR.ROBOT_PUBLIC not in allowed()
        assert "firewall: allowed set" in rig.log("laptop")
        listing = nft(lab, "laptop", "list", "table", "inet", "rosnet_tui").stdout
        assert "drop" in listing
        # Another writer of the folder forges the robot's record (not the robot's key, the
        # highest seq): the set keeps the robot's genuine address, and the robot's next
        # address still gets through (issue 35).
        forged = sign_record(new_record("turtlebot", local_ip=ADDR.ROBOT_LOCAL,
                                        public_ip="198.51.100.99", role="master", seq=10**6),
                             sync_key("sami"))
        # The robot's service is held still meanwhile: its next publish would overwrite the
        # forged file before a busy laptop reads it (the test's race, not the product's).
        robot_pid = rig.procs["robot"].pid          # `ip netns exec` execs the service itself
        os.kill(robot_pid, signal.SIGSTOP)
        try:
            (folder / "turtlebot.json").write_text(forged.to_text())
            assert lab.wait_output(rig.procs["laptop"], r"refused the record turtlebot\.json .*"
                                   r"not by turtlebot's key", WAIT), rig.log("laptop")
        finally:
            os.kill(robot_pid, signal.SIGCONT)
        assert "198.51.100.99" not in allowed() and new_ip in allowed()
        lab.set_robot_wan("203.0.113.79")
        assert wait_for(lambda: "203.0.113.79" in allowed(), WAIT), rig.log("laptop")[-3000:]
        assert "198.51.100.99" not in allowed()
    finally:
        rig.stop()
        nft(lab, "laptop", "delete", "table", "inet", "rosnet_tui")
        lab.reset()
        lab.stop_roscore()


def test_as_a_user_the_exact_sudo_command_loads_the_previewed_table(fw_lab, tmp_path,
                                                                    monkeypatch, capsys):
    """In process, inside the robot's namespace, as if this user were not root: a stand-in sudo
    on PATH runs the command it is given (we are root already), so the path is exercised but the
    password."""
    import os
    import sys

    from rosnet_tui.cli import main
    from rosnet_tui.core.files import privilege

    lab = fw_lab
    fake = tmp_path / "bin"
    fake.mkdir()
    # Like sudo's env_reset, the stand-in drops the SSH session's variables.
    (fake / "sudo").write_text('#!/bin/sh\necho "sudo $*" > "$(dirname "$0")/called"\n'
                               '[ "$1" = "-n" ] && shift\n'
                               'exec env -u SSH_CONNECTION -u SSH_CLIENT "$@"\n')
    os.chmod(fake / "sudo", 0o755)
    monkeypatch.setenv("PATH", f"{fake}{os.pathsep}{os.environ.get('PATH', '')}")
    monkeypatch.setattr(privilege, "is_root", lambda: False)
    monkeypatch.setenv("SSH_CONNECTION", f"{TECHNICIAN} 50022 {ADDR.ROBOT_LOCAL} 22")
    cfg, state = lab.config_path("robot"), tmp_path / "state"
    rc = lab.call_in("robot", main, ["--config", str(cfg), "firewall", "apply", "--yes",
                                     "--no-checks", "--state-dir", str(state)])
    out = capsys.readouterr().out
    assert rc == 0, out
    called = [x for x in (fake / "called").read_text().split() if x != "-n"]
    assert called[:4] == ["sudo", sys.executable, "-m", "rosnet_tui"]
    joined = " ".join(called)
    assert "firewall apply --profile remote --expect-digest" in joined and "--yes" in joined
    assert "needs root; running:" in out and "+table inet rosnet_tui {" in out
    # The session was read here, on the user's side, and handed to root (sudo drops it).
    assert f"--session-ip {TECHNICIAN} --session-port 22 --yes" in joined
    listing = nft(lab, "robot", "list", "table", "inet", "rosnet_tui").stdout
    assert ADDR.LAPTOP_PUBLIC in listing and f"{TECHNICIAN} . 22" in listing
    # The digest names what was previewed: another ruleset is refused, nothing loaded.
    nft(lab, "robot", "delete", "table", "inet", "rosnet_tui")
    r = fw(lab, "robot", state, "firewall", "apply", "--yes", "--no-checks",
           "--expect-digest", "0" * 64, "--state-dir", str(state))
    assert r.returncode == 1 and "not the one previewed" in r.stderr, r.stdout + r.stderr
    assert nft(lab, "robot", "list", "table", "inet", "rosnet_tui").returncode != 0
