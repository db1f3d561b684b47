"""Where rosnet-tui's files are: the config folder and the settings file in it, the state dir
(undo journal, backups, status), the hosts file and the shell rc file it writes.

The defaults are declared here once. A :class:`Paths` value carries one set of places; the CLI
or the app builds one and hands the same value to the session, the write plans and the check
runner (tests point it into a temporary folder).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

DEFAULT_HOSTS_PATH = Path("/etc/hosts")


def xdg_config_home() -> Path:
    """This user's config base: $XDG_CONFIG_HOME, or ~/.config."""
    return Path(os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config"))


def default_config_dir() -> Path:
    """rosnet-tui's config folder: the settings file, the Zenoh configs, the fleet's TLS files.
    (``fleet_tls``, a program fed to peers, keeps its own copy; a test holds the two equal.)"""
    return xdg_config_home() / "rosnet-tui"


def default_config_path() -> Path:
    return default_config_dir() / "config.toml"


def default_state_dir() -> Path:
    base = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    return Path(base) / "rosnet-tui"


def default_bashrc_path() -> Path:
    return Path.home() / ".bashrc"


@dataclass(frozen=True)
class Paths:
    """The files one session, write or round of checks uses; each field defaults to the
    everyday place (read from the environment when the value is made)."""

    config_path: Path = field(default_factory=default_config_path)
    state_dir: Path = field(default_factory=default_state_dir)
    hosts_path: Path = DEFAULT_HOSTS_PATH
    bashrc_path: Path = field(default_factory=default_bashrc_path)
    # this machine's sshd config folder (sshd_config; its HostKey lines, or the default keys
    # there): relay.tunnel knows its own sshd by those keys
    sshd_dir: Path = Path("/etc/ssh")
