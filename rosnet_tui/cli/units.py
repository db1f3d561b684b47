"""systemd units written by the CLI (`sync install-service`, `relay tunnel --install-service`):
how a command line becomes an ExecStart, how this very install is found again, and the preview,
question and write every unit goes through."""

from __future__ import annotations

import argparse
import difflib
import sys
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path

from rosnet_tui.cli.common import EXIT_FAIL, EXIT_OK, EXIT_USAGE, say
from rosnet_tui.cli.writing import confirm
from rosnet_tui.core.files import privilege


def systemd_quote(arg: str) -> str:
    """One ExecStart word: as is when plain, else in double quotes with \\ and " escaped."""
    if arg and all(c.isalnum() or c in "/._-=:+@,%" for c in arg):
        return arg
    return '"' + arg.replace("\\", "\\\\").replace('"', '\\"').replace("%", "%%") + '"'


def exec_lines(argv: Sequence[str], root: Path | None = None) -> list[str]:
    """ExecStart of *argv* (an install by its absolute path: systemd starts it with a clean
    environment), and the path to the package (*root*: the folder holding ``rosnet_tui``;
    default: this very install's) when it is not installed in site-packages (a checkout)."""
    lines = ["ExecStart=" + " ".join(systemd_quote(a) for a in argv),
             "Environment=PYTHONUNBUFFERED=1"]
    root = privilege.package_root() if root is None else root
    if root.parts and not any(part in ("site-packages", "dist-packages") for part in root.parts):
        lines.append("Environment=" + systemd_quote(f"PYTHONPATH={root}"))
    return lines


def restart_lines(policy: str, seconds: int) -> list[str]:
    """How a unit's command is started again: *policy* after *seconds*, but never after it
    refused its settings (exit 2: a restart cannot mend them; a tunnel unit left from ROS 2 days
    on a component now on ROS 1 started Python every few seconds, for ever). The journal keeps
    the refusal; once the settings are mended, ``systemctl restart`` runs it again."""
    return [f"Restart={policy}", f"RestartSec={seconds}",
            f"RestartPreventExitStatus={EXIT_USAGE}"]


def install_unit(args: argparse.Namespace, path: Path, text: str, *, ctl: str = "systemctl",
                 notes: Iterable[str] = (), denied: Callable[[], str]) -> int:
    """Show the unit (or its change against the file there), ask, write it atomically; then say
    how to start it. *denied*: the words when this user may not write *path*."""
    from rosnet_tui.core.files.regular_file import FileRefusedError, read_regular
    from rosnet_tui.core.saved.settings import atomic_write_text

    try:   # without blocking: a FIFO or a device there is refused, not waited on
        old = read_regular(path, 1 << 20).decode("utf-8", "replace")
    except FileNotFoundError:
        old = None
    except FileRefusedError as exc:
        say(f"rosnet-tui: {exc}")
        return EXIT_FAIL
    except OSError as exc:
        say(f"rosnet-tui: cannot read {path}: {exc.strerror}")
        return EXIT_FAIL
    print(f"The systemd unit {path}:")
    if old is None:
        for line in text.splitlines():
            print(f"  {line}")
    elif old == text:
        print("  (already there, exactly this content; nothing to write)")
    else:
        sys.stdout.writelines(difflib.unified_diff(old.splitlines(True), text.splitlines(True),
                                                   f"{path} (now)", f"{path} (after)"))
    for n in notes:
        print(f"note: {n}")
    unit = path.name
    then = f"Then: {ctl} daemon-reload && {ctl} enable --now {unit}"
    if old == text:
        print(then)
        return EXIT_OK
    stop = confirm(args, f"Write {path}?", dry_run="nothing was written",
                   cancelled="Nothing was written.",
                   no_terminal="rosnet-tui: not writing without a terminal to ask on; read the "
                               "unit above, then run the same command with --yes")
    if stop is not None:
        return stop
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_text(path, text, mode=0o644)
    except PermissionError:
        say(denied())
        return EXIT_FAIL
    except OSError as exc:
        say(f"rosnet-tui: cannot write {path}: {exc.strerror}")
        return EXIT_FAIL
    print(f"Wrote {path}.")
    print(then)
    return EXIT_OK
