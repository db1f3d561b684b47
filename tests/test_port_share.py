"""The test port's lock and its sharing between runs of rosnet-tui (core/net/portshare.py, the
pool in core/net/listener.py), on loopback with real processes: a SIGKILLed holder frees the
lock, another user's run shares it too, a run that shares keeps the listener up for the others,
a peer's chat holds the port for a moment (BUSY) and a stranger squatting the lock cannot block
a check beyond its wait."""

from __future__ import annotations

import asyncio
import os
import pwd
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from rosnet_tui.core.checks import REGISTRY, CheckContext, load_builtin_checks, run_check
from rosnet_tui.core.checks.probes.listening import services_listening
from rosnet_tui.core.config.paths import Paths
from rosnet_tui.core.config.settings_model import ProbeSettings, Settings, ThisComponent
from rosnet_tui.core.net import portshare
from rosnet_tui.core.net.listener import (
    GREETING,
    ListenerPool,
    PortHeld,
    SharedListener,
    TestListener,
)
from rosnet_tui.core.peer import chatproto
from rosnet_tui.core.results import Status
from tests.builders import free_port

HOLDER = ("import socket, sys, time\n"
          "s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)\n"
          "s.bind('\\0rosnet-tui/test-port/' + sys.argv[1]); s.listen(4)\n"
          "print('HELD', flush=True); time.sleep(60)\n")


SYSTEM_PYTHON = Path("/usr/bin/python3")     # one that another user may run (ours may not)


