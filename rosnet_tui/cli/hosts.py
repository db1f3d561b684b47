"""`rosnet-tui hosts apply|use|show`: this component's hosts set per network profile.

Also home of the helpers the writer commands share (`ros`, `undo`): settings loading, the
diff-and-ask flow, and re-running the affected checks after a write.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterable
from pathlib import Path

from rosnet_tui.cli import (
    EXIT_FAIL,
    EXIT_OK,
    EXIT_USAGE,
    add_config_option,
    config_path,
    load_settings_or_say,
)
from rosnet_tui.core import affected, privilege
from rosnet_tui.core import managed_file as mf
from rosnet_tui.core.hosts import (
    DEFAULT_HOSTS_PATH,
    PROFILE_TITLES,
    WriterSettingsError,
    active_profile,
    find_hosts_conflicts,
    hosts_entries,
    preview_hosts,
    render_hosts_text,
)
from rosnet_tui.core.settings import (
    PROFILES,
    Settings,
    SettingsError,
    default_state_dir,
    load_settings,
    save_settings,
)


# --------------------------------------------------------------------------- shared helpers
def err(msg: str) -> None:
    print(msg, file=sys.stderr)


def interactive() -> bool:
    """A person at a terminal who can answer a question."""
    try:
        return sys.stdin.isatty() and sys.stdout.isatty()
    except (AttributeError, ValueError):
        return False


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
    from rosnet_tui.core.netinfo import with_detected

    settings = load_settings_or_say(args)
    return with_detected(settings) if settings is not None else None


def yes_to_all(args: argparse.Namespace) -> bool:
    """--yes answers every question the command would ask, unless the command replays an exact
    preview (--expect-digest, the privileged re-run): then only the flags decide."""
    return bool(args.yes) and not getattr(args, "expect_digest", None)


def report_settings_problems(exc: WriterSettingsError) -> int:
    err("rosnet-tui: nothing was written; the settings are not usable for this:")
    for key, why in exc.problems:
        err(f"  {key}: {why}")
    return EXIT_USAGE


def state_dir_of(args: argparse.Namespace) -> Path:
    sd = getattr(args, "state_dir", None)
    return Path(sd).expanduser().absolute() if sd else default_state_dir()


def add_writer_options(p: argparse.ArgumentParser, *, file_help: str) -> None:
    add_config_option(p)
    p.add_argument("--dry-run", action="store_true", help="show the diff, write nothing")
    p.add_argument("--yes", "-y", action="store_true",
                   help="answer yes to every question the command would ask: write, and fix "
                        "what it would offer to fix (needed where there is no terminal)")
    p.add_argument("--file", metavar="PATH", type=Path, default=None, help=file_help)
    p.add_argument("--state-dir", metavar="DIR", type=Path, default=None,
                   help="where backups and the undo journal live "
                        "(default: $XDG_STATE_HOME/rosnet-tui)")
    p.add_argument("--expect-digest", metavar="SHA256", default=None,
                   help="refuse unless the file is still the one previewed (used with sudo)")
    p.add_argument("--no-checks", action="store_true",
                   help="do not re-run the affected checks after writing")


def print_changes(changes: Iterable[mf.LineChange]) -> None:
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


def confirm(args: argparse.Namespace, question: str) -> int | None:
    """None to go on; an exit code to stop with (declined, or no terminal to ask on)."""
    if args.yes:
        return None
    if interactive():
        if ask(question):
            return None
        print("Cancelled: nothing was written.")
        return EXIT_FAIL
    err("rosnet-tui: not writing without a confirmation, and there is no terminal to ask on: "
        "read the diff above, then run the same command with --yes")
    return EXIT_USAGE


def run_as_root(cmd: list[str], doing: str, what: str) -> int:
    """Run our own sudo command *cmd* in this terminal, saying so first; an exit code."""
    line = privilege.format_command(cmd)
    if not privilege.sudo_available():
        err(f"rosnet-tui: {doing} needs root, and sudo is not installed; run this as root:\n"
            f"  {line}")
        return EXIT_FAIL
    print(f"{doing[0].upper()}{doing[1:]} needs root; running:\n  {line}")
    sys.stdout.flush()
    rc = privilege.run_privileged(cmd, interactive=interactive())
    if rc != 0:
        err(f"rosnet-tui: the privileged {what} did not succeed (exit {rc})")
        return EXIT_FAIL
    return EXIT_OK


def write_preview(args: argparse.Namespace, preview: mf.Preview, sudo_cmd: list[str] | None
                  ) -> int:
    """Write *preview* here, or through *sudo_cmd* when this user may not; say what happened."""
    if preview.needs_privilege:
        if sudo_cmd is None:
            err(f"rosnet-tui: this user may not write {preview.path}; nothing was written")
            return EXIT_FAIL
        return run_as_root(sudo_cmd, f"writing {preview.path}", "write")
    try:
        result = mf.apply_preview(preview, state_dir=state_dir_of(args))
    except mf.StalePreviewError as exc:
        err(f"rosnet-tui: {exc}")
        return EXIT_FAIL
    except mf.ManagedFileError as exc:
        err(f"rosnet-tui: {exc}")
        return EXIT_FAIL
    if result.changed:
        how = " in place (the file is a mount point)" if result.in_place else ""
        backups = ", ".join(str(b) for b in result.backups) or "none (the file was new)"
        print(f"Wrote {preview.path}{how}. Backup: {backups}. "
              f"Undo with: rosnet-tui undo")
    return EXIT_OK


def rerun_checks(ids: Iterable[str], settings: Settings | None, *, hosts_path: Path | None = None,
                 bashrc_path: Path | None = None, state_dir: Path | None = None) -> None:
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
    opts = RunOptions(hosts_path=hosts_path, bashrc_path=bashrc_path, state_dir=state_dir)
    results = {r.id: r for r in run_now(settings, specs, opts)}
    print("Checks after the change:")
    for spec in specs:
        r = results.get(spec.id)
        if r is None:
            continue
        print(f"  {r.status.label:<4} {r.id}: {r.summary}")
        if r.status.value in ("fail", "warn"):
            for line in r.evidence[:6]:
                print(f"         {line}")


# --------------------------------------------------------------------------- hosts
def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("hosts", help="write this component's hosts set into /etc/hosts",
                       description="This component's /etc/hosts entries per network profile "
                                   "(remote, office, portable), kept in a marked block.")
    p.set_defaults(func=lambda a: (p.print_help(sys.stderr), EXIT_USAGE)[1])
    hs = p.add_subparsers(dest="hosts_command", metavar="ACTION", parser_class=type(p))

    a = hs.add_parser("apply", help="write the set of a profile (default: the active one)")
    a.add_argument("--profile", choices=PROFILES, default=None,
                   help="which set to write (default: this.profile in the settings)")
    add_writer_options(a, file_help="hosts file to write (default: /etc/hosts)")
    a.add_argument("--comment-conflicts", action="store_true",
                   help="also comment out lines outside our block that give our names "
                        "other addresses")
    a.set_defaults(func=run_apply)

    u = hs.add_parser("use", help="switch the active set to PROFILE and save it in the settings")
    u.add_argument("profile", choices=PROFILES, metavar="PROFILE",
                   help="remote | office | portable")
    add_writer_options(u, file_help="hosts file to write (default: /etc/hosts)")
    u.add_argument("--comment-conflicts", action="store_true",
                   help="also comment out lines outside our block that give our names "
                        "other addresses")
    u.set_defaults(func=run_use)

    s = hs.add_parser("show", help="show a profile's set and the state of the hosts file")
    s.add_argument("--profile", choices=PROFILES, default=None)
    s.add_argument("--file", metavar="PATH", type=Path, default=None,
                   help="hosts file to look at (default: /etc/hosts)")
    s.add_argument("--state-dir", metavar="DIR", type=Path, default=None,
                   help="the state dir of the writer, where a write cut short may have left its "
                        "journal (default: $XDG_STATE_HOME/rosnet-tui)")
    add_config_option(s)
    s.set_defaults(func=run_show)


def _decide_conflicts(args: argparse.Namespace, settings: Settings, profile: str,
                      path: Path) -> bool | int:
    """Whether to fix conflicting lines: the flag, or the user's answer on a terminal."""
    if args.comment_conflicts or yes_to_all(args):
        return True
    if args.yes or args.dry_run or not interactive():
        return False
    try:
        old = mf.read_bytes(path, state_dir=state_dir_of(args))
        conflicts = find_hosts_conflicts(mf.decode(old) if old is not None else None,
                                         settings, profile)
    except mf.ManagedFileError:
        return False
    if not conflicts:
        return False
    print(f"{path} has lines outside the rosnet-tui block that conflict with the new set:")
    print_changes(conflicts)
    return ask("Change these lines as shown (the backup keeps the originals)?")


