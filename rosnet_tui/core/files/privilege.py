"""Writing root-owned files (/etc/hosts) from a program that never runs as root.

The TUI and the CLI run as the user. When a write needs root, they re-run our own writer under
``sudo`` with everything spelled out (absolute settings file, state dir, target file, and the
digest of the previewed file, so root writes exactly what the user saw or nothing). The TUI
suspends itself so sudo can ask for the password in the terminal, then resumes.
"""

from __future__ import annotations

import os
import shlex
import shutil
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

import rosnet_tui
from rosnet_tui.core.config.paths import Paths, default_config_path, default_state_dir
from rosnet_tui.core.files.managed_write import can_write

SUDO = "sudo"


def is_root() -> bool:
    return os.geteuid() == 0


def needs_privilege(path: Path) -> bool:
    """True when this process cannot write *path* itself (so the write needs sudo)."""
    return not is_root() and not can_write(Path(path))


def sudo_available() -> bool:
    return shutil.which(SUDO) is not None


def package_root() -> Path:
    """The folder holding the rosnet_tui package (a checkout's top, or site-packages)."""
    return Path(rosnet_tui.__file__).resolve().parent.parent


def self_argv(args: Sequence[str]) -> list[str]:
    """argv that runs rosnet-tui with *args* under this very Python."""
    return [sys.executable, "-m", "rosnet_tui", *args]


def sudo_argv(args: Sequence[str]) -> list[str]:
    """``sudo <this python> -m rosnet_tui ARGS``."""
    return [SUDO, *self_argv(args)]


def _abs(p: Path) -> str:
    return str(Path(p).expanduser().absolute())


def hosts_apply_command(*, profile: str, config: Path, digest: str, hosts_file: Path,
                        state_dir: Path, fix_conflicts: bool = False) -> list[str]:
    """The exact sudo command that writes the previewed hosts set (and nothing else)."""
    args = ["--config", _abs(config), "hosts", "apply", "--profile", profile, "--yes",
            "--expect-digest", digest, "--file", _abs(hosts_file), "--state-dir", _abs(state_dir),
            "--no-checks"]
    if fix_conflicts:
        args.append("--comment-conflicts")
    return sudo_argv(args)


def undo_command(*, entry_id: str, state_dir: Path, force: bool = False) -> list[str]:
    """The exact sudo command that undoes journal entry *entry_id* (and only that one)."""
    args = ["undo", "--yes", "--expect-entry", entry_id, "--state-dir", _abs(state_dir),
            "--no-checks"]
    if force:
        args.append("--force")
    return sudo_argv(args)


def format_command(argv: Sequence[str]) -> str:
    """A command line the user can read and paste."""
    return shlex.join(argv)


def rosnet_command(words: Sequence[str], *, config: Path | None = None,
                   state_dir: Path | None = None) -> str:
    """``rosnet-tui WORDS`` as the user must type it to act on what a session recorded: with
    its settings file and state dir when they are not the everyday ones (else `undo` looks in
    the everyday journal and finds nothing), shell-quoted. The CLI and the TUI both print it."""
    argv = ["rosnet-tui", *words]
    if config is not None:
        argv += ["--config", _abs(config)]
    if state_dir is not None:
        argv += ["--state-dir", _abs(state_dir)]
    return format_command(argv)


def session_command(words: Sequence[str], paths: Paths) -> str:
    """:func:`rosnet_command` for a session on *paths*: the settings file and state dir are
    named when they differ from the everyday ones."""
    config = None if _abs(paths.config_path) == _abs(default_config_path()) else paths.config_path
    state = None if _abs(paths.state_dir) == _abs(default_state_dir()) else paths.state_dir
    return rosnet_command(words, config=config, state_dir=state)


def run_privileged(argv: Sequence[str], *, interactive: bool = True,
                   timeout_s: float | None = 300) -> int:
    """Run *argv* (a sudo command from this module) in the current terminal; its exit code.

    *interactive*: sudo may ask for the password on the terminal (the TUI suspends first);
    otherwise ``sudo -n`` fails at once instead of waiting for a password. Bounded by
    *timeout_s*; 126 when sudo is missing, 124 on timeout.
    """
    argv = list(argv)
    if argv and argv[0] == SUDO:
        if not sudo_available():
            return 126
        if not interactive:
            argv.insert(1, "-n")
    try:
        return subprocess.run(argv, cwd=package_root(), timeout=timeout_s).returncode
    except subprocess.TimeoutExpired:
        return 124
    except OSError:
        return 126
