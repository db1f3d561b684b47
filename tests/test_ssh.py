"""The SSH layer against a real sshd on 127.0.0.1 with throwaway keys (started per module; the
``sshd`` and ``ssh_client`` fixtures are in tests/plugins/ssh.py)."""

from __future__ import annotations

import asyncio
import os
import shutil
import socket
import threading
import time

import pytest

from rosnet_tui.core.net.blocking import run_blocking
from rosnet_tui.core.ssh.connection import SshResult
from rosnet_tui.core.ssh.known_hosts import trust_host_key
from rosnet_tui.core.ssh.session import ssh_run, ssh_session
from tests.builders import free_port
from tests.plugins.ssh import SSHD, keygen

pytestmark = pytest.mark.skipif(not os.path.exists(SSHD) or not shutil.which("ssh-keygen"),
                                reason="needs OpenSSH (sshd, ssh-keygen)")


# --------------------------------------------------------------------------- tests
async def test_runs_a_command_with_exit_status_and_both_streams(ssh_client, sshd):
    res = await ssh_run(ssh_client.opts(), ssh_client.peer(), "echo hi; echo oops >&2; exit 3",
                        timeout=10)
    assert res.ok and res.failure is None
    assert res.exit_status == 3
    assert res.stdout == "hi\n" and res.stderr == "oops\n"
    assert res.fingerprint == sshd.fingerprint
    assert res.address == "127.0.0.1"


async def test_stdin_reaches_the_command(ssh_client):
    res = await ssh_run(ssh_client.opts(), ssh_client.peer(), "cat", stdin=b"through ssh\n",
                        timeout=10)
    assert res.ok and res.exit_status == 0 and res.stdout == "through ssh\n"


async def test_unknown_host_key_stops_before_login_and_can_then_be_trusted(ssh_client, sshd):
    (ssh_client.dir / "known_hosts").write_text("")
    before = sshd.log.read_text()
    res = await ssh_run(ssh_client.opts(), ssh_client.peer(), "echo should-not-run", timeout=10)
    assert not res.ok and res.failure == "host_key_unknown"
    assert res.fingerprint == sshd.fingerprint and sshd.fingerprint in res.detail
    assert "ssh-keyscan" in res.detail and "ssh-keygen -lf" in res.detail
    assert "publickey" not in sshd.log_until_ended(before)  # no login was even tried
    path = trust_host_key(ssh_client.opts(), "localhost", sshd.port, res.host_key)
    assert path == ssh_client.dir / "known_hosts"
    again = await ssh_run(ssh_client.opts(), ssh_client.peer(), "echo now-ok", timeout=10)
    assert again.ok and again.stdout == "now-ok\n"
    with pytest.raises(ValueError):
        trust_host_key(ssh_client.opts(), "localhost", sshd.port, res.host_key)


async def test_changed_host_key_is_refused(ssh_client, sshd, tmp_path):
    other = keygen(tmp_path / "impostor").rsplit(" ", 1)[0]
    (ssh_client.dir / "known_hosts").write_text(f"[localhost]:{sshd.port} {other}\n")
    before = sshd.log.read_text()
    res = await ssh_run(ssh_client.opts(), ssh_client.peer(), "echo no", timeout=10)
    assert not res.ok and res.failure == "host_key_changed"
    assert res.fingerprint == sshd.fingerprint and "CHANGED" in res.detail
    assert "ssh-keygen -R" in res.detail
    assert "publickey" not in sshd.log_until_ended(before)


async def test_known_key_of_another_type_counts_as_changed(ssh_client, sshd, tmp_path):
    other = keygen(tmp_path / "ecdsa", "ecdsa").rsplit(" ", 1)[0]
    (ssh_client.dir / "known_hosts").write_text(f"[localhost]:{sshd.port} {other}\n")
    res = await ssh_run(ssh_client.opts(), ssh_client.peer(), "true", timeout=10)
    assert res.failure == "host_key_changed"


async def test_a_refused_key_is_an_auth_failure(ssh_client, sshd):
    sshd.authorized.write_text("")
    res = await ssh_run(ssh_client.opts(), ssh_client.peer(), "true", timeout=10)
    assert not res.ok and res.failure == "auth"
    assert "ssh-copy-id" in res.detail and res.fingerprint == sshd.fingerprint


