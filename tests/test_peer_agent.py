"""The round's peer agent (core/peer/agentproto.py, the master's side core/peer/peer_agent.py): one program
per peer and round serves every probe the checks run there (issue 25, bench row 8).

The program itself runs here under the distribution's ``python3 -S`` as a peer runs it (fed on
stdin after BOOT); the master's side talks to it over a real sshd. Each run keeps its own output,
exit status and timeout; the agent bounds its own life (stdin's end, a hard maximum).
"""

from __future__ import annotations

import ast
import asyncio
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from rosnet_tui.core.checks.probes import agents as probe_agents
from rosnet_tui.core.peer import agentproto, chatproto, commands, rosproto, zenohproto
from rosnet_tui.core.peer.peer_agent import (
    AGENT_SOURCE,
    AgentKind,
    PeerAgents,
    agent_run,
    boot_payload,
)
from rosnet_tui.core.ssh.pool import SshPool
from rosnet_tui.core.ssh.session import ssh_run
from tests.builders import free_port

PY = shutil.which("python3") or "python3"
PPID = b"import os, sys, time\nprint(os.getppid(), *sys.argv[1:], flush=True)\n" \
       b"time.sleep(float(sys.argv[1]) if sys.argv[1:] else 0)\nsys.exit(7)\n"


def alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:    # a zombie has ended
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except (FileNotFoundError, ProcessLookupError):   # gone (reaped), maybe since we looked
        return False


def gone_within(pid: int, seconds: float) -> bool:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if not alive(pid):
            return True
        time.sleep(0.02)
    return not alive(pid)


class Local:
    """The agent as a peer runs it, here: ``python3 -S -c BOOT MAX_S [no-install]``."""

    def __init__(self, max_s: float = 30, *extra: str, programs=(("p", PPID, None),)) -> None:
        self.proc = subprocess.Popen([PY, "-S", "-c", agentproto.BOOT, str(max_s), *extra],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE)
        self.send_raw(boot_payload(tuple(programs)))
        ready = self.line()
        assert ready.get(agentproto.READY) == 1, ready
        self.pid = ready["pid"]

    def send_raw(self, data: bytes) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write(data)
        self.proc.stdin.flush()

    def send(self, msg: dict) -> None:
        self.send_raw(json.dumps(msg).encode() + b"\n")

    def line(self) -> dict:
        assert self.proc.stdout is not None
        raw = self.proc.stdout.readline().decode()
        body, _, seq = raw.rstrip("\n").rpartition("#")
        assert seq.isdigit(), raw
        return json.loads(body)

    def until_exits(self, n: int) -> dict[int, dict]:
        """Read until *n* runs ended: {run id: {"o": stdout, "e": stderr, "x": status}}."""
        runs: dict[int, dict] = {}
        while sum("x" in r for r in runs.values()) < n:
            msg = self.line()
            r = runs.setdefault(msg["id"], {"o": "", "e": ""})
            for k in ("o", "e"):
                r[k] += msg.get(k, "")
            if "x" in msg:
                r["x"] = msg["x"]
        return runs

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait(5)
        for s in (self.proc.stdin, self.proc.stdout, self.proc.stderr):
            if s is not None:
                s.close()


@pytest.fixture
def local():
    made: list[Local] = []

    def make(*a, **kw) -> Local:
        made.append(Local(*a, **kw))
        return made[-1]

    yield make
    for a in made:
        a.close()


@pytest.mark.parametrize("module", [agentproto, chatproto, rosproto])
def test_peer_programs_are_py38_stdlib_only(module):
    """They run on the peer's python3 (as old as Ubuntu 20.04's 3.8), without rosnet-tui (the
    Zenoh program needs eclipse-zenoh: tests/test_peer_install.py runs it on an install)."""
    tree = ast.parse(Path(module.__file__).read_text(), feature_version=(3, 8))
    imported = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            imported |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            imported.add((node.module or "").split(".")[0])
    assert imported <= set(sys.stdlib_module_names) | {"__future__"}, imported


