"""`rosnet-tui check` served by the warm process a cold run leaves (rosnet_tui/cli/warm.py).

Real processes only: the command as a user runs it, the warm process it starts, a loopback web
service standing in for the what-is-my-IP service. Which process asked that service (found by
its TCP port) and that process's parent tell a served run from a cold one.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import psutil
import pytest

from rosnet_tui.cli import warm
from tests.builders import loopback_master_config
from tests.plugins.web import WebServer


class Asked:
    """A what-is-my-IP service on loopback (tests/plugins/web.py) that notes which process asked
    it and that process's parent, and can hold its answer (``hold`` cleared) to keep a check
    running."""

    def __init__(self) -> None:
        self.askers: list[tuple[int, int]] = []       # (pid, parent pid)
        self.hold = threading.Event()
        self.hold.set()
        self.asked = threading.Event()
        self.web = WebServer()
        self.web.routes["/ip"] = (200, "203.0.113.9\n")
        self.web.on_request = self._noted
        self.url = self.web.url("/ip")

    def _noted(self, client: tuple[str, int]) -> None:
        self.askers.append(_owner(client))
        self.asked.set()
        self.hold.wait(20)

    def close(self) -> None:
        self.hold.set()
        self.web.close()


def _owner(client: tuple[str, int]) -> tuple[int, int]:
    for c in psutil.net_connections(kind="tcp4"):
        if c.laddr and (c.laddr.ip, c.laddr.port) == tuple(client) and c.pid:
            try:
                return c.pid, psutil.Process(c.pid).ppid()
            except psutil.Error:
                break
    return 0, 0


@pytest.fixture
def asked():
    a = Asked()
    yield a
    a.close()


@pytest.fixture
def box(tmp_path, asked):
    """A user's settings, environment (warm processes on) and socket folder; every warm process
    started under it is stopped at the end."""
    run_dir = Path(tempfile.mkdtemp(prefix="rw", dir="/tmp"))   # a socket's path is short
    env = {k: v for k, v in os.environ.items()
           if not k.lower().endswith("_proxy") and k != warm.ENV_SWITCH}
    env.update(XDG_STATE_HOME=str(tmp_path / "state"), XDG_CONFIG_HOME=str(tmp_path / "cfg"),
               XDG_RUNTIME_DIR=str(run_dir), NO_COLOR="1", COLUMNS="200")

    class Box:
        pass

    b = Box()
    b.dir, b.env, b.sockets = tmp_path, env, run_dir / "rosnet-tui"
    write_settings(tmp_path, asked.url)
    yield b
    for p in warm_processes(b):
        p.kill()
    psutil.wait_procs(warm_processes(b), timeout=5)
    shutil.rmtree(run_dir, ignore_errors=True)


def write_settings(folder: Path, url: str, keep_warm_s: float = 60, timeout_s: float = 2) -> None:
    loopback_master_config(folder, url, "http://127.0.0.1:9", timeout_s=timeout_s,
                           keep_warm_s=keep_warm_s)


def warm_processes(b) -> list[psutil.Process]:
    out = []
    for p in psutil.process_iter(["cmdline"]):
        cmd = p.info["cmdline"] or []
        if any("serve_warm" in c for c in cmd) and any(str(b.sockets) in c for c in cmd):
            out.append(p)
    return out


def check(b, *args: str, env: dict | None = None, **popen) -> subprocess.Popen:
    """`rosnet-tui check --step isp --json --no-upnp ARGS` as a user starts it, in b.dir."""
    return subprocess.Popen(
        [sys.executable, "-m", "rosnet_tui", "check", "--step", "isp", "--json", "--no-upnp",
         "--config", "config.toml", *args], cwd=b.dir, env=env or b.env,
        stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        **popen)


def finish(proc: subprocess.Popen, timeout: float = 30) -> tuple[int, str, str]:
    out, err = proc.communicate(timeout=timeout)
    return proc.returncode, out, err


def verdicts(out: str) -> list[tuple[str, str, str]]:
    return [(c["id"], c["status"], c["summary"]) for c in json.loads(out)["checks"]]


def progress(err: str) -> list[str]:
    """The progress lines, without their numbers (the checks end in any order)."""
    return sorted(re.sub(r"^\[\d+/\d+\] ", "", line) for line in err.splitlines())


def wait_for(predicate, timeout: float = 20.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        got = predicate()
        if got:
            return got
        time.sleep(0.05)
    return predicate()


def the_warm_process(b) -> psutil.Process:
    """The one warm process of *b*, once it listens."""
    ready = wait_for(lambda: list(b.sockets.glob("warm-*.sock")) if b.sockets.exists() else [])
    assert len(ready) == 1, ready
    procs = warm_processes(b)
    assert len(procs) == 1, procs
    return procs[0]


def test_the_next_run_is_served_by_the_warm_process_and_sees_what_a_cold_one_sees(box, asked):
    code, out, err = finish(check(box))
    assert code == 0, err
    cold_pid, cold_parent = asked.askers[-1]
    server = the_warm_process(box)
    assert cold_parent != server.pid and cold_pid != server.pid

    # the settings named relative to the command's own directory, its stdout a pipe of its own
    code2, out2, err2 = finish(check(box))
    assert asked.askers[-1][1] == server.pid            # asked by a child of the warm process
    # what a cold run says now (the first one recorded the public address: "unchanged since")
    code3, out3, err3 = finish(check(box, env=dict(box.env, ROSNET_TUI_WARM="0")))
    assert asked.askers[-1][1] != server.pid
    assert code2 == code3 == 0 and verdicts(out2) == verdicts(out3)
    assert "unchanged since" in out2 and progress(err2) == progress(err3)
    assert the_warm_process(box).pid == server.pid      # still there for the next one


def test_a_served_run_refuses_bad_input_as_a_cold_one_does(box, asked):
    assert finish(check(box))[0] == 0
    the_warm_process(box)
    served = finish(check(box, "--timeout", "soon"))
    cold = finish(check(box, "--timeout", "soon", env=dict(box.env, ROSNET_TUI_WARM="0")))
    assert served[0] == cold[0] == 2
    assert served[2] == cold[2] and "--timeout" in served[2]
    # a missing settings file: the same refusal, read from the served run's directory
    (box.dir / "config.toml").rename(box.dir / "elsewhere.toml")
    code, _out, err = finish(check(box))
    assert code == 2 and "config.toml" in err


def test_another_environment_gets_another_warm_process(box, asked):
    assert finish(check(box))[0] == 0
    first = the_warm_process(box)
    other = dict(box.env, ROS_DOMAIN_ID="7")
    assert finish(check(box, env=other))[0] == 0
    assert asked.askers[-1][1] != first.pid             # not served by the first one
    assert wait_for(lambda: len(list(box.sockets.glob("warm-*.sock"))) == 2)
    assert warm.key(box.env) != warm.key(other)
    assert warm.key(box.env) == warm.key(dict(box.env, PWD="/elsewhere", OLDPWD="/"))


def test_ctrl_c_stops_the_served_check(box, asked):
    assert finish(check(box))[0] == 0
    server = the_warm_process(box)
    asked.hold.clear()
    asked.asked.clear()
    proc = check(box)
    assert asked.asked.wait(15)
    child = asked.askers[-1][0]
    assert asked.askers[-1][1] == server.pid
    t0 = time.monotonic()
    proc.send_signal(signal.SIGINT)
    code, _out, err = finish(proc, timeout=10)
    assert code == 130 and "interrupted" in err
    assert time.monotonic() - t0 < 3
    assert wait_for(lambda: not psutil.pid_exists(child) or
                    psutil.Process(child).status() == psutil.STATUS_ZOMBIE, 5)


def held_served_check(b, asked: Asked, **popen) -> tuple[subprocess.Popen, int]:
    """A served check kept running (the service holds its answer, the check would wait 20 s):
    the command and the child of the warm process that runs it."""
    write_settings(b.dir, asked.url, timeout_s=20)
    asked.hold.clear()
    asked.asked.clear()
    proc = check(b, **popen)
    assert asked.asked.wait(15)
    return proc, asked.askers[-1][0]


def test_a_killed_command_takes_its_served_check_with_it(box, asked):
    assert finish(check(box))[0] == 0
    the_warm_process(box)
    proc, child = held_served_check(box, asked)
    proc.kill()
    proc.communicate(timeout=10)
    assert wait_for(lambda: not psutil.pid_exists(child) or
                    psutil.Process(child).status() == psutil.STATUS_ZOMBIE, 3)


def test_ctrl_z_stops_the_served_check_and_fg_goes_on(box, asked):
    """A technician's Ctrl-Z stops the command: the child that runs it stops too (it would go
    on writing to the terminal), and both go on when the shell continues the command."""
    assert finish(check(box))[0] == 0
    the_warm_process(box)
    proc, child = held_served_check(box, asked, process_group=0)   # a job of a shell
    stopped = psutil.STATUS_STOPPED
    proc.send_signal(signal.SIGTSTP)
    assert wait_for(lambda: psutil.Process(proc.pid).status() == stopped, 5)
    assert wait_for(lambda: psutil.Process(child).status() == stopped, 5)
    proc.send_signal(signal.SIGCONT)
    assert wait_for(lambda: psutil.Process(child).status() != stopped, 5)
    assert psutil.Process(proc.pid).status() != stopped
    asked.hold.set()
    code, out, _err = finish(proc)
    assert code == 0 and verdicts(out)


def test_ctrl_z_where_nothing_may_stop_leaves_the_check_running(box, asked):
    """A command in an orphaned process group (started by a process that left, or by setsid)
    is not stopped by the kernel on SIGTSTP: nobody could continue it. The child, stopped first,
    must go on at once, or the run would hang."""
    assert finish(check(box))[0] == 0
    the_warm_process(box)
    proc, child = held_served_check(box, asked, start_new_session=True)
    proc.send_signal(signal.SIGTSTP)
    time.sleep(0.5)
    asked.hold.set()
    code, out, _err = finish(proc, timeout=15)
    assert code == 0 and verdicts(out)


def test_a_command_killed_while_stopped_takes_its_stopped_child_with_it(box, asked):
    """Ctrl-Z, then `kill -9 %1` after the warm process's idle time: the child, stopped with the
    command, cannot see it go; the warm process, still there for it, continues it, and it
    ends."""
    write_settings(box.dir, asked.url, keep_warm_s=5)   # time enough to start the next run
    assert finish(check(box))[0] == 0
    server = the_warm_process(box)
    proc, child = held_served_check(box, asked, process_group=0)
    proc.send_signal(signal.SIGTSTP)
    assert wait_for(lambda: psutil.Process(child).status() == psutil.STATUS_STOPPED, 5)
    time.sleep(5.5)                     # its 5 s since the run came are up: it stays for its child
    assert server.is_running() and server.status() != psutil.STATUS_ZOMBIE
    proc.kill()
    proc.communicate(timeout=10)
    assert wait_for(lambda: not psutil.pid_exists(child) or
                    psutil.Process(child).status() == psutil.STATUS_ZOMBIE, 5)


def test_no_warm_process_when_it_is_switched_off(box, asked):
    assert finish(check(box, env=dict(box.env, ROSNET_TUI_WARM="0")))[0] == 0
    write_settings(box.dir, asked.url, keep_warm_s=0)
    assert finish(check(box))[0] == 0
    time.sleep(1.5)
    assert warm_processes(box) == [] and not list(box.sockets.glob("warm-*"))
    # one that is there stops when a run it serves reads keep_warm_s = 0
    write_settings(box.dir, asked.url)
    assert finish(check(box))[0] == 0
    server = the_warm_process(box)
    write_settings(box.dir, asked.url, keep_warm_s=0)
    assert finish(check(box))[0] == 0
    assert asked.askers[-1][1] == server.pid
    assert wait_for(lambda: not server.is_running() or server.status() == psutil.STATUS_ZOMBIE, 5)
    assert wait_for(lambda: not list(box.sockets.glob("warm-*")), 5)


def test_an_idle_warm_process_leaves_and_takes_its_files(box, asked):
    write_settings(box.dir, asked.url, keep_warm_s=1)
    assert finish(check(box))[0] == 0
    server = the_warm_process(box)
    assert wait_for(lambda: not server.is_running() or server.status() == psutil.STATUS_ZOMBIE, 8)
    assert wait_for(lambda: not list(box.sockets.iterdir()), 5)


def test_a_killed_warm_process_is_replaced(box, asked):
    assert finish(check(box))[0] == 0
    server = the_warm_process(box)
    server.kill()
    server.wait(5)
    assert list(box.sockets.glob("warm-*.sock"))         # left behind
    code, out, err = finish(check(box))
    assert code == 0, err
    assert asked.askers[-1][1] != server.pid
    again = the_warm_process(box)
    assert again.pid != server.pid
    finish(check(box))
    assert asked.askers[-1][1] == again.pid


def test_a_socket_folder_others_may_enter_is_not_used(box, asked):
    box.sockets.mkdir(mode=0o755)
    os.chmod(box.sockets, 0o755)
    assert finish(check(box))[0] == 0
    time.sleep(1.5)
    assert warm_processes(box) == [] and list(box.sockets.iterdir()) == []
    if os.geteuid() == 0:       # a folder of another user's, as only root can make here
        os.chmod(box.sockets, 0o700)
        os.chown(box.sockets, 65534, 65534)
        assert finish(check(box))[0] == 0
        time.sleep(1.5)
        assert warm_processes(box) == []


def test_two_cold_runs_at_once_leave_one_warm_process(box, asked):
    procs = [check(box) for _ in range(3)]
    assert [finish(p)[0] for p in procs] == [0, 0, 0]
    the_warm_process(box)
    time.sleep(1.5)
    assert len(warm_processes(box)) == 1


def test_a_terminated_command_ends_as_a_cold_one_would(box, asked):
    assert finish(check(box))[0] == 0
    the_warm_process(box)
    proc, child = held_served_check(box, asked)
    proc.terminate()
    code, _out, _err = finish(proc, timeout=10)
    assert code == -signal.SIGTERM
    assert wait_for(lambda: not psutil.pid_exists(child) or
                    psutil.Process(child).status() == psutil.STATUS_ZOMBIE, 3)


def answer(s: socket.socket) -> bytes | str:
    try:
        return s.recv(64)
    except ConnectionResetError:
        return "reset"


def test_what_is_not_a_request_is_refused_and_the_next_run_served(box, asked):
    assert finish(check(box))[0] == 0
    server = the_warm_process(box)
    (path,) = box.sockets.glob("warm-*.sock")
    junk = [b"", b"\x00\x00\x00\x05hello", b"\xff\xff\xff\xff", b"\x00\x00\x00\x02{}"]
    for data in junk:
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
            s.settimeout(10)
            s.connect(str(path))
            if data:
                s.sendall(data)
            s.shutdown(socket.SHUT_WR)
            assert answer(s) in (b"", "reset")  # no child named, nothing run
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:   # a request with no stdio
        s.settimeout(10)
        s.connect(str(path))
        body = json.dumps({"argv": ["check"], "argv0": "x", "cwd": "/", "env": {},
                           "umask": 18}).encode()
        s.sendall(struct.pack("!I", len(body)) + body)
        s.shutdown(socket.SHUT_WR)
        assert answer(s) in (b"", "reset")
    assert finish(check(box))[0] == 0
    assert asked.askers[-1][1] == server.pid


OTHER_PYTHON = "/usr/bin/python3"     # one another user may run (this one may be under /root)


@pytest.mark.skipif(os.geteuid() != 0 or not os.access(OTHER_PYTHON, os.X_OK),
                    reason="needs root (connects as another user) and /usr/bin/python3")
def test_another_user_is_not_served_even_where_the_files_would_let_them(box, asked):
    assert finish(check(box))[0] == 0
    the_warm_process(box)
    (path,) = box.sockets.glob("warm-*.sock")
    for p in (box.sockets.parent, box.sockets):
        os.chmod(p, 0o755)
    os.chmod(path, 0o777)       # a mistake of the user's, say: the process still checks who asks
    body = json.dumps({"argv": ["check", "--help"], "argv0": "x", "cwd": "/", "env": {},
                       "umask": 18}).encode()
    probe = ("import socket, struct\ns = socket.socket(socket.AF_UNIX)\ns.settimeout(10)\n"
             f"s.connect({str(path)!r})\nbody = {body!r}\n"
             "try:\n"
             "    socket.send_fds(s, [struct.pack('!I', len(body))], [0, 1, 2])\n"
             "    s.sendall(body)\n    s.shutdown(socket.SHUT_WR)\n"
             "except (BrokenPipeError, ConnectionResetError):\n"   # refused before we sent
             "    print('reset')\n    raise SystemExit(0)\n"
             "try:\n    print(repr(s.recv(64)))\n"
             "except ConnectionResetError:\n    print('reset')\n")
    out = subprocess.run([OTHER_PYTHON, "-c", probe], capture_output=True, text=True,
                         timeout=30, user=65534, group=65534, cwd="/")
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() in ("b''", "reset")


@pytest.mark.skipif(os.geteuid() != 0, reason="needs root: makes a network namespace")
def test_the_key_stays_when_a_network_namespace_comes_and_goes():
    """`ip netns add` mounts a handle under /run/netns: the key followed it, and in CI a run
    beside the lab's tests missed the warm process its first run had left."""
    name = f"rnl-warmkey-{os.getpid()}"
    before = warm.key()
    subprocess.run(["ip", "netns", "add", name], check=True, capture_output=True, timeout=30)
    try:
        during = warm.key()
    finally:
        subprocess.run(["ip", "netns", "del", name], capture_output=True, timeout=30)
    assert during == before == warm.key()


