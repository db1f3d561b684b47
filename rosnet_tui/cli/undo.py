"""`rosnet-tui undo`: take back the last change rosnet-tui made (one per call): the files it wrote,
byte for byte, the firewall table it loaded or removed, or the modem forwards it made."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from rosnet_tui.cli.common import (
    EXIT_FAIL,
    EXIT_OK,
    EXIT_USAGE,
    add_config_option,
    add_state_dir_option,
    say,
    state_dir_of,
    state_dir_problem,
)
from rosnet_tui.cli.writing import confirm, paths_of, rerun_checks, run_as_root
from rosnet_tui.core import affected
from rosnet_tui.core.config.paths import DEFAULT_HOSTS_PATH
from rosnet_tui.core.config.settings_model import Settings, SettingsError
from rosnet_tui.core.exposure import firewall
from rosnet_tui.core.files import managed_file as mf
from rosnet_tui.core.files import managed_text as mt
from rosnet_tui.core.files import privilege
from rosnet_tui.core.ros import relay_apply
from rosnet_tui.core.saved.settings import load_settings
from rosnet_tui.core.upnp.journal import describe as describe_forward


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("undo", help="take back the last change rosnet-tui made: files, "
                                    "firewall or modem forwards",
                       description="Take back the last change rosnet-tui made, one per call "
                                   "(run it again to go further back): the files it wrote, put "
                                   "back byte for byte (/etc/hosts by `hosts apply` or sync, "
                                   "~/.bashrc and the Zenoh router's config by `ros apply`), "
                                   "the firewall table `firewall apply` loaded (or `firewall "
                                   "undo` removed), or the modem forwards `router map` made. "
                                   "Not the fleet CA and keys (`ros pair`).")
    add_config_option(p)
    p.add_argument("--yes", "-y", action="store_true",
                   help="restore without asking (needed where there is no terminal)")
    p.add_argument("--dry-run", action="store_true", help="show what would be restored")
    p.add_argument("--force", action="store_true",
                   help="restore even a file someone changed after rosnet-tui wrote it")
    add_state_dir_option(p, "where backups and the undo journal live")
    p.add_argument("--expect-entry", metavar="ID", default=None,
                   help="refuse unless the last change is still this one (used with sudo)")
    p.add_argument("--no-checks", action="store_true",
                   help="do not re-run the affected checks afterwards")
    p.set_defaults(func=run)


def _settings_quietly(args: argparse.Namespace) -> Settings | None:
    from rosnet_tui.cli.common import config_path

    try:
        return load_settings(config_path(args))
    except SettingsError:
        return None


def run(args: argparse.Namespace) -> int:
    sd = state_dir_of(args)
    bad_dir = state_dir_problem(sd)
    if bad_dir:
        say(f"rosnet-tui undo: {bad_dir}")
        return EXIT_USAGE
    try:
        plan = mf.plan_undo(sd, entry_id=args.expect_entry)
    except mt.NothingToUndoError as exc:
        print(f"rosnet-tui: {exc}")
        return EXIT_FAIL
    except mt.ManagedFileError as exc:
        say(f"rosnet-tui: {exc}")
        return EXIT_FAIL
    e = plan.entry
    print(f"Undo change #{e.id} ({e.label or 'no label'}, made {e.created}):")
    for f in e.files:
        what = "put back as it was" if f.existed else "removed (rosnet-tui created it)"
        print(f"  {f.path}: {what}")
    forwards = e.made()
    for kind, m in forwards:
        print(f"  {firewall.describe(m)}" if kind == firewall.KIND else
              f"  {relay_apply.describe(m)}" if kind == relay_apply.KIND else
              f"  the forward {describe_forward(m)}: removed from the modem")
    diff = plan.diff()
    if diff:
        sys.stdout.write(diff)
    elif e.files:
        print("The files are already as they were before that change.")
    if plan.conflicts and not args.force:
        say("rosnet-tui: changed by someone else since rosnet-tui wrote it: "
            + ", ".join(plan.conflicts) + ". Undoing would lose that change; nothing was "
            "restored. Pass --force to restore anyway.")
        return EXIT_FAIL
    if args.dry_run:
        print("Dry run: nothing was restored.")
        return EXIT_OK
    if diff or forwards:
        stop = confirm(args, "Restore these files?" if diff else
                       "Put the firewall back?" if e.kinds()[:1] == [firewall.KIND]
                       else "Put the relay's files back?" if e.kinds()[:1] == [relay_apply.KIND]
                       else "Remove these forwards?")
        if stop is not None:
            return stop
    if plan.needs_privilege:
        cmd = privilege.undo_command(entry_id=e.id, state_dir=sd, force=args.force)
        rc = run_as_root(cmd, "restoring", "undo")
        if rc != EXIT_OK:
            return rc
    else:
        try:
            result = mf.apply_undo(plan, force=args.force)
        except mt.ManagedFileError as exc:
            say(f"rosnet-tui: {exc}")
            return EXIT_FAIL
        if result.files:
            print(f"Restored: {', '.join(str(p) for p in result.files)}")
        for line in result.forwards:
            print(line)
    if not args.no_checks and firewall.KIND in e.kinds():
        rerun_checks(affected.FIREWALL, _settings_quietly(args), paths_of(args))
    elif not args.no_checks and e.kinds() and relay_apply.KIND not in e.kinds():
        rerun_checks(affected.FORWARD, _settings_quietly(args), paths_of(args))
    elif not args.no_checks:
        settings = _settings_quietly(args)
        paths = [Path(f.path) for f in e.files]
        hosts = [p for p in paths if p == DEFAULT_HOSTS_PATH or p.name == "hosts"]
        others = [p for p in paths if p not in hosts]
        ids = (affected.HOSTS if hosts else ()) + (affected.ROS_ENV if others else ())
        rerun_checks(ids, settings, paths_of(args, hosts_path=hosts[0] if hosts else None,
                                             bashrc_path=others[0] if others else None))
    return EXIT_OK
