"""Fixtures (a pytest plugin, loaded by tests/conftest.py): a real sshd on 127.0.0.1 with
throwaway keys, and our side of it.

``sshd`` is started once per test module that asks for it; ``ssh_client`` is a fresh ~/.ssh-like
folder whose key the sshd accepts and whose known_hosts trusts it.
"""

from __future__ import annotations

import getpass
import os
import re
import shutil
import socket
import subprocess
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from rosnet_tui.core.checks import CheckContext
from rosnet_tui.core.config.settings_model import Peer, Settings
from rosnet_tui.core.ssh.known_hosts import host_key_name
from rosnet_tui.core.ssh.options import SshOptions
from tests.builders import free_port
from tests.lab import procs

SSHD = shutil.which("sshd") or "/usr/sbin/sshd"
# sshd (LogLevel VERBOSE) ends a connection's lines with one of these
CONNECTION_ENDED = re.compile(
    r"^(Connection (reset|closed) by|Disconnected from|Received disconnect from) ", re.M)
def keygen(path: Path, kind: str = "ed25519") -> str:
    """Make a key pair at *path*; return the public key line."""
    subprocess.run(["ssh-keygen", "-q", "-t", kind, "-N", "", "-C", "rosnet-test", "-f", str(path)],
                   check=True, capture_output=True, timeout=30)
    return Path(f"{path}.pub").read_text().strip()


def fingerprint(pub: Path) -> str:
    out = subprocess.run(["ssh-keygen", "-lf", str(pub)], check=True, capture_output=True,
                         text=True, timeout=10).stdout
    return out.split()[1]


class Sshd:
    """A real sshd on 127.0.0.1:PORT with its own host key and authorized_keys (nothing else)."""

    def __init__(self, root: Path, extra_config: str = "", wrap: tuple[str, ...] = ()) -> None:
        self.root = root
        self.wrap = wrap        # a command sshd runs under (``exec "$@"`` at its end), if any
        root.mkdir(parents=True, exist_ok=True)
        self.port = free_port()
        self.host_key = root / "host_ed25519"
        self.host_pub = keygen(self.host_key)
        self.authorized = root / "authorized_keys"
        self.authorized.write_text("")
        self.log = root / "sshd.log"
        self.config = root / "sshd_config"
        self.config.write_text(
            f"Port {self.port}\nListenAddress 127.0.0.1\nHostKey {self.host_key}\n"
            f"PidFile {root / 'sshd.pid'}\nAuthorizedKeysFile {self.authorized}\n"
            "StrictModes no\nUsePAM no\nPasswordAuthentication no\n"
            "KbdInteractiveAuthentication no\nPubkeyAuthentication yes\n"
            "PermitRootLogin prohibit-password\nLogLevel VERBOSE\nMaxStartups 50\n" + extra_config)
        self.proc: subprocess.Popen | None = None

    @property
    def fingerprint(self) -> str:
        return fingerprint(Path(f"{self.host_key}.pub"))

    def start(self) -> None:
        if os.geteuid() == 0:
            os.makedirs("/run/sshd", mode=0o755, exist_ok=True)
        self.proc = subprocess.Popen([*self.wrap, SSHD, "-D", "-e", "-f", str(self.config), "-E", str(self.log)],
                                     stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                     stderr=subprocess.DEVNULL)
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(f"sshd exited: {self.log.read_text() if self.log.exists() else ''}")
            try:
                with socket.create_connection(("127.0.0.1", self.port), timeout=0.5) as s:
                    if s.recv(64).startswith(b"SSH-"):
                        return
            except OSError:
                time.sleep(0.05)
        raise RuntimeError("sshd did not start within 10 s")

    def log_until_ended(self, before: str, timeout: float = 30.0) -> str:
        """What sshd logged after *before*, read once it logged the connection's end: what did
        not happen ("no login was tried") is read after that event, not after a guessed pause."""
        deadline = time.monotonic() + timeout
        while True:
            new = self.log.read_text()[len(before):]
            if CONNECTION_ENDED.search(new):
                return new
            assert time.monotonic() < deadline, f"sshd logged no connection's end: {new!r}"
            time.sleep(0.02)

    def stop(self) -> None:
        if self.proc is not None:
            procs.stop(self.proc, 5)
        self.proc = None


@dataclass
class Client:
    """Our side: an ~/.ssh-like folder with a key the sshd accepts and its known_hosts entry."""

    dir: Path
    pub: str
    sshd: Sshd

    def opts(self, **kw) -> SshOptions:
        kw.setdefault("ssh_dir", self.dir)
        kw.setdefault("known_hosts_files", (self.dir / "known_hosts",))
        kw.setdefault("ssh_agent", False)
        return SshOptions(**kw)

    def ctx(self, settings: Settings | None = None, **kw) -> CheckContext:
        """A check context for this client (the checks' tests use it)."""
        kw.setdefault("ssh_options", self.opts())
        kw.setdefault("upnp", False)
        return CheckContext(settings=settings or Settings(), **kw)

    def peer(self, **kw) -> Peer:
        kw.setdefault("ssh_user", getpass.getuser())
        kw.setdefault("ssh_port", self.sshd.port)
        kw.setdefault("public_ip", "127.0.0.1")
        return Peer(name=kw.pop("name", "localhost"), **kw)

    def trust(self) -> None:
        (self.dir / "known_hosts").write_text(
            f"{host_key_name('localhost', self.sshd.port)} {self.sshd.host_pub.rsplit(' ', 1)[0]}\n")


def ros_sshd(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Sshd]:
    """The body of a module's own ``sshd`` fixture for ROS 1 probes on loopback: sessions with
    ROS_IP=127.0.0.1, so a peer-side probe advertises loopback only (``ssh_client`` then logs in
    there)."""
    if os.geteuid() != 0:
        pytest.skip("the loopback sshd needs root (privilege separation)")
    d = Sshd(tmp_path_factory.mktemp("sshd"), extra_config="SetEnv ROS_IP=127.0.0.1\n")
    d.start()
    yield d
    d.stop()


@pytest.fixture(scope="module")
def sshd(tmp_path_factory):
    d = Sshd(tmp_path_factory.mktemp("sshd"))
    d.start()
    yield d
    d.stop()


@pytest.fixture
def ssh_client(sshd, tmp_path) -> Client:
    cdir = tmp_path / "dot_ssh"
    cdir.mkdir(mode=0o700)
    pub = keygen(cdir / "id_ed25519")
    sshd.authorized.write_text(pub + "\n")
    c = Client(cdir, pub, sshd)
    c.trust()
    return c
