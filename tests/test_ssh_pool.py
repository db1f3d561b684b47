"""One SSH connection per peer per round (core/ssh/pool.py), against a real sshd on loopback."""

from __future__ import annotations

import asyncio
import dataclasses
import socket
import time

import pytest

from rosnet_tui.core.ssh.pool import SshPool
from rosnet_tui.core.ssh.session import ssh_run, ssh_session
from tests.builders import free_port
from tests.plugins.ssh import Sshd


def logins(d: Sshd) -> int:
    return d.log.read_text().count("Accepted publickey") if d.log.exists() else 0


@pytest.fixture
def silent_port():
    """A port whose connections the kernel accepts and nothing ever answers (no SSH banner)."""
    with socket.socket() as silent:
        silent.bind(("127.0.0.1", 0))
        silent.listen(8)
        yield silent.getsockname()[1]


def pooled(client, pool: SshPool, **kw):
    return dataclasses.replace(client.opts(**kw), pool=pool)


async def test_concurrent_sessions_share_one_login(ssh_client, sshd):
    pool = SshPool()
    before = logins(sshd)
    opts = pooled(ssh_client, pool)
    try:
        got = await asyncio.gather(*(ssh_run(opts, ssh_client.peer(), f"echo {i}", timeout=10)
                                     for i in range(5)))
    finally:
        pool.close()
    assert [r.stdout.strip() for r in got] == [str(i) for i in range(5)]
    assert all(r.ok and r.tcp == "connected" for r in got)
    deadline = time.monotonic() + 5
    while logins(sshd) < before + 1 and time.monotonic() < deadline:
        await asyncio.sleep(0.05)
    assert logins(sshd) == before + 1


async def test_prestarted_connection_is_used_by_the_round(ssh_client, sshd):
    pool = SshPool()
    before = logins(sshd)
    opts = pooled(ssh_client, pool)
    pool.prestart(opts, [ssh_client.peer()])
    try:
        a, b = await asyncio.gather(ssh_run(opts, ssh_client.peer(), "echo a", timeout=10),
                                    ssh_run(opts, ssh_client.peer(), "echo b", timeout=10))
    finally:
        pool.close()
    assert a.ok and b.ok
    deadline = time.monotonic() + 5      # sshd's log of the login may come a moment late
    while logins(sshd) < before + 1 and time.monotonic() < deadline:
        await asyncio.sleep(0.05)
    assert logins(sshd) == before + 1


async def test_sessions_beyond_maxsessions_get_their_own_connection(ssh_client, tmp_path):
    d = Sshd(tmp_path / "sshd2")
    d.config.write_text(d.config.read_text() + "MaxSessions 2\n")
    d.authorized.write_text(ssh_client.pub + "\n")
    d.start()
    try:
        client = dataclasses.replace(ssh_client, sshd=d)
        client.trust()
        pool = SshPool()
        opts = pooled(client, pool)
        try:
            got = await asyncio.gather(*(ssh_run(opts, client.peer(), f"sleep 0.5; echo {i}",
                                                 timeout=10) for i in range(5)))
        finally:
            pool.close()
        assert [r.stdout.strip() for r in got] == [str(i) for i in range(5)], got
    finally:
        d.stop()


async def test_a_refusing_peer_is_one_shared_verdict(ssh_client):
    pool = SshPool()
    opts = pooled(ssh_client, pool, timeout_s=10.0)
    peer = ssh_client.peer(ssh_port=free_port())          # nothing listens there
    t0 = time.monotonic()
    try:
        got = await asyncio.gather(*(ssh_run(opts, peer, "true", timeout=20) for _ in range(4)))
    finally:
        pool.close()
    assert time.monotonic() - t0 < 5.0      # at once: not after the (long) timeout
    assert all(r.failure == "network" and r.tcp == "refused" for r in got)
    assert all("it may listen on another port" in r.detail for r in got)


async def test_a_peer_that_answered_may_use_the_longer_budget(ssh_client, silent_port):
    """The TCP connection is made (the kernel accepts), but no SSH banner ever comes: the caller
    waits past its TCP bound, up to its own timeout, and the verdict says it connected."""
    peer = ssh_client.peer(ssh_port=silent_port)
    pool = SshPool()
    opts = pooled(ssh_client, pool, timeout_s=0.3)
    t0 = time.monotonic()
    try:
        r = await ssh_run(opts, peer, "true", timeout=1.5, tcp_timeout=0.3)
    finally:
        pool.close()
    took = time.monotonic() - t0
    assert not r.ok and r.tcp == "connected", r
    assert 0.5 < took < 1.5 + 0.25, took  # one wait (bench row 3 times it), and no longer


def test_close_ends_the_connections_and_later_sessions_still_work(ssh_client):
    async def go():
        pool = SshPool()
        opts = pooled(ssh_client, pool)
        r = await ssh_run(opts, ssh_client.peer(), "echo one", timeout=10)
        fut = pool.start(opts, ssh_client.peer())
        transport = fut.result().transport
        pool.close()
        assert not transport.is_active()
        again = await ssh_run(opts, ssh_client.peer(), "echo two", timeout=10)
        return r, again

    r, again = asyncio.run(go())
    assert r.stdout.strip() == "one" and again.stdout.strip() == "two"


