"""The real wizard under a pseudo-terminal, treated the way a mobile SSH link treats it (issue 12):
keys in bursts, a dropped session (SIGHUP), a kill (SIGTERM), quitting while checks hang on a
dead network, a terminal that cannot draw (TERM=dumb), a crash.

Everything runs on loopback (bench/local_env.py), or in network namespaces this test builds and
removes (the blackholed network).
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import termios
import time
from pathlib import Path

import pytest

from bench.local_env import base_env, local_world, spawn_app
from bench.pty_harness import PtyProcess
from bench.rows_local import app_title
from rosnet_tui.core.config.settings_model import (
    Peer,
    ProbeSettings,
    RosSettings,
    Settings,
    ThisComponent,
)
from rosnet_tui.core.saved.settings import atomic_write_text, load_settings, render_settings
from rosnet_tui.core.saved.ui_state import UiState

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def world():
    with local_world() as w:
        yield w


def settle(p: PtyProcess, quiet: float = 0.4) -> None:
    p.wait_quiet(quiet, 10)


def press(p: PtyProcess, keys: str, shown: str | None = None, timeout: float = 10) -> str:
    mark = p.mark
    p.send(keys)
    if shown is not None:
        assert p.wait_text(shown, timeout, mark) is not None, p.text_since(mark)[-800:]
    else:
        p.wait_for(lambda t: True, 2, mark)
    settle(p)
    return p.text_since(mark)


def wait_exit(p: PtyProcess, seconds: float) -> float | None:
    """Seconds until the program exited (reading its output meanwhile), None if it did not."""
    t0 = time.monotonic()
    while p.alive() and time.monotonic() - t0 < seconds:
        p.pump(0.02)
    p.drain(0.1)
    return None if p.alive() else time.monotonic() - t0


TYPED_PEER = {"name": "ops-laptop", "local_ip": "10.1.2.3", "public_ip": "", "ssh_user": ""}


def draft_peers(ui_json: Path, config: Path) -> list:
    """The peers of *config*'s set-up draft kept in *ui_json* ([] while there is none)."""
    try:
        return json.loads(ui_json.read_text())["drafts"][UiState.draft_key(config)]["peers"]
    except (OSError, ValueError, KeyError, TypeError):
        return []


def test_a_dropped_session_resumes_with_its_results_and_draft(world):
    """SIGHUP (what sshd sends when the link drops) mid-way: the next start reopens the
    half-filled set-up, and the router step shows its results with their time."""
    world.fresh_state()
    p = spawn_app(world)
    try:
        assert p.wait_text(app_title("1"), 30) is not None
        settle(p)
        press(p, "2", app_title("2"))
        press(p, "r", "checking")
        assert p.wait_for(lambda t: t.count("PASS") + t.count("FAIL") >= 3, 20) is not None
        settle(p, 1.0)
        press(p, "s", "This component")
        press(p, "\x0e", "name")  # Ctrl+N: a new peer row, focused
        press(p, "ops-laptop\t10.1.2.3")
        # The draft is kept 0.3 s after the last key: wait for it (bounded), not for a time a
        # loaded machine may not keep.
        ui_json = world.root / "state" / "rosnet-tui" / "ui.json"
        end = time.monotonic() + 15
        while draft_peers(ui_json, world.config)[-1:] != [TYPED_PEER] and time.monotonic() < end:
            p.pump(0.05)
        os.kill(p.pid, signal.SIGHUP)
        assert wait_exit(p, 5) is not None, "SIGHUP did not end the wizard"
    finally:
        p.close()
    state = json.loads((world.root / "state" / "rosnet-tui" / "ui.json").read_text())
    draft = state["drafts"][UiState.draft_key(world.config)]  # kept for its settings file
    assert draft["peers"][-1] == TYPED_PEER
    assert {"router.local_ip", "router.port_free", "router.listener",
            "router.port_open"} <= set(state["results"])

    p = spawn_app(world)
    try:
        out = p.wait_text("ops-laptop", 30)
        assert out is not None, p.text_since(0)[-800:]
        assert p.wait_text("Back where you", 10) is not None  # the set-up, as it was left
        assert "10.1.2.3" in p.text_since(0)
        settle(p)
        press(p, "\x1b", None)  # back without saving: the draft is dropped
        text = press(p, "2", None)
        assert "results of" in p.text_since(0)  # shown as earlier results, with their time
        assert "not run yet" not in text
    finally:
        p.close(b"\x11")
    state = json.loads((world.root / "state" / "rosnet-tui" / "ui.json").read_text())
    assert not state.get("drafts") and "draft" not in state


