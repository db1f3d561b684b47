"""The SSH audit's `none` authentication (core/peer/sshnone.py, issue 32, on cryptography's
primitives), the audit program against a real sshd on loopback: the methods read without
paramiko where sshd offers curve25519 and chacha20-poly1305 (OpenSSH's defaults), with paramiko
where it offers neither, and the same methods either way."""

from __future__ import annotations

import getpass
import subprocess
import sys
import time

import pytest

from rosnet_tui.core.exposure import outsider
from tests.plugins.ssh import Sshd


def audit(port: int, *users: str) -> tuple[dict, float]:
    t0 = time.monotonic()
    r = subprocess.run([sys.executable, "-", "127.0.0.1", str(port), "3", *users],
                       input=outsider.SSH_AUDIT_PROGRAM, capture_output=True, text=True,
                       timeout=30)
    took = time.monotonic() - t0
    rep = outsider.parse_marked(r.stdout, outsider.SSH_MARK)
    assert rep is not None, r.stdout + r.stderr
    return rep, took


@pytest.fixture
def sshd_of(tmp_path):
    started: list[Sshd] = []

    def make(name: str, **replace: str) -> Sshd:
        d = Sshd(tmp_path / name)
        text = d.config.read_text()
        for old, new in replace.items():
            text = text.replace(old, new)
        d.config.write_text(text)
        d.start()
        started.append(d)
        return d
    yield make
    for d in started:
        d.stop()


def test_the_audit_reads_the_methods_without_paramiko_and_a_password_too(sshd_of):
    user = getpass.getuser()
    keys = sshd_of("keys")
    rep, took = audit(keys.port, user, "root")
    print(f"the audit (sshnone) took {took:.2f} s")
    assert rep["tcp"] == "connected" and rep["banner"].startswith("SSH-2.0-OpenSSH"), rep
    for u in (user, "root"):
        assert rep["users"][u] == {"methods": ["publickey"], "via": "sshnone"}, rep
    pw = sshd_of("password", **{"PasswordAuthentication no": "PasswordAuthentication yes"})
    rep, _ = audit(pw.port, user)
    assert rep["users"][user]["via"] == "sshnone", rep
    assert set(rep["users"][user]["methods"]) == {"publickey", "password"}, rep
    assert outsider.read_ssh_audit(rep, user).password


def test_a_server_without_chacha20_is_asked_with_paramiko_and_says_the_same(sshd_of):
    user = getpass.getuser()
    aes = sshd_of("aes", **{"MaxStartups 50\n": "MaxStartups 50\nCiphers aes128-ctr\n"})
    rep, _ = audit(aes.port, user)
    assert rep["users"][user] == {"methods": ["publickey"], "via": "paramiko"}, rep
    assert rep["banner"].startswith("SSH-2.0-OpenSSH"), rep


def test_nothing_listening_is_told_as_refused(sshd_of):
    from tests.builders import free_port

    rep, _ = audit(free_port(), getpass.getuser(), "root")
    assert rep["tcp"] == "refused" and not rep["users"], rep


def test_the_audit_s_messages_go_out_without_waiting_for_acks(sshd_of):
    """NEWKEYS and the service request go out back to back: with Nagle's algorithm on, the
    second waited for sshd's delayed ACK (40 ms on Linux, the audit's handshake doubled)."""
    import socket

    from rosnet_tui.core.peer import sshnone

    d = sshd_of("nodelay")
    sock = socket.create_connection(("127.0.0.1", d.port), timeout=5)
    try:
        methods, banner = sshnone.none_methods(sock, getpass.getuser())
        assert methods == ["publickey"] and banner.startswith("SSH-2.0-OpenSSH")
        assert sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY) == 1
    finally:
        sock.close()