# Each run marks itself in a folder, then waits (bounded) until all have: it ends 7 only when it
# met the others, which runs one after another never do (the first would wait out its bound).
MEET = (b"import os, sys, time\nhere, me, n = sys.argv[1], sys.argv[2], int(sys.argv[3])\n"
        b"open(os.path.join(here, me), 'w').close()\nend = time.monotonic() + 30\n"
        b"while len(os.listdir(here)) < n and time.monotonic() < end:\n    time.sleep(0.01)\n"
        b"print(os.getppid(), me, flush=True)\nsys.exit(7 if len(os.listdir(here)) >= n else 1)\n")


def test_concurrent_runs_are_forked_by_one_agent_each_with_its_own_output_and_status(local,
                                                                                    tmp_path):
    a = local(programs=(("meet", MEET, None),))
    for rid in (1, 2, 3):
        a.send({"run": "meet", "id": rid, "argv": [str(tmp_path), f"run{rid}", "3"]})
    runs = a.until_exits(3)
    for rid in (1, 2, 3):     # the agent is every run's parent: no interpreter of its own
        assert runs[rid] == {"o": f"{a.pid} run{rid}\n", "e": "", "x": 7}   # 7: they met


def test_a_run_of_a_module_gets_its_entry_called_with_argv_and_its_errors_on_stderr(local):
    src = Path(chatproto.__file__).read_bytes()
    a = local(programs=(("chat", src, "main"),))
    a.send({"run": "chat", "id": 1, "argv": ["connect", "localhost", str(free_port()), "0.5"]})
    a.send({"run": "chat", "id": 2, "argv": ["nonsense"]})
    a.send({"run": "nothing-loaded", "id": 3, "argv": []})
    runs = a.until_exits(3)
    assert runs[1]["x"] == 3 and "RESOLVED 127.0.0.1" in runs[1]["o"] and \
        "CONNECT-ERROR" in runs[1]["o"], runs[1]
    assert runs[2]["x"] == 2 and "usage" in runs[2]["o"]
    assert runs[3]["x"] == 2 and "no program 'nothing-loaded' loaded" in runs[3]["e"]


def test_the_end_of_stdin_ends_the_agent_and_its_runs(local):
    a = local()
    a.send({"run": "p", "id": 1, "argv": ["30"]})
    a.line()
    kids = _children(a.pid)
    assert len(kids) == 1
    assert a.proc.stdin is not None
    a.proc.stdin.close()
    assert a.proc.wait(3) == 0
    assert gone_within(kids[0], 2.0)


def test_the_hard_maximum_ends_the_agent_while_stdin_stays_open(local):
    a = local(1)
    a.send({"run": "p", "id": 1, "argv": ["30"]})
    a.line()
    kids = _children(a.pid)
    # its 1 s maximum ends it, not its run's 30 s nor stdin's end (never): the wait's bound only
    # tells 1 s from 30 s, far from both on a loaded machine
    assert a.proc.wait(15) == 0
    assert gone_within(kids[0], 2.0)


def test_a_kill_stops_one_run_and_leaves_the_others(local):
    a = local()
    a.send({"run": "p", "id": 1, "argv": ["30", "long"]})
    a.send({"run": "p", "id": 2, "argv": ["0.5", "short"]})
    a.line()
    a.line()
    a.send({"kill": 1})
    runs = a.until_exits(2)
    assert runs[1]["x"] == 128 + 9 and runs[2]["x"] == 7


def test_without_the_install_a_run_that_needs_it_gets_the_finders_report(local):
    a = local(30, "no-install")
    a.send({"run": "p", "id": 1, "argv": [], "ni": ["REPORT no_install\n", 4]})
    a.send({"run": "p", "id": 2, "argv": []})
    runs = a.until_exits(2)
    assert runs[1] == {"o": "REPORT no_install\n", "e": "", "x": 4}
    assert runs[2]["x"] == 7


