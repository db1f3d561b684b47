"""What the SSH layer is told: where our keys and known_hosts are, the agent, the budget, a pool."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

SYSTEM_KNOWN_HOSTS = Path("/etc/ssh/ssh_known_hosts")


@dataclass(frozen=True)
class SshOptions:
    """What the SSH layer needs to know, and nothing more.

    ``ssh_dir``: the folder with our keys and known_hosts (None: ``$HOME/.ssh``);
    ``known_hosts_files``: the files to trust (None: that folder's known_hosts and
    /etc/ssh/ssh_known_hosts); ``ssh_agent``: offer the agent's keys; ``timeout_s``: the default
    connect budget; ``pool``: an :class:`~rosnet_tui.core.ssh.pool.SshPool` whose connections
    the sessions share (None: one connection per session).
    """

    ssh_dir: Path | None = None
    known_hosts_files: tuple[Path, ...] | None = None
    ssh_agent: bool = True
    timeout_s: float = 3.0
    pool: Any = field(default=None, compare=False)


def ssh_dir(opts: SshOptions | None) -> Path:
    d = getattr(opts, "ssh_dir", None) if opts is not None else None
    return Path(d) if d else Path(os.path.expanduser("~")) / ".ssh"


def known_hosts_files(opts: SshOptions | None) -> list[Path]:
    files = getattr(opts, "known_hosts_files", None) if opts is not None else None
    if files:
        return [Path(f) for f in files]
    return [ssh_dir(opts) / "known_hosts", SYSTEM_KNOWN_HOSTS]