async def test_no_key_at_all_is_an_auth_failure(ssh_client, sshd):
    (ssh_client.dir / "id_ed25519").unlink()
    res = await ssh_run(ssh_client.opts(), ssh_client.peer(), "true", timeout=10)
    assert res.failure == "auth" and "ssh-keygen" in res.detail


async def test_nothing_listening_is_a_network_failure(ssh_client):
    res = await ssh_run(ssh_client.opts(), ssh_client.peer(ssh_port=free_port()), "true", timeout=5)
    assert not res.ok and res.failure == "network" and "refused" in res.detail


async def test_no_user_is_reported_without_connecting(ssh_client):
    res = await ssh_run(ssh_client.opts(), ssh_client.peer(ssh_user=""), "true", timeout=5)
    assert res.failure == "no_user"


class _FakeServer:
    """A TCP server on loopback that answers with *greeting* (or nothing) and never speaks SSH."""

    def __init__(self, greeting: bytes | None) -> None:
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(8)
        self.port = self.sock.getsockname()[1]
        self.greeting = greeting
        self.closed_by_client = threading.Event()
        self.conns: list[socket.socket] = []
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        while True:
            try:
                c, _ = self.sock.accept()
            except OSError:
                return
            self.conns.append(c)
            if self.greeting is not None:
                c.sendall(self.greeting)
                c.close()
            else:
                threading.Thread(target=self._wait_eof, args=(c,), daemon=True).start()

    def _wait_eof(self, c: socket.socket) -> None:
        c.settimeout(10)
        try:
            while c.recv(1024):
                pass
        except OSError:
            pass
        self.closed_by_client.set()

    def close(self) -> None:
        self.sock.close()
        for c in self.conns:
            c.close()


async def test_a_service_that_is_not_sshd_is_an_sshd_failure(ssh_client):
    srv = _FakeServer(b"HTTP/1.1 400 Bad Request\r\n\r\n")
    try:
        res = await ssh_run(ssh_client.opts(), ssh_client.peer(ssh_port=srv.port), "true", timeout=3)
    finally:
        srv.close()
    assert not res.ok and res.failure == "sshd"


async def test_a_silent_server_gives_a_verdict_within_the_timeout(ssh_client):
    srv = _FakeServer(None)
    try:
        t0 = time.monotonic()
        res = await ssh_run(ssh_client.opts(), ssh_client.peer(ssh_port=srv.port), "true", timeout=1.0)
        took = time.monotonic() - t0
    finally:
        srv.close()
    assert not res.ok and res.failure in ("sshd", "timeout")
    assert took < 2.5


async def test_cancelling_closes_the_connection_at_once(ssh_client):
    srv = _FakeServer(None)
    try:
        with pytest.raises(asyncio.TimeoutError):
            await asyncio.wait_for(ssh_run(ssh_client.opts(), ssh_client.peer(ssh_port=srv.port),
                                           "true", timeout=30), 0.5)
        assert await run_blocking(srv.closed_by_client.wait, 3.0, timeout=4)
    finally:
        srv.close()


async def test_a_command_that_runs_too_long_times_out(ssh_client):
    t0 = time.monotonic()
    res = await ssh_run(ssh_client.opts(), ssh_client.peer(), "echo started; sleep 60",
                        timeout=1.5)
    assert res.failure == "timeout" and not res.ok
    assert res.stdout == "started\n"
    # ended at its 1.5 s, not the command's 60 s (a loaded machine stays far below the bound)
    assert time.monotonic() - t0 < 20


async def test_a_session_keeps_the_remote_side_running_while_we_act(ssh_client):
    async with ssh_session(ssh_client.opts(), ssh_client.peer(),
                           "echo READY; read line; echo \"peer got $line\"", timeout=10) as s:
        assert s.ok
        out = await s.read_until("READY", 5)
        assert out is not None and out.startswith("READY")
        assert await s.write("hello from here\n")
        res = await s.wait(5)
    assert isinstance(res, SshResult) and res.ok and res.exit_status == 0
    assert "peer got hello from here" in res.stdout


async def test_a_failed_session_says_why_and_is_inert(ssh_client):
    async with ssh_session(ssh_client.opts(), ssh_client.peer(ssh_port=free_port()), "true",
                           timeout=3) as s:
        assert not s.ok and s.result.failure == "network"
        assert await s.read_until("x", 0.1) is None
        assert not await s.write("x")
        assert (await s.wait(0.1)).failure == "network"