def test_ros2_agent_on_a_peer_without_rosnet_tui_runs_on_python3_and_says_no_install(tmp_path):
    """The install finder's fallback: info and the chats run on the peer's python3; a Zenoh probe
    gets the very report a lone command got (no_install, exit status 4)."""
    if any(p.exists() for p in (Path("/usr/local/bin/rosnet-tui"), Path("/opt/pipx/venvs"))):
        pytest.skip("this machine has a root-owned rosnet-tui install")
    home = tmp_path / "home"
    home.mkdir()
    kind = probe_agents.ZENOH_AGENT
    runs = [{"run": "zenoh", "id": 1, "argv": ["info"]},
            {"run": "zenoh", "id": 2, "argv": ["graph", "--timeout", "1"],
             "ni": list(kind.no_install or ())}]
    stdin = (boot_payload(tuple(kind.programs))
             + b"".join(json.dumps(r).encode() + b"\n" for r in runs))
    proc = subprocess.Popen(["/bin/sh", "-c", kind.command(20)], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            env={"HOME": str(home), "PATH": "/usr/bin:/bin", "SHELL": "/bin/sh"},
                            cwd=home)
    assert proc.stdin is not None and proc.stdout is not None
    proc.stdin.write(stdin)          # stdin stays open: its end would end the agent
    proc.stdin.flush()
    out: dict[int, str] = {}
    status: dict[int, int] = {}
    try:
        while len(status) < 2:
            line = proc.stdout.readline().decode()
            assert line, proc.stderr.read() if proc.stderr else ""
            msg = json.loads(line.rpartition("#")[0])
            if "o" in msg:
                out[msg["id"]] = out.get(msg["id"], "") + msg["o"]
            if "x" in msg:
                status[msg["id"]] = msg["x"]
    finally:
        proc.stdin.close()
        assert proc.wait(5) == 0
        proc.stdout.close()
        if proc.stderr is not None:
            proc.stderr.close()
    info = zenohproto.parse_report(out[1])
    assert status[1] == 0 and info is not None and info["python"].endswith("python3"), out
    assert status[2] == commands.NO_INSTALL_EXIT
    assert zenohproto.parse_report(out[2]) == {"error": "no_install",
                                               "detail": "no rosnet-tui installed"}


def _children(pid: int) -> list[int]:
    """The child processes of *pid* (waits a little for the fork)."""
    end = time.monotonic() + 2
    while time.monotonic() < end:
        kids = []
        for d in os.listdir("/proc"):
            if d.isdigit():
                try:
                    with open(f"/proc/{d}/stat") as f:
                        if int(f.read().rsplit(")", 1)[1].split()[1]) == pid:
                            kids.append(int(d))
                except (OSError, ValueError, IndexError):
                    continue
        if kids:
            return kids
        time.sleep(0.02)
    return []


# --------------------------------------------------------------------------- over SSH
KIND = AgentKind("test", lambda m: f"python3 -S -c {commands.shq(agentproto.BOOT)} {m:.0f}",
                 (("p", PPID, None),))


MEET_KIND = AgentKind("meet", KIND.command, (("meet", MEET, None),))


async def test_a_rounds_runs_on_a_peer_share_one_agent_and_end_with_the_round(ssh_client,
                                                                             tmp_path):
    """The four runs are in flight at once over the one session (they meet: exit 7), not sent
    one after another (the first would wait out its bound and end 1, or time out)."""
    opts = ssh_client.opts(timeout_s=3.0, pool=SshPool())
    agents, peer = PeerAgents(), ssh_client.peer()
    here = tmp_path / "meet"
    here.mkdir()
    try:
        got = await asyncio.gather(*(agent_run(agents, opts, peer, MEET_KIND, "meet",
                                               [str(here), str(i), "4"], timeout=20)
                                     for i in range(4)))
        assert all(r.ok and r.exit_status == 7 for r in got), got
        parents = {r.stdout.split()[0] for r in got}
        assert len(parents) == 1 and len(agents.agents) == 1     # one agent served all four
        assert sorted(r.stdout.split()[1] for r in got) == ["0", "1", "2", "3"]
        agent_pid = int(parents.pop())
        assert alive(agent_pid)
    finally:
        agents.close()
        opts.pool.close()
    assert await asyncio.to_thread(gone_within, agent_pid, 3.0)