def apply_profile(args: argparse.Namespace, profile: str | None) -> tuple[int, Settings | None]:
    settings = load_settings_for(args)
    if settings is None:
        return EXIT_USAGE, None
    profile = profile or settings.this.profile
    path = Path(args.file).expanduser().absolute() if args.file else DEFAULT_HOSTS_PATH
    fix = _decide_conflicts(args, settings, profile, path)
    try:
        preview = preview_hosts(settings, profile, path, fix_conflicts=bool(fix),
                                state_dir=state_dir_of(args))
    except WriterSettingsError as exc:
        return report_settings_problems(exc), settings
    except mf.ManagedFileError as exc:
        err(f"rosnet-tui: {exc}")
        return EXIT_FAIL, settings
    if args.expect_digest and preview.digest != args.expect_digest:
        err(f"rosnet-tui: {path} changed since the preview was made; nothing was written. "
            "Look at the new preview and apply again.")
        return EXIT_FAIL, settings
    print(f"Hosts set '{profile}' for {settings.this.name} in {path}:")
    show_preview(preview)
    if not preview.changed:
        return EXIT_OK, settings
    if args.dry_run:
        print("Dry run: nothing was written.")
        return EXIT_OK, settings
    stop = confirm(args, f"Write these changes to {path}?")
    if stop is not None:
        return stop, settings
    sudo_cmd = privilege.hosts_apply_command(
        profile=profile, config=config_path(args), digest=preview.digest, hosts_file=path,
        state_dir=state_dir_of(args), fix_conflicts=bool(fix))
    rc = write_preview(args, preview, sudo_cmd)
    if rc == EXIT_OK and not args.no_checks:
        rerun_checks(affected.HOSTS, settings, hosts_path=path, state_dir=state_dir_of(args))
    return rc, settings


