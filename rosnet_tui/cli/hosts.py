"""`rosnet-tui hosts apply|use|show`: this component's hosts set per network profile."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from rosnet_tui.cli.common import (
    EXIT_FAIL,
    EXIT_OK,
    EXIT_USAGE,
    add_config_option,
    config_path,
    interactive,
    say,
    state_dir_of,
)
from rosnet_tui.cli.writing import (
    add_writer_options,
    ask,
    command_line,
    confirm,
    file_of,
    load_settings_for,
    paths_of,
    print_changes,
    report_settings_problems,
    rerun_checks,
    show_preview,
    write_preview,
    yes_to_all,
)
from rosnet_tui.core import affected
from rosnet_tui.core.config.paths import DEFAULT_HOSTS_PATH
from rosnet_tui.core.config.settings_model import PROFILES, Settings, SettingsError
from rosnet_tui.core.files import managed_text as mt
from rosnet_tui.core.files import managed_write as mw
from rosnet_tui.core.files import privilege
from rosnet_tui.core.files.hosts import (
    PROFILE_TITLES,
    WriterSettingsError,
    active_profile,
    find_hosts_conflicts,
    hosts_entries,
    preview_hosts,
    render_hosts_text,
)
from rosnet_tui.core.saved.settings import load_settings, save_settings


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
        old = mw.read_bytes(path, state_dir=state_dir_of(args))
        conflicts = find_hosts_conflicts(mt.decode(old) if old is not None else None,
                                         settings, profile)
    except mt.ManagedFileError:
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
    path = file_of(args, DEFAULT_HOSTS_PATH)
    fix = _decide_conflicts(args, settings, profile, path)
    try:
        preview = preview_hosts(settings, profile, path, fix_conflicts=bool(fix),
                                state_dir=state_dir_of(args))
    except WriterSettingsError as exc:
        return report_settings_problems(exc), settings
    except mt.ManagedFileError as exc:
        say(f"rosnet-tui: {exc}")
        return EXIT_FAIL, settings
    if args.expect_digest and preview.write_digest != args.expect_digest:
        say(f"rosnet-tui: {path}, its mode or owner, or the settings changed since the preview "
            "was made; nothing was written. Look at the new preview and apply again.")
        return EXIT_FAIL, settings
    print(f"Hosts set '{profile}' for {settings.this.name} in {path}:")
    show_preview(preview)
    if not preview.changed:
        return EXIT_OK, settings
    stop = confirm(args, f"Write these changes to {path}?", dry_run="nothing was written")
    if stop is not None:
        return stop, settings
    sudo_cmd = privilege.hosts_apply_command(
        profile=profile, config=config_path(args), digest=preview.write_digest, hosts_file=path,
        state_dir=state_dir_of(args), fix_conflicts=bool(fix))
    rc = write_preview(args, preview, sudo_cmd)
    if rc == EXIT_OK and not args.no_checks:
        rerun_checks(affected.HOSTS, settings, paths_of(args, hosts_path=path))
    return rc, settings


def _file_arg(args: argparse.Namespace) -> list[str]:
    """--file as given to this command, for a command printed for the user to run next."""
    return ["--file", str(file_of(args, DEFAULT_HOSTS_PATH))] if args.file else []


def run_apply(args: argparse.Namespace) -> int:
    rc, settings = apply_profile(args, args.profile)
    if rc == EXIT_OK and settings is not None and args.profile \
            and args.profile != settings.this.profile and not args.dry_run:
        print(f"note: the settings still name '{settings.this.profile}' as the active profile; "
              f"{command_line(args, 'hosts', 'use', args.profile, *_file_arg(args))} switches "
              "both")
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
            say(f"rosnet-tui: the hosts file was written, but the settings were not saved: {exc}")
            return EXIT_FAIL
        print(f"Active profile saved: {args.profile} ({config_path(args)})")
    return EXIT_OK


def run_show(args: argparse.Namespace) -> int:
    settings = load_settings_for(args)
    if settings is None:
        return EXIT_USAGE
    profile = args.profile or settings.this.profile
    path = file_of(args, DEFAULT_HOSTS_PATH)
    try:
        block = render_hosts_text(settings, profile)
    except WriterSettingsError as exc:
        say("rosnet-tui: the settings do not give a usable hosts set:")
        for key, why in exc.problems:
            say(f"  {key}: {why}")
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
    except mw.TornFileError as exc:      # only root may complete it: a failed state
        print(f"\n{exc}")
        return EXIT_FAIL
    except mt.ManagedFileError as exc:
        print(f"\n{path}: {exc}")
        return EXIT_OK
    text = mt.decode(preview.old) if preview.old is not None else None
    now = active_profile(text)
    print()
    if preview.old is None:
        print(f"{path} does not exist yet.")
    elif now is None:
        print(f"{path} has no rosnet-tui block yet.")
    else:
        print(f"{path}: the '{now}' set is active in the rosnet-tui block.")
    if preview.changed:
        print("To write this set: "
              + command_line(args, "hosts", "apply", "--profile", profile, *_file_arg(args)))
    else:
        print("The file already has exactly this set.")
    for note in preview.notes:
        print(f"note: {note}")
    return EXIT_OK