async def test_a_program_its_kind_does_not_load_is_loaded_by_its_first_run(ssh_client):
    """security.outsider's TLS probe (made per process: its foreign certificate inside) runs on
    the member's agent of the round, not on an interpreter of its own: loaded once, with the
    first run; a changed source is loaded again."""
    opts = ssh_client.opts(timeout_s=3.0, pool=SshPool())
    agents, peer = PeerAgents(), ssh_client.peer()
    src = b"import os, sys\nprint('hello', os.getppid(), *sys.argv[1:])\n"
    try:
        got = await asyncio.gather(*(agent_run(agents, opts, peer, KIND, "extra", [w],
                                               timeout=20, source=src) for w in "ab"))
        assert [r.stdout.split()[::2] for r in got] == [["hello", "a"], ["hello", "b"]], got
        assert len({r.stdout.split()[1] for r in got}) == 1 and len(agents.agents) == 1
        (agent,) = agents.agents.values()
        assert agent.loaded == {"extra": src}
        plain = await agent_run(agents, opts, peer, KIND, "p", ["0"], timeout=20)
        assert plain.exit_status == 7          # the kind's own programs are still there
        new = await agent_run(agents, opts, peer, KIND, "extra", [], timeout=20,
                              source=b"print('changed')\n")
        assert new.ok and new.stdout == "changed\n", new
    finally:
        agents.close()
        opts.pool.close()


async def test_each_run_keeps_its_own_timeout(ssh_client):
    opts = ssh_client.opts(timeout_s=3.0, pool=SshPool())
    agents, peer = PeerAgents(), ssh_client.peer()
    try:
        t0 = time.monotonic()
        slow, quick = await asyncio.gather(
            agent_run(agents, opts, peer, KIND, "p", ["30"], timeout=1.0),
            agent_run(agents, opts, peer, KIND, "p", ["0"], timeout=20.0))
        assert slow.failure == "timeout" and quick.ok and quick.exit_status == 7
        # the slow run ends at its own 1 s, not at the other's 20 s nor its program's 30 s
        # (the bound leaves a loaded machine room for the SSH connection and the agent's start)
        assert time.monotonic() - t0 < 10.0
    finally:
        agents.close()
        opts.pool.close()


async def test_a_slow_start_is_waited_for_as_long_as_its_most_patient_caller_waits(ssh_client):
    """A thin link takes seconds to carry the agent's programs. The round's quick check that
    started the agent gives up at its own bound; the start goes on for ros2.link, which waits
    longer (at 64 kbit/s under load the start used to end at the first caller's bound, and the
    link measurement was skipped: 'did not start in time')."""
    slow = AgentKind("slow", lambda m: f"sleep 5; {KIND.command(m)}", KIND.programs)
    opts = ssh_client.opts(timeout_s=1.0, pool=SshPool())
    agents, peer = PeerAgents(), ssh_client.peer()
    try:
        quick = asyncio.ensure_future(agent_run(agents, opts, peer, slow, "p", ["0"],
                                                timeout=0.5))
        await asyncio.sleep(0.2)            # the quick one starts the agent
        patient = await agent_run(agents, opts, peer, slow, "p", ["0"], timeout=20.0)
        quick_res = await quick
    finally:
        agents.close()
        opts.pool.close()
    assert quick_res.failure == "timeout", quick_res
    assert patient.ok and patient.exit_status == 7, patient


async def test_an_unreachable_peer_gives_the_same_classified_failure_as_a_lone_command(
        ssh_client):
    peer = ssh_client.peer(ssh_port=free_port())           # nothing listens there
    lone = await ssh_run(ssh_client.opts(timeout_s=10.0, pool=SshPool()), peer, "true",
                         timeout=10)
    opts = ssh_client.opts(timeout_s=10.0, pool=SshPool())
    agents = PeerAgents()
    try:
        t0 = time.monotonic()
        res = await agent_run(agents, opts, peer, KIND, "p", [], timeout=10.0)
        assert time.monotonic() - t0 < 5.0      # refused: at once, not after the 10 s timeout
    finally:
        agents.close()
        opts.pool.close()
    assert not res.ok and res.failure == lone.failure and res.tcp == lone.tcp, (res, lone)


async def test_a_peer_without_python3_gives_exit_status_127_to_every_run(ssh_client):
    kind = AgentKind("nopy", lambda m: f"no-such-python3 -S -c {commands.shq(agentproto.BOOT)} "
                                       f"{m:.0f}", (("p", PPID, None),))
    opts = ssh_client.opts(timeout_s=3.0, pool=SshPool())
    agents = PeerAgents()
    try:
        got = await asyncio.gather(*(agent_run(agents, opts, ssh_client.peer(), kind, "p", [],
                                               timeout=5) for _ in range(2)))
    finally:
        agents.close()
        opts.pool.close()
    assert all(r.ok and r.exit_status == 127 and probe_agents.no_python(r) for r in got), got


