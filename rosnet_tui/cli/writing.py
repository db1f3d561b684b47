"""What the writer commands share (`hosts`, `ros`, `router`, `undo`): their options, settings
loading, the diff-and-ask flow, writing here or through sudo, and re-running the checks a write
affects.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterable
from pathlib import Path

from rosnet_tui.cli.common import (
    EXIT_FAIL,
    EXIT_OK,
    EXIT_USAGE,
    add_config_option,
    add_state_dir_option,
    config_path,
    interactive,
    load_settings_or_say,
    say,
    state_dir_of,
)
from rosnet_tui.core.config.paths import Paths
from rosnet_tui.core.config.settings_model import Settings
from rosnet_tui.core.files import managed_file as mf
from rosnet_tui.core.files import managed_text as mt
from rosnet_tui.core.files import privilege
from rosnet_tui.core.files.hosts import WriterSettingsError


def ask(question: str) -> bool:
    """Ask a yes/no question on the terminal; anything but y/yes is no."""
    try:
        answer = input(f"{question} [y/N] ")
    except EOFError:
        print()
        return False
    return answer.strip().lower() in ("y", "yes")


def load_settings_for(args: argparse.Namespace) -> Settings | None:
    """The settings, or None after saying why (the caller exits 2).

    A blank local IP (and interface) is filled in from this machine for this run, as `check`
    and the wizard do: the documented settings leave local_ip out. Nothing is saved.
    """
    from rosnet_tui.core.net.netinfo import with_detected

    settings = load_settings_or_say(args)
    return with_detected(settings) if settings is not None else None


def yes_to_all(args: argparse.Namespace) -> bool:
    """--yes answers every question the command would ask, unless the command replays an exact
    preview (--expect-digest, the privileged re-run): then only the flags decide."""
    return bool(args.yes) and not getattr(args, "expect_digest", None)


def report_settings_problems(exc: WriterSettingsError) -> int:
    say("rosnet-tui: nothing was written; the settings are not usable for this:")
    for key, why in exc.problems:
        say(f"  {key}: {why}")
    return EXIT_USAGE


def file_of(args: argparse.Namespace, default: Path) -> Path:
    """The file named by --file, absolute; *default* without it."""
    return Path(args.file).expanduser().absolute() if args.file else default


def paths_of(args: argparse.Namespace, *, hosts_path: Path | None = None,
             bashrc_path: Path | None = None) -> Paths:
    """The files of this command: --config, --state-dir, and the hosts file or rc file it
    wrote (None: the everyday place)."""
    files = {k: v for k, v in (("hosts_path", hosts_path), ("bashrc_path", bashrc_path))
             if v is not None}
    return Paths(config_path=config_path(args), state_dir=state_dir_of(args), **files)


def add_writer_options(p: argparse.ArgumentParser, *, file_help: str) -> None:
    add_config_option(p)
    p.add_argument("--dry-run", action="store_true", help="show the diff, write nothing")
    p.add_argument("--yes", "-y", action="store_true",
                   help="answer yes to every question the command would ask: write, and fix "
                        "what it would offer to fix (needed where there is no terminal)")
    p.add_argument("--file", metavar="PATH", type=Path, default=None, help=file_help)
    add_state_dir_option(p, "where backups and the undo journal live")
    p.add_argument("--expect-digest", metavar="SHA256", default=None,
                   help="refuse unless the file is still the one previewed (used with sudo)")
    p.add_argument("--no-checks", action="store_true",
                   help="do not re-run the affected checks after writing")


def command_line(args: argparse.Namespace, *words: str) -> str:
    """``rosnet-tui WORDS`` as the user must type it to act on what this command recorded:
    with its --config and --state-dir when they were given (else undo looks in the everyday
    journal and finds nothing), shell-quoted."""
    return privilege.rosnet_command(
        words, config=config_path(args) if getattr(args, "config", None) else None,
        state_dir=state_dir_of(args) if getattr(args, "state_dir", None) else None)


def print_changes(changes: Iterable[mt.LineChange]) -> None:
    for c in changes:
        print(f"  line {c.lineno}: {c.old.strip()}")
        print(f"    why: {c.why}")
        print(f"    becomes: {c.new.strip()}")


def show_preview(preview: mf.Preview) -> None:
    for note in preview.notes:
        print(f"note: {note}")
    if preview.changed:
        sys.stdout.write(preview.diff())
    else:
        print(f"{preview.path} is already up to date: nothing to write.")
    sys.stdout.flush()


NOT_WRITING = ("rosnet-tui: not writing without a confirmation, and there is no terminal to ask "
               "on: read the diff above, then run the same command with --yes")


def confirm(args: argparse.Namespace, question: str, *, dry_run: str | None = None,
            cancelled: str = "Cancelled: nothing was written.", no_terminal: str = NOT_WRITING
            ) -> int | None:
    """None to go on (--yes, or the person said yes); an exit code to stop with: a dry run
    (when the command has --dry-run, its *dry_run* words: "Dry run: <dry_run>."), declined
    (*cancelled* said), or no terminal to ask on (*no_terminal* on stderr)."""
    if dry_run is not None and args.dry_run:
        print(f"Dry run: {dry_run}.")
        return EXIT_OK
    if args.yes:
        return None
    if interactive():
        if ask(question):
            return None
        print(cancelled)
        return EXIT_FAIL
    say(no_terminal)
    return EXIT_USAGE


def run_as_root(cmd: list[str], doing: str, what: str) -> int:
    """Run our own sudo command *cmd* in this terminal, saying so first; an exit code."""
    line = privilege.format_command(cmd)
    if not privilege.sudo_available():
        say(f"rosnet-tui: {doing} needs root, and sudo is not installed; run this as root:\n"
            f"  {line}")
        return EXIT_FAIL
    print(f"{doing[0].upper()}{doing[1:]} needs root; running:\n  {line}")
    sys.stdout.flush()
    rc = privilege.run_privileged(cmd, interactive=interactive())
    if rc != 0:
        say(f"rosnet-tui: the privileged {what} did not succeed (exit {rc})")
        return EXIT_FAIL
    return EXIT_OK


def write_preview(args: argparse.Namespace, preview: mf.Preview, sudo_cmd: list[str] | None
                  ) -> int:
    """Write *preview* here, or through *sudo_cmd* when this user may not; say what happened."""
    if preview.needs_privilege:
        if sudo_cmd is None:
            say(f"rosnet-tui: this user may not write {preview.path}; nothing was written")
            return EXIT_FAIL
        return run_as_root(sudo_cmd, f"writing {preview.path}", "write")
    try:
        result = mf.apply_preview(preview, state_dir=state_dir_of(args))
    except mt.StalePreviewError as exc:
        say(f"rosnet-tui: {exc}")
        return EXIT_FAIL
    except mt.ManagedFileError as exc:
        say(f"rosnet-tui: {exc}")
        return EXIT_FAIL
    if result.changed:
        how = " in place (the file is a mount point)" if result.in_place else ""
        backups = ", ".join(str(b) for b in result.backups) or "none (the file was new)"
        print(f"Wrote {preview.path}{how}. Backup: {backups}. "
              f"Undo with: {command_line(args, 'undo')}")
    return EXIT_OK


def rerun_checks(ids: Iterable[str], settings: Settings | None, paths: Paths) -> None:
    """Re-run the checks a write affects and print them; skipped quietly if not available."""
    ids = list(ids)
    if settings is None or not ids:
        return
    try:
        from rosnet_tui.core.checks.runner import RunOptions, run_now, select

        specs = select(ids=ids)
    except Exception as exc:  # a broken check module must not hide a successful write
        print(f"(the checks could not be loaded: {type(exc).__name__}: {exc})")
        return
    if not specs:
        print(f"(checks {', '.join(ids)} are not available in this version)")
        return
    results = {r.id: r for r in run_now(settings, specs, RunOptions(paths=paths))}
    print("Checks after the change:")
    for spec in specs:
        r = results.get(spec.id)
        if r is None:
            continue
        print(f"  {r.status.label:<4} {r.id}: {r.summary}")
        if r.status.value in ("fail", "warn"):
            for line in r.evidence[:6]:
                print(f"         {line}")
