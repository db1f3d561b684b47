"""What the SSH layer is told: where our keys and known_hosts are, the agent, the budget, a pool,
and the relay that is the jump host to peers nobody can reach."""

from __future__ import annotations

import getpass
import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from rosnet_tui.core.config.settings_model import RelaySettings

SYSTEM_KNOWN_HOSTS = Path("/etc/ssh/ssh_known_hosts")


@dataclass(frozen=True)
class RelayRoute:
    """The relay as a jump host: its sshd (``host``, ``port``, login ``user``) and, by component
    name, the relay's loopback port where that component's reverse tunnel ends."""

    host: str
    user: str
    port: int = 22
    tunnels: tuple[tuple[str, int], ...] = ()

    def tunnel_port(self, name: str) -> int | None:
        """The relay's loopback port for *name* (None: *name* is reached directly)."""
        return next((p for n, p in self.tunnels if n == name), None)


def relay_route(relay: RelaySettings) -> RelayRoute | None:
    """The jump route of the ``[relay]`` settings; None without a relay or without tunnels."""
    if not relay.host or not relay.tunnels:
        return None
    return RelayRoute(relay.host, relay.ssh_user or getpass.getuser(), int(relay.ssh_port or 22),
                      tuple(sorted((str(n), int(p)) for n, p in relay.tunnels.items())))


@dataclass(frozen=True)
class SshOptions:
    """What the SSH layer needs to know, and nothing more.

    ``ssh_dir``: the folder with our keys and known_hosts (None: ``$HOME/.ssh``);
    ``known_hosts_files``: the files to trust (None: that folder's known_hosts and
    /etc/ssh/ssh_known_hosts); ``ssh_agent``: offer the agent's keys; ``timeout_s``: the default
    connect budget; ``pool``: an :class:`~rosnet_tui.core.ssh.pool.SshPool` whose connections
    the sessions share (None: one connection per session); ``relay``: the jump host to the
    peers that have a tunnel on it (None: every peer is reached directly).
    """

    ssh_dir: Path | None = None
    known_hosts_files: tuple[Path, ...] | None = None
    ssh_agent: bool = True
    timeout_s: float = 3.0
    pool: Any = field(default=None, compare=False)
    relay: RelayRoute | None = None


def options_for(relay: RelaySettings, base: SshOptions | None = None) -> SshOptions:
    """*base* (default: the defaults) with the jump route of the ``[relay]`` settings: what a
    caller that has settings but no options of its own hands to the SSH layer."""
    return replace(base or SshOptions(), relay=relay_route(relay))


def ssh_dir(opts: SshOptions | None) -> Path:
    d = getattr(opts, "ssh_dir", None) if opts is not None else None
    return Path(d) if d else Path(os.path.expanduser("~")) / ".ssh"


def known_hosts_files(opts: SshOptions | None) -> list[Path]:
    files = getattr(opts, "known_hosts_files", None) if opts is not None else None
    if files:
        return [Path(f) for f in files]
    return [ssh_dir(opts) / "known_hosts", SYSTEM_KNOWN_HOSTS]