def holder(port: int, user: str | None = None) -> subprocess.Popen:
    """A process holding *port*'s lock (as *user*), once it said so."""
    python = sys.executable if user is None else str(SYSTEM_PYTHON)
    proc = subprocess.Popen([python, "-S", "-c", HOLDER, str(port)], user=user,
                            stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None and proc.stdout.readline().strip() == "HELD"
    return proc


def lock_free(port: int) -> bool:
    s = portshare.take_lock(port)
    if s is None:
        return False
    s.close()
    return True


def greeting(port: int) -> str:
    with socket.create_connection(("127.0.0.1", port), timeout=2) as c:
        c.settimeout(2)
        return c.recv(200).decode()


def chat_line(port: int, text: str) -> None:
    with socket.create_connection(("127.0.0.1", port), timeout=2) as c:
        c.settimeout(2)
        c.recv(200)
        c.sendall(text.encode() + b"\n")
        c.recv(200)


@pytest.mark.parametrize("user", [None, "nobody"])
def test_sigkill_of_the_holder_frees_the_lock(user):
    if user is not None:
        if os.geteuid() != 0:
            pytest.skip("needs root to run the holder as another user")
        try:
            pwd.getpwnam(user)
        except KeyError:
            pytest.skip(f"no user {user}")
        if not SYSTEM_PYTHON.exists():
            pytest.skip(f"no {SYSTEM_PYTHON} for {user} to run")
    port = free_port()
    proc = holder(port, user)
    try:
        assert not lock_free(port)          # held by another process (another user's too)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=5)
        assert lock_free(port)              # nothing stale: the kernel dropped it
    finally:
        proc.kill()
        proc.wait(timeout=5)
        if proc.stdout:
            proc.stdout.close()


def test_a_second_run_shares_the_listener_and_hears_what_it_saw():
    port = free_port()

    async def go() -> None:
        first, second = ListenerPool(), ListenerPool()
        async with first.hold(port) as mine:
            assert isinstance(mine, TestListener)
            async with second.hold(port) as shared:
                assert isinstance(shared, SharedListener) and shared.pid == os.getpid()
                assert shared.token == first.token and "shared with another check run" in shared.note
                got = await asyncio.to_thread(greeting, port)
                assert got.startswith(f"{GREETING} {first.token} {port}")
                await asyncio.to_thread(chat_line, port, "ROSNET-TUI CHAT hi abc123")
                seen = await shared.wait_for_line("abc123", 2.0)     # told by the first run
                assert seen is not None and seen.address == "127.0.0.1"
            assert not second.holds(port) and first.holds(port)
        await asyncio.wait_for(first.aclose(), 5)        # the end of the first run's round
        assert lock_free(port) and not first.holds(port)

    asyncio.run(go())


def test_the_owner_lingers_after_its_own_holds_end():
    port = free_port()

    async def go() -> None:
        first, second = ListenerPool(), ListenerPool()
        cm = first.hold(port)
        await cm.__aenter__()
        async with second.hold(port) as shared:
            await cm.__aexit__(None, None, None)   # the first run's checks are done
            closing = asyncio.ensure_future(first.aclose())     # the first run ends...
            await asyncio.sleep(0.3)
            assert not closing.done() and shared.listening     # ...after the second
            assert first.holds(port)
            assert (await asyncio.to_thread(greeting, port)).startswith(GREETING)
        # it ends as soon as the second left: the bound is far below the linger's maximum
        # (listener.LINGER_MAX_S, 30 s), which a loaded machine never comes near
        await asyncio.wait_for(closing, 15)
        await first.aclose()
        assert not first.holds(port) and lock_free(port)

    asyncio.run(go())


def test_a_stranger_squatting_the_lock_blocks_a_check_only_for_its_wait():
    port = free_port()
    proc = holder(port)          # holds the name, never answers
    try:
        async def go() -> float:
            t0 = time.monotonic()
            async with ListenerPool().hold(port, wait_s=2.0) as lst:
                assert isinstance(lst, TestListener)   # the port itself was free: ours
                return time.monotonic() - t0

        took = asyncio.run(go())
        # its wait (2 s), not the stranger's life (60 s): the upper bound is far from both
        assert 1.9 < took < 15
    finally:
        proc.kill()
        proc.wait(timeout=5)
        if proc.stdout:
            proc.stdout.close()


def peer_chat(port: int, wait: float) -> subprocess.Popen:
    """The peer side of another machine's linux.chat_out, listening here (as python3 -S)."""
    proc = subprocess.Popen([sys.executable, "-S", str(Path(chatproto.__file__)), "listen",
                             str(port), "tok", str(wait)], stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    assert proc.stdout.readline().strip().startswith("LISTENING")
    return proc


def test_a_peers_chat_holds_the_port_a_moment_and_a_check_waits_for_it():
    port = free_port()
    proc = peer_chat(port, 0.8)
    try:
        async def go() -> tuple[float, str]:
            t0 = time.monotonic()
            async with ListenerPool().hold(port, wait_s=30) as lst:
                return time.monotonic() - t0, lst.note

        took, note = asyncio.run(go())
        # it waited (the note says so) until the chat's 0.8 s were over, not its own 30 s
        assert "another check run had the test port" in note and "waited" in note
        assert took < 15
    finally:
        proc.kill()
        proc.wait(timeout=5)
        if proc.stdout:
            proc.stdout.close()


def test_a_peers_chat_held_longer_than_the_wait_is_said_plainly():
    port = free_port()
    proc = peer_chat(port, 20)
    try:
        async def go() -> None:
            with pytest.raises(PortHeld) as err:
                async with ListenerPool().hold(port, wait_s=0.3):
                    pass
            assert err.value.pid == proc.pid and "another run of rosnet-tui" in str(err.value)

        asyncio.run(go())
    finally:
        proc.kill()
        proc.wait(timeout=5)
        if proc.stdout:
            proc.stdout.close()


def test_a_peers_chat_takes_a_random_port_while_a_run_here_holds_the_test_port():
    port = free_port()

    async def go() -> str:
        async with ListenerPool().hold(port):
            proc = await asyncio.to_thread(subprocess.run, [
                sys.executable, "-S", str(Path(chatproto.__file__)), "listen", str(port), "tok",
                "0.1"], capture_output=True, text=True, timeout=10)
            return proc.stdout

    out = asyncio.run(go())
    listening = int(out.split("LISTENING ")[1].split()[0])
    assert listening != port and "TIMEOUT" in out


OWNER = ("import asyncio, sys\n"
         "from rosnet_tui.core.net.listener import ListenerPool\n"
         "async def main():\n"
         "    pool = ListenerPool()\n"
         "    async with pool.hold(int(sys.argv[1])):\n"
         "        print('READY', pool.token, flush=True)\n"
         "        await asyncio.sleep(60)\n"
         "asyncio.run(main())\n")


def test_when_the_run_that_shares_is_killed_the_other_takes_the_port_over():
    port = free_port()
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    owner = subprocess.Popen([sys.executable, "-c", OWNER, str(port)], stdout=subprocess.PIPE,
                             text=True, env=env)
    try:
        assert owner.stdout is not None
        ready = owner.stdout.readline().split()
        assert ready[:1] == ["READY"]

        async def go() -> None:
            async with ListenerPool().hold(port) as lst:
                assert isinstance(lst, SharedListener) and lst.token == ready[1]
                assert lst.pid == owner.pid
                owner.send_signal(signal.SIGKILL)
                await asyncio.to_thread(owner.wait, 5)
                for _ in range(100):                  # bounded: 2 s
                    if lst.sharing is not None:
                        break
                    await asyncio.sleep(0.02)
                assert lst.listening and lst.sharing is not None     # ours now, same token
                got = await asyncio.to_thread(greeting, port)
                assert got.startswith(f"{GREETING} {ready[1]} {port}")
                await asyncio.to_thread(chat_line, port, "ROSNET-TUI CHAT after abc")
                assert await lst.wait_for_line("after abc", 2.0) is not None
            assert lock_free(port)

        asyncio.run(go())
    finally:
        owner.kill()
        owner.wait(timeout=5)
        if owner.stdout:
            owner.stdout.close()


def test_a_listener_of_another_run_is_told_from_a_service_of_the_users():
    port = free_port()

    async def go() -> None:
        first, second = ListenerPool(), ListenerPool()
        assert not second.rosnet_listens(port)
        async with first.hold(port):
            assert first.rosnet_listens(port) and second.rosnet_listens(port)
        await first.aclose()
        assert not second.rosnet_listens(port)

    asyncio.run(go())


def test_services_listening_tells_a_users_service_from_rosnet_tuis_listeners():
    """What the checks ask before they stand in for a service: a plain listener is somebody's
    service (loopback left out when only reachable ones count); our own listener and another
    run's are none."""
    port = free_port()

    async def go() -> None:
        ours, other = ListenerPool(), ListenerPool()
        with socket.socket() as service:
            service.bind(("127.0.0.1", port))
            service.listen(1)
            assert services_listening(port, ours) == ["127.0.0.1"]
            assert services_listening(port, ours, reachable=True) == []
        async with other.hold(port):
            assert services_listening(port) == ["0.0.0.0"]     # without the pool: a listener
            assert services_listening(port, ours) == []        # another run's
            async with ours.hold(port):
                assert services_listening(port, ours) == []    # ours (shared)
        await other.aclose()

    asyncio.run(go())


def test_the_pool_has_its_listener_until_it_is_closed(monkeypatch):
    """Released, the listener is closed first and forgotten after: while it still listens the
    pool says it has the port (it used to forget it first, so a check looking at the port in
    between took our listener for a service of the user's)."""
    port = free_port()
    pool = ListenerPool()
    while_closing: list[bool] = []
    real_close = TestListener.close

    async def close(self: TestListener) -> None:
        while_closing.append(pool.holds(port))
        await real_close(self)

    monkeypatch.setattr(TestListener, "close", close)

    async def go() -> None:
        async with pool.hold(port):
            pass
        assert not pool.holds(port)

    asyncio.run(go())
    assert while_closing == [True]


def test_router_port_free_says_plainly_when_another_run_keeps_the_port(tmp_path):
    load_builtin_checks()
    port = free_port()
    ctx = CheckContext(settings=Settings(this=ThisComponent(name="turtlebot"),
                                         probe=ProbeSettings(port=port)),
                       timeout_s=1.0, upnp=False, paths=Paths(state_dir=tmp_path))
    proc = peer_chat(port, 20)                 # a peer's chat here, for longer than we wait
    try:
        r = asyncio.run(run_check(REGISTRY["router.port_free"], ctx))
    finally:
        proc.kill()
        proc.wait(timeout=5)
        if proc.stdout:
            proc.stdout.close()
    assert r.status == Status.WARN, r
    assert "another check run of rosnet-tui" in r.summary and r.duration_s <= r.timeout_s + 0.5
    assert r.data["pid"] == proc.pid and r.data["in_use"] is True
    r = asyncio.run(run_check(REGISTRY["router.port_free"], ctx))     # it ended: free again
    assert r.status == Status.PASS, r