def test_a_request_keeps_undecodable_bytes_and_nothing_else_is_taken_for_one():
    r = warm.Request(["check", "--json"], "rosnet-tui", "/tmp", {"NAME": "caf\udce9"}, 0o022)
    assert warm.Request.decode(r.encode()) == r
    good = json.loads(r.encode())
    bad = [b"", b"[]", b"not json", json.dumps({**good, "more": 1}).encode(),
           json.dumps({k: v for k, v in good.items() if k != "env"}).encode()]
    for field, value in [("argv", "check"), ("argv", [1]), ("env", {"A": 1}), ("env", [["A", "b"]]),
                         ("umask", True), ("umask", -1), ("umask", 0o1000), ("cwd", None),
                         ("argv", [[[["deep"]]]])]:
        bad.append(json.dumps({**good, field: value}).encode())
    assert [warm.Request.decode(b) for b in bad] == [None] * len(bad)


def test_the_warm_process_has_loaded_what_a_run_of_the_checks_loads(tmp_path, asked):
    """What a served run would still import is CPU on its path again (the ROS steps: the lab's
    bench, row 2)."""
    write_settings(tmp_path, asked.url)
    code = ("import json, sys\nfrom rosnet_tui.cli import main, preload_warm\npreload_warm()\n"
            "before = set(sys.modules)\n"
            "main(['check', '--step', 'isp', '--step', 'router', '--json', '--no-upnp', "
            "'--config', 'config.toml'])\n"
            "print('NEW', json.dumps(sorted(set(sys.modules) - before)))\n")
    env = {k: v for k, v in os.environ.items() if not k.lower().endswith("_proxy")}
    env.update(XDG_STATE_HOME=str(tmp_path / "state"), XDG_CONFIG_HOME=str(tmp_path / "cfg"))
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, text=True,
                         capture_output=True, timeout=60, stdin=subprocess.DEVNULL)
    line = [ln for ln in out.stdout.splitlines() if ln.startswith("NEW ")]
    assert line, out.stderr[-2000:]
    assert json.loads(line[0][4:]) == []