def test_sigterm_gives_the_terminal_back(world):
    world.fresh_state()
    p = spawn_app(world)
    try:
        assert p.wait_text(app_title("1"), 30) is not None
        settle(p)
        mark = p.mark
        os.kill(p.pid, signal.SIGTERM)
        # ends on the signal (nothing runs at step 1 to wait for): the bound only tells an end
        # from a hang, far from what a loaded machine takes to end a Python process
        took = wait_exit(p, 20)
        assert took is not None, "SIGTERM did not end the wizard"
        tail = p.raw_since(mark)
        for seq, what in ((b"\x1b[?1049l", "alternate screen off"),
                          (b"\x1b[?25h", "cursor shown"),
                          (b"\x1b[?1000l", "mouse reporting off")):
            assert seq in tail, f"{what}: {seq!r} not written on SIGTERM"
        attrs = termios.tcgetattr(p.master)
        assert attrs[3] & termios.ECHO and attrs[3] & termios.ICANON, "echo not restored"
        assert p.proc.returncode == 128 + signal.SIGTERM
    finally:
        p.close()


BLACKHOLE_NS = "rosnet-t12-bh"


@contextlib.contextmanager
def blackholed_network():
    """A namespace whose only link leads to one where every packet is silently dropped: the
    peer's addresses and the probe service never answer, never refuse."""
    if os.geteuid() != 0:
        pytest.skip("needs root for network namespaces")

    def ip(*args: str) -> None:
        subprocess.run(["ip", *args], check=True, capture_output=True, timeout=10)

    sink = BLACKHOLE_NS + "-sink"
    for ns in (BLACKHOLE_NS, sink):
        subprocess.run(["ip", "netns", "del", ns], capture_output=True, timeout=10)
    try:
        ip("netns", "add", BLACKHOLE_NS)
        ip("netns", "add", sink)
    except (subprocess.CalledProcessError, FileNotFoundError) as exc:
        pytest.skip(f"network namespaces not available: {exc}")
    try:
        ip("-n", BLACKHOLE_NS, "link", "set", "lo", "up")
        ip("-n", BLACKHOLE_NS, "link", "add", "bh0", "type", "veth", "peer", "name", "bh1",
           "netns", sink)
        ip("-n", BLACKHOLE_NS, "addr", "add", "203.0.113.1/24", "dev", "bh0")
        ip("-n", BLACKHOLE_NS, "link", "set", "bh0", "up")
        ip("-n", sink, "link", "set", "bh1", "up")
        for addr in ("203.0.113.2", "203.0.113.7", "203.0.113.9", "203.0.113.254"):
            ip("-n", BLACKHOLE_NS, "neigh", "add", addr, "lladdr", "02:00:00:00:99:99", "dev",
               "bh0", "nud", "permanent")  # frames to a station that does not exist
        ip("-n", BLACKHOLE_NS, "route", "add", "default", "via", "203.0.113.254")
        yield BLACKHOLE_NS
    finally:
        for ns in (BLACKHOLE_NS, sink):
            subprocess.run(["ip", "netns", "del", ns], capture_output=True, timeout=10)


@pytest.mark.parametrize("step", ["3", "4"])
def test_quit_while_checks_hang_on_a_dead_network_does_not_wait_for_them(world, step, tmp_path):
    """SSH, ping and ROS to a peer whose packets are dropped: q leaves at once (it waited out the
    checks: 10 s)."""
    with blackholed_network() as ns:
        s = Settings(this=ThisComponent(name="bhbox", role="master", connection="home",
                                        profile="remote", local_ip="203.0.113.1",
                                        interface="bh0"),
                     peers=[Peer(name="deadpeer", local_ip="203.0.113.7",
                                 public_ip="203.0.113.2", ssh_user="ops")],
                     ros=RosSettings(master="bhbox"),
                     probe=ProbeSettings(public_ip_urls=["http://203.0.113.9/ip"],
                                         port_check_url="http://203.0.113.9"))
        cfg = tmp_path / "blackholed.toml"
        atomic_write_text(cfg, render_settings(s))
        world.fresh_state()
        argv = ["ip", "netns", "exec", ns, sys.executable, "-m", "rosnet_tui", "--config",
                str(cfg)]
        p = PtyProcess(argv, world.env(), cwd=str(REPO))
        try:
            assert p.wait_text(app_title("1"), 30) is not None, p.text_since(0)[-500:]
            settle(p)
            press(p, step, app_title(step))
            press(p, "r", "checking")
            time.sleep(0.7)  # the checks are now waiting on the dead network
            t0 = p.send("q")
            took = wait_exit(p, 15)
            assert took is not None, "q did not end the wizard"
            # the defect waited out the checks (10 s); a loaded machine may take seconds to end
            # a Python process, so the bound is 5 s, not the 1 s a quiet machine shows
            assert time.monotonic() - t0 < 5.0, took
            assert p.proc.returncode == 0
        finally:
            p.close()