@pytest.mark.parametrize("steps, started", [(None, True), (["isp"], False), (["ros"], True)])
def test_prestart_ssh_only_when_the_steps_use_the_peers(ssh_client, steps, started):
    from rosnet_tui.core.checks.runner import RunOptions, prestart_ssh
    from tests.builders import settings_with

    s = settings_with(ssh_client.peer())
    o = prestart_ssh(s, RunOptions(ssh=ssh_client.opts(), timeout_s=2.0), steps)
    assert (o.ssh_pool is not None) == started
    if o.ssh_pool is not None:
        fut = o.ssh_pool.start(ssh_client.opts(timeout_s=2.0), ssh_client.peer())
        assert fut.result(timeout=10).result.ok
        o.ssh_pool.close()


async def test_per_peer_work_runs_concurrently_bounded_and_in_order(ssh_client, sshd):
    """each_peer: every peer at once up to the bound, results in the peers' order; real SSH
    sessions on one shared connection per peer."""
    from rosnet_tui.core.checks.probes.peers import each_peer
    from rosnet_tui.core.config.settings_model import Peer

    running = peak = 0

    async def work(p: Peer) -> str:
        nonlocal running, peak
        running += 1
        peak = max(peak, running)
        await asyncio.sleep(0.1)
        running -= 1
        return p.name

    peers = [Peer(f"member{i}") for i in range(12)]
    got = await each_peer(peers, work, limit=8)
    assert got == [p.name for p in peers] and peak == 8   # 8 at once: concurrent, and bounded
    pool = SshPool()
    opts = pooled(ssh_client, pool)
    try:
        res = await each_peer([ssh_client.peer()] * 3,
                              lambda p: ssh_run(opts, p, "echo hi", timeout=10))
    finally:
        pool.close()
    assert [r.stdout for r in res] == ["hi\n"] * 3


async def test_a_command_killed_by_a_signal_is_not_reported_as_exit_status_minus_one(ssh_client):
    # sshd sends exit-signal, not exit-status, for a command a signal ended: paramiko then
    # leaves its placeholder -1, which used to read as "ran, exit status -1".
    res = await ssh_run(ssh_client.opts(), ssh_client.peer(), "echo started; kill -9 $$",
                        timeout=10)
    assert res.exit_status is None and not res.ok and res.failure == "sshd"
    assert "without an exit status" in res.detail, res.detail
    assert res.stdout == "started\n"


async def test_a_round_connection_that_breaks_midway_is_made_again_for_a_probe(ssh_client, sshd):
    # The pooled connection dies while a command runs (a mobile link dropping, sshd's process
    # for it killed): the probe runs once more on a new connection within its time.
    pool = SshPool()
    opts = pooled(ssh_client, pool)
    peer = ssh_client.peer()
    try:
        first = await ssh_run(opts, peer, "echo warm", timeout=10)
        assert first.ok
        conn = pool.start(opts, peer).result(5)

        async def break_it() -> None:
            await asyncio.sleep(0.3)
            conn.transport.sock.shutdown(socket.SHUT_RDWR)   # the link dies under paramiko

        breaker = asyncio.ensure_future(break_it())
        res = await ssh_run(opts, peer, "sleep 0.6; echo done", timeout=6)
        await breaker
    finally:
        pool.close()
    assert res.ok and res.exit_status == 0 and res.stdout == "done\n", res
    assert "again" in res.detail, res.detail


async def test_writing_to_a_session_whose_connection_broke_says_so_without_raising(ssh_client):
    # paramiko raises EOFError (not an OSError) for a send on a transport whose socket died: it
    # used to escape the session and end a check with "failed unexpectedly: EOFError".
    pool = SshPool()
    opts = pooled(ssh_client, pool)
    try:
        async with ssh_session(opts, ssh_client.peer(), "cat >/dev/null; sleep 5",
                               timeout=5) as s:
            assert s.ok and await s.write(b"first")
            conn = pool.start(opts, ssh_client.peer()).result(5)
            conn.transport.sock.shutdown(socket.SHUT_WR)   # our side can send no more
            assert await s.write(b"x" * 100_000) is False
            res = await s.wait(2)
    finally:
        pool.close()
    assert not res.ok and res.exit_status is None and "broke" in res.detail, res


async def test_a_caller_waits_no_longer_than_its_own_timeout_for_a_longer_attempt(ssh_client,
                                                                                 silent_port):
    """The round's connection, started with the round's longer bound, is still in its SSH
    handshake (the peer answered, no banner yet): a check that gives it less time hears its
    verdict at its own timeout. It waited 0.5 s more, and ros2.env, which gives its peer 0.8 of
    its time, overran the round's bound at 64 kbit/s ("no verdict within 3 s")."""
    peer = ssh_client.peer(ssh_port=silent_port)
    pool = SshPool()
    opts = pooled(ssh_client, pool, timeout_s=0.3)
    try:
        pool.start(opts, peer, 6.0)                 # the round's attempt, patient
        t0 = time.monotonic()
        r = await ssh_run(opts, peer, "true", timeout=1.2, tcp_timeout=0.3)
        took = time.monotonic() - t0
    finally:
        pool.close()
    assert not r.ok and r.tcp == "connected", r
    assert 1.0 < took < 1.2 + 0.25, took
