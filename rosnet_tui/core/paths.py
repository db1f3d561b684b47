"""Where rosnet-tui's files are by default: the settings file, the state dir (undo journal,
backups, status), the hosts file and the shell rc file it writes. Declared here once; the
session, the writers, the checks and the CLI take these unless told other paths.
"""

from __future__ import annotations

import os
from pathlib import Path

DEFAULT_HOSTS_PATH = Path("/etc/hosts")


def default_config_path() -> Path:
    base = os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    return Path(base) / "rosnet-tui" / "config.toml"


def default_state_dir() -> Path:
    base = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    return Path(base) / "rosnet-tui"


def default_bashrc_path() -> Path:
    return Path.home() / ".bashrc"