def test_a_terminal_that_cannot_draw_is_pointed_to_check(world):
    p = PtyProcess([sys.executable, "-m", "rosnet_tui"], world.env(), term="dumb",
                   cwd=str(REPO))
    try:
        assert wait_exit(p, 20) is not None
        text = p.text_since(0)
        assert "TERM=dumb" in text and "rosnet-tui check" in text
        assert "\x1b[" not in p.raw_since(0).decode(errors="replace")  # no screen drawn
        assert p.proc.returncode == 2
        assert len([ln for ln in text.splitlines() if ln.strip()]) == 1  # one line
    finally:
        p.close()


def test_a_crash_never_exits_0(world, tmp_path):
    """An unexpected error inside the wizard ends it with a non-zero status (it exited 0)."""
    script = tmp_path / "crash.py"
    script.write_text(
        "import sys\n"
        "from rosnet_tui.ui.step_screen import StepScreen\n"
        "def boom(self):\n"
        "    raise RuntimeError('a bug')\n"
        "StepScreen.action_run_checks = boom\n"
        "from rosnet_tui.cli import main\n"
        "sys.exit(main([]))\n")
    world.fresh_state()
    p = PtyProcess([sys.executable, str(script)], world.env(), cwd=str(REPO))
    try:
        assert p.wait_text(app_title("1"), 30) is not None
        settle(p)
        p.send("r")
        assert wait_exit(p, 10) is not None
        assert p.proc.returncode == 1
        assert "a bug" in p.text_since(0)
    finally:
        p.close()


def test_setup_filled_in_one_burst_over_a_pty(world, tmp_path):
    """The issue's first-run burst, written to the terminal in one write: saved as typed."""
    cfg = tmp_path / "fresh.toml"
    world.fresh_state()
    env = base_env() | world.env()
    p = PtyProcess([sys.executable, "-m", "rosnet_tui", "--config", str(cfg)], env,
                   cwd=str(REPO))
    try:
        assert p.wait_text("This component", 30) is not None
        settle(p)
        mark = p.mark
        p.send("robot1\x0esami\t192.168.1.10\t198.51.100.2\x7f3\x13")
        assert p.wait_text(app_title("1"), 15, mark) is not None, p.text_since(mark)[-800:]
        settle(p)
        assert p.alive()
    finally:
        p.close(b"\x11")
    saved = load_settings(cfg)
    assert saved is not None and saved.this.name == "robot1"
    assert [(x.name, x.local_ip, x.public_ip) for x in saved.peers] == [
        ("sami", "192.168.1.10", "198.51.100.3")]


def _process_state(pid: int) -> str:
    with open(f"/proc/{pid}/stat", encoding="ascii") as f:
        return f.read().rsplit(")", 1)[1].split()[0]


def test_ctrl_z_suspends_and_fg_brings_it_back(world):
    world.fresh_state()
    p = spawn_app(world)
    try:
        assert p.wait_text(app_title("1"), 30) is not None
        settle(p)
        mark = p.mark
        p.send("\x1a")  # Ctrl+Z
        deadline = time.monotonic() + 5
        while _process_state(p.pid) != "T" and time.monotonic() < deadline:
            p.pump(0.05)
        assert _process_state(p.pid) == "T", "Ctrl+Z did not suspend the wizard"
        assert b"\x1b[?1049l" in p.raw_since(mark)  # the terminal given back meanwhile
        mark = p.mark
        os.kill(p.pid, signal.SIGCONT)  # what the shell's fg does
        assert p.wait_text(app_title("1"), 10, mark) is not None  # drawn again, whole
        assert p.alive()
    finally:
        p.close(b"\x11")