def run_apply(args: argparse.Namespace) -> int:
    rc, settings = apply_profile(args, args.profile)
    if rc == EXIT_OK and settings is not None and args.profile \
            and args.profile != settings.this.profile and not args.dry_run:
        print(f"note: the settings still name '{settings.this.profile}' as the active profile; "
              f"'rosnet-tui hosts use {args.profile}' switches both")
    return rc


def run_use(args: argparse.Namespace) -> int:
    rc, settings = apply_profile(args, args.profile)
    if rc != EXIT_OK or settings is None or args.dry_run:
        return rc
    if settings.this.profile != args.profile:
        try:
            # The file's own values, not this run's (the local IP filled in from this machine).
            saved = load_settings(config_path(args)) or settings
            saved.this.profile = args.profile
            save_settings(saved, config_path(args))
        except (SettingsError, OSError) as exc:
            err(f"rosnet-tui: the hosts file was written, but the settings were not saved: {exc}")
            return EXIT_FAIL
        print(f"Active profile saved: {args.profile} ({config_path(args)})")
    return EXIT_OK


def run_show(args: argparse.Namespace) -> int:
    settings = load_settings_for(args)
    if settings is None:
        return EXIT_USAGE
    profile = args.profile or settings.this.profile
    path = Path(args.file).expanduser().absolute() if args.file else DEFAULT_HOSTS_PATH
    try:
        block = render_hosts_text(settings, profile)
    except WriterSettingsError as exc:
        err("rosnet-tui: the settings do not give a usable hosts set:")
        for key, why in exc.problems:
            err(f"  {key}: {why}")
        return EXIT_USAGE
    print(f"Profile: {PROFILE_TITLES[profile]}"
          f"{' (active in the settings)' if profile == settings.this.profile else ''}")
    for e in hosts_entries(settings, profile):
        print(f"  {e.ip:<15} {e.name}  ({e.why})")
    print()
    print(f"The block rosnet-tui writes into {path}:")
    sys.stdout.write(block)
    try:
        preview = preview_hosts(settings, profile, path, state_dir=state_dir_of(args))
    except mf.ManagedFileError as exc:
        print(f"\n{path}: {exc}")
        return EXIT_OK
    text = mf.decode(preview.old) if preview.old is not None else None
    now = active_profile(text)
    print()
    if preview.old is None:
        print(f"{path} does not exist yet.")
    elif now is None:
        print(f"{path} has no rosnet-tui block yet.")
    else:
        print(f"{path}: the '{now}' set is active in the rosnet-tui block.")
    if preview.changed:
        print(f"To write this set: rosnet-tui hosts apply --profile {profile}")
    else:
        print("The file already has exactly this set.")
    for note in preview.notes:
        print(f"note: {note}")
    return EXIT_OK
