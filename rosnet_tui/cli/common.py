"""What every sub-command shares: exit codes, number and state-dir arguments, --config, and
loading the settings it names (saying why on stderr when they cannot be used).

Imported when rosnet-tui starts: heavy modules are imported inside the functions that need them.
"""

from __future__ import annotations

import argparse
import math
import os
import re
import stat
import sys
from pathlib import Path

EXIT_OK, EXIT_FAIL, EXIT_USAGE = 0, 1, 2

_DECIMAL = re.compile(r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?")
_WHOLE = re.compile(r"[+-]?\d{1,18}")


def number_in(lo: float, hi: float, *, whole: bool = False):
    """An argparse type: a plain decimal number (a whole one with *whole*) from *lo* to *hi*.

    NaN, infinities, hexadecimal, digit separators and values out of range are refused, so
    argparse exits 2 naming the option. Say the range in the option's help (``lo-hi``)."""
    def convert(text: str) -> float | int:
        t = text.strip()
        if not (_WHOLE if whole else _DECIMAL).fullmatch(t):
            raise argparse.ArgumentTypeError(
                f"'{text[:40]}' is not {'a whole number' if whole else 'a number'} "
                f"(from {lo:g} to {hi:g})")
        value: float | int = int(t) if whole else float(t)
        if not math.isfinite(value) or not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"{text[:40]} is out of range: from {lo:g} to "
                                             f"{hi:g}")
        return value
    convert.__name__ = "whole number" if whole else "number"
    return convert


def state_dir_problem(path: Path) -> str | None:
    """Why *path* cannot be a state dir (None: it can, or it does not exist yet)."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return None
    except NotADirectoryError:
        return f"--state-dir {path}: a part of this path is a file, not a folder"
    except OSError as exc:
        return f"--state-dir {path}: {exc.strerror}"
    if not stat.S_ISDIR(st.st_mode):
        return f"--state-dir {path} is not a folder"
    return None


def add_state_dir_option(parser: argparse.ArgumentParser, what: str) -> None:
    """--state-dir DIR; *what*: what lives there (the help says the default)."""
    parser.add_argument("--state-dir", metavar="DIR", type=Path, default=None,
                        help=f"{what} (default: $XDG_STATE_HOME/rosnet-tui)")


def state_dir_of(args: argparse.Namespace) -> Path:
    """The state dir named by --state-dir, absolute; the everyday one without it."""
    from rosnet_tui.core.config.paths import default_state_dir

    sd = getattr(args, "state_dir", None)
    return Path(sd).expanduser().absolute() if sd else default_state_dir()


def add_config_option(parser: argparse.ArgumentParser, *, top: bool = False) -> None:
    parser.add_argument(
        "--config", metavar="FILE", type=Path,
        default=None if top else argparse.SUPPRESS,
        help="settings file (default: $XDG_CONFIG_HOME/rosnet-tui/config.toml)")


def config_path(args: argparse.Namespace) -> Path:
    from rosnet_tui.core.config.paths import default_config_path

    return Path(args.config).expanduser() if getattr(args, "config", None) else default_config_path()


def _option_values(argv: list[str], option: str) -> list[str]:
    """The values given to *option* in *argv* (``--opt VALUE`` or ``--opt=VALUE``)."""
    out = []
    for i, a in enumerate(argv):
        if a == option and i + 1 < len(argv):
            out.append(argv[i + 1])
        elif a.startswith(option + "="):
            out.append(a[len(option) + 1:])
    return out


def complete_cut_writes(argv: list[str]) -> None:
    """Run first by every command, before anything reads a file: complete the in-place writes
    of rosnet-tui that a killed run left half done (a torn /etc/hosts, which every program on the
    machine reads), or, where this user may not, say that the file is torn and which command
    completes it. A few stats when nothing is pending; never stops the command (its own reads
    complete or refuse again)."""
    try:
        from rosnet_tui.core.config.paths import (
            DEFAULT_HOSTS_PATH,
            default_bashrc_path,
            default_config_path,
            default_state_dir,
        )
        from rosnet_tui.core.files.cut_writes import pending

        files: list[Path | str] = [Path(f).expanduser().absolute()
                                   for f in _option_values(argv, "--file")]
        dirs: list[Path | str] = [Path(d).expanduser().absolute()
                                  for d in _option_values(argv, "--state-dir")]
        files.append(DEFAULT_HOSTS_PATH)
        try:
            files.append(default_bashrc_path())
            dirs.append(default_state_dir())
        except (RuntimeError, KeyError):   # no home folder
            pass
        found = pending(files, dirs)
        if not found:
            return
        from rosnet_tui.core.files.managed_write import complete_cut_writes as complete
        from rosnet_tui.core.files.privilege import format_command, sudo_argv

        configs = [Path(c).expanduser().absolute() for c in _option_values(argv, "--config")]
        config = (configs or [default_config_path()])[-1]
        for line in complete(found, config=config if config.is_file() else None,
                             sudo=lambda args: format_command(sudo_argv(args))):
            say(f"rosnet-tui: {line}")
    except Exception:  # noqa: BLE001 - a look-ahead only; the command's own reads decide
        return


def say(msg: str) -> None:
    """A message on stderr (refusals, errors, what a command could not do)."""
    print(msg, file=sys.stderr, flush=True)


def interactive() -> bool:
    """A person at a terminal who can answer a question."""
    try:
        return sys.stdin.isatty() and sys.stdout.isatty()
    except (AttributeError, ValueError):
        return False


def preload_settings() -> None:
    """Import what :func:`load_settings_or_say` imports (for a process that loads ahead)."""
    import rosnet_tui.core.net.netinfo
    import rosnet_tui.core.saved.settings  # noqa: F401


def load_settings_or_say(args: argparse.Namespace, *, complete: bool = False):
    """The settings named by --config (Settings), or None after saying why on stderr.

    With *complete*, blank local IP and interface are filled in from this machine for this run,
    and settings that are still incomplete are refused (the caller exits 2).
    """
    from rosnet_tui.core.config.settings_model import SettingsError
    from rosnet_tui.core.net.netinfo import with_detected
    from rosnet_tui.core.saved.settings import load_settings

    path = config_path(args)
    try:
        settings = load_settings(path)
    except SettingsError as exc:
        say(f"rosnet-tui: the settings file cannot be used: {exc}")
        return None
    if settings is None:
        say(f"rosnet-tui: no settings file at {path}; run 'rosnet-tui' (the wizard) first, "
            "or pass --config FILE")
        return None
    if not complete:
        return settings
    settings = with_detected(settings)
    problems = settings.problems()
    if problems:
        say(f"rosnet-tui: the settings in {path} are not complete:")
        for key, why in problems:
            say(f"  {key}: {why}")
        say("Fix them by hand or with the wizard (rosnet-tui --setup).")
        return None
    return settings