def test_a_line_that_is_no_request_is_said_and_the_agent_goes_on(local):
    """Garbage, a request nested past the recursion limit, a request of the wrong shape: each is
    answered with an error line, and the next good request still runs."""
    a = local()
    a.send_raw(b"not json at all\n" + b"[" * 100_000 + b"\n")
    a.send(["a list, not a request"])
    errors = [a.line() for _ in range(3)]
    assert all(e["id"] is None and e["e"].startswith("agent: ") for e in errors), errors
    a.send({"run": "p", "id": 9, "argv": ["0", "after"]})
    assert a.until_exits(1)[9]["o"] == f"{a.pid} 0 after\n"


def test_the_agents_start_is_compressed_for_a_thin_link(local):
    """Issue 31 at 64 kbit/s: the ROS 2 agent's start (its source and programs, about 58 kB)
    goes compressed, about 20 kB, so it is ready within a few seconds on such a line; a
    "loadz" frame the agent cannot take is said, and the agent goes on."""
    kind = probe_agents.ZENOH_AGENT
    raw = len(AGENT_SOURCE) + sum(len(p[1]) for p in kind.programs)
    sent = len(boot_payload(tuple(kind.programs)))
    assert raw > 50_000 and sent < 24_000, (raw, sent)
    a = local()                              # its program came in a loadz frame: it runs
    a.send({"run": "p", "id": 1, "argv": []})
    assert a.until_exits(1)[1]["x"] == 7      # PPID ends 7
    a.send({"loadz": 0})
    assert "a loadz frame of 0 bytes" in a.line()["e"]
    a.send({"run": "p", "id": 2, "argv": []})
    assert a.until_exits(1)[2]["x"] == 7


async def test_a_run_waiting_behind_another_senders_write_ends_at_its_own_timeout(ssh_client):
    """At 64 kbit/s a program's source (security.outsider's, some kB) takes seconds to send,
    and every other run's request waits for the channel behind it: ros2.env, which gives its
    peer 0.8 of its time, then overran the round's bound ("no verdict within 3 s"). Another
    sender holding the channel is that write, made as long as wanted."""
    opts = ssh_client.opts(timeout_s=3.0, pool=SshPool())
    agents, peer = PeerAgents(), ssh_client.peer()
    try:
        warm = await agent_run(agents, opts, peer, KIND, "p", ["0"], timeout=20)
        assert warm.exit_status == 7, warm
        (agent,) = agents.agents.values()
        async with agent.send_lock:                 # a long write of another check's
            t0 = time.monotonic()
            r = await asyncio.wait_for(      # bounded here: it waited for the lock for good
                agent_run(agents, opts, peer, KIND, "p", ["0"], timeout=1.0), 10)
            took = time.monotonic() - t0
        assert r.failure == "timeout", r
        assert took < 1.0 + 0.25, took
        assert "in time" in r.detail, r
        after = await agent_run(agents, opts, peer, KIND, "p", ["0"], timeout=20)
        assert after.exit_status == 7, after        # the agent's stream is whole
    finally:
        agents.close()
        opts.pool.close()


async def test_the_agents_start_is_bounded_from_the_call_the_connections_wait_included(
        ssh_client):
    """A run's time covers reaching the peer and its agent's start together: the start's bound
    was counted after the connection's wait, so a slow connection and a slow start could take
    the two of them. The slow connection here is the pool's own, delayed before it connects."""
    class SlowPool(SshPool):
        async def connect(self, *a, **k):
            await asyncio.sleep(0.6)
            return await super().connect(*a, **k)

    slow = AgentKind("slow", lambda m: f"sleep 5; {KIND.command(m)}", KIND.programs)
    opts = ssh_client.opts(timeout_s=1.0, pool=SlowPool())
    agents, peer = PeerAgents(), ssh_client.peer()
    try:
        t0 = time.monotonic()
        r = await asyncio.wait_for(agent_run(agents, opts, peer, slow, "p", ["0"], timeout=1.2),
                                   10)
        took = time.monotonic() - t0
    finally:
        agents.close()
        opts.pool.close()
    assert r.failure == "timeout", r
    assert took < 1.2 + 0.25, took
