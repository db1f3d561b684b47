"""paramiko is loaded without invoke (paramiko.config's runner of ssh_config's ``Match exec``,
as long to import as the rest of paramiko, on the path of every round of checks)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _keygen(path: Path) -> None:
    subprocess.run(["ssh-keygen", "-q", "-t", "ed25519", "-N", "", "-C", path.name, "-f",
                    str(path)], check=True, capture_output=True, timeout=30)


def _load_keys_in_a_new_process(ssh_dir: Path) -> list[str]:
    code = ("import sys\n"
            "from rosnet_tui.core.ssh.connection import load_keys\n"
            "from rosnet_tui.core.ssh.options import SshOptions\n"
            f"keys, notes = load_keys(SshOptions(ssh_dir={str(ssh_dir)!r}, ssh_agent=False))\n"
            "print(len(keys), 'invoke' in sys.modules, sorted(notes))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=60, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip().split(maxsplit=2)


def test_keys_are_read_without_importing_invoke(tmp_path):
    _keygen(tmp_path / "id_ed25519")
    (tmp_path / "config").write_text("Host robot\n    User root\n")
    assert _load_keys_in_a_new_process(tmp_path) == ["1", "False", "[]"]


def test_the_connection_to_a_peer_sends_without_waiting_for_acks(ssh_client):
    """A round's checks send their runs to the peer's agent on one connection, one right after
    another: with Nagle's algorithm on, each waited for the ACK of the one before (sshd delays
    its ACKs up to 40 ms)."""
    import socket
    import time

    from rosnet_tui.core.ssh.connection import Holder, connect_blocking

    conn = connect_blocking(ssh_client.opts(), ssh_client.peer(), time.monotonic() + 10, Holder())
    assert conn.transport is not None, conn.result.detail
    try:
        sock = conn.transport.sock
        assert sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY) == 1
    finally:
        conn.transport.close()


def test_a_match_block_in_ssh_config_does_not_hide_its_identity_files(tmp_path):
    """paramiko's SSHConfig.get_hostnames raises on any Match block: every IdentityFile of such a
    config was silently left out, and a technician whose key is named only there could not log
    in to the peers."""
    _keygen(tmp_path / "fleet_key")
    (tmp_path / "config").write_text(
        "Match host *.lab exec \"true\"\n    User ops\n\n"
        f"Host robot\n    IdentityFile = \"{tmp_path / 'fleet_key'}\"\n"
        "Host *\n    identityfile %d/no_such_key\n")
    assert _load_keys_in_a_new_process(tmp_path) == ["1", "False", "[]"]
