"""`rosnet-tui ros apply|export`: the ROS environment for this component's role, in ~/.bashrc.

ROS 1: ROS_MASTER_URI. ROS 2 ([ros] version = 2): RMW_IMPLEMENTATION, ROS_DOMAIN_ID and the
Zenoh router's config (ZENOH_ROUTER_CONFIG_URI and the JSON5 file it names), or client mode for a
lone node; all files in one undoable apply.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from rosnet_tui.cli import ros_pair
from rosnet_tui.cli.common import (
    EXIT_FAIL,
    EXIT_OK,
    EXIT_USAGE,
    add_config_option,
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
from rosnet_tui.core.config.paths import default_bashrc_path, default_config_dir
from rosnet_tui.core.files import managed_file as mf
from rosnet_tui.core.files import managed_text as mt
from rosnet_tui.core.files import managed_write as mw
from rosnet_tui.core.files.bashrc import (
    ROS_IP_REASON,
    find_ros_ip_lines,
    preview_bashrc,
    shell_lines,
)
from rosnet_tui.core.files.hosts import WriterSettingsError
from rosnet_tui.core.ros import ros2
from rosnet_tui.core.ssh.client_config import ssh_config_previews
from rosnet_tui.core.ssh.options import options_for

HELP = "write the ROS environment for this component's role (ROS 1 or 2) into ~/.bashrc"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("ros", help=HELP,
                       description="The ROS environment for this component's role, in a marked "
                                   "block of ~/.bashrc (or another shell file). ROS 1: "
                                   "ROS_MASTER_URI. ROS 2 ([ros] version = 2): "
                                   "RMW_IMPLEMENTATION=rmw_zenoh_cpp, ROS_DOMAIN_ID and "
                                   "ZENOH_ROUTER_CONFIG_URI, with the Zenoh router's config file "
                                   "it names; under mutual TLS also the fleet CA and this "
                                   "router's key and certificate (the master), or pairing with "
                                   "the master (a member).")
    p.set_defaults(func=lambda a: (p.print_help(sys.stderr), EXIT_USAGE)[1])
    rs = p.add_subparsers(dest="ros_command", metavar="ACTION", parser_class=type(p))

    a = rs.add_parser("apply", help="write the block (ROS 1: ROS_MASTER_URI; ROS 2: rmw_zenoh "
                                    "and the router's config), after a preview",
                      description="Show what changes, ask, then write. ROS 1: the "
                                  "ROS_MASTER_URI block of ~/.bashrc. ROS 2: RMW_IMPLEMENTATION, "
                                  "ROS_DOMAIN_ID and ZENOH_ROUTER_CONFIG_URI in ~/.bashrc, and "
                                  "the Zenoh router's config file; under mutual TLS ([ros] "
                                  "security = \"mtls\", the default) the master also gets the "
                                  "fleet CA and its router's key and certificate, a member pairs "
                                  "with the master over SSH. `rosnet-tui undo` takes the files "
                                  "back, not the CA or keys.")
    add_writer_options(a, file_help="shell file to write (default: ~/.bashrc)")
    a.add_argument("--comment-ros-ip", action="store_true",
                   help="also comment out ROS_IP / ROS_HOSTNAME lines (they break remote "
                        "networks); --yes does it too")
    a.add_argument("--client", action="store_true",
                   help="ROS 2, a member without a router of its own: its nodes connect to the "
                        "master's router in client mode")
    a.add_argument("--router-config", metavar="PATH", type=Path, default=None,
                   help="ROS 2: where to write the Zenoh router's config (default: "
                        "~/.config/rosnet-tui/zenoh-router.json5)")
    a.set_defaults(func=run_apply)

    e = rs.add_parser("export", help="print the lines that set up the current shell "
                                     "(eval \"$(rosnet-tui ros export)\")")
    add_config_option(e)
    e.add_argument("--client", action="store_true",
                   help="ROS 2: the lines of a lone node in client mode")
    e.set_defaults(func=run_export)
    ros_pair.register(rs)


def _decide_comment(args: argparse.Namespace, path: Path) -> bool:
    if args.comment_ros_ip or yes_to_all(args):   # --yes: yes to this question too
        return True
    if args.yes or args.dry_run or not interactive():
        return False
    try:
        old = mw.read_bytes(path, state_dir=state_dir_of(args))
        found = find_ros_ip_lines(mt.decode(old) if old is not None else None)
    except mt.ManagedFileError:
        return False
    if not found:
        return False
    print(f"{path} sets ROS_IP or ROS_HOSTNAME:")
    print_changes(found)
    print(f"Why it matters: {ROS_IP_REASON}.")
    return ask("Comment these lines out (they stay in the file, and in the backup)?")


def run_apply(args: argparse.Namespace) -> int:
    settings = load_settings_for(args)
    if settings is None:
        return EXIT_USAGE
    if settings.ros2:
        return _apply_ros2(args, settings)
    path = file_of(args, default_bashrc_path())
    comment = _decide_comment(args, path)
    try:
        preview = preview_bashrc(settings, path, comment_ros_ip=comment,
                                 state_dir=state_dir_of(args))
        # ROS 1 refuses [relay]: this only takes out a block a ROS 2 apply left (as ROS 2's)
        jumps, notes = ssh_config_previews(settings, state_dir=state_dir_of(args))
        lines = shell_lines(settings, os.environ)
    except WriterSettingsError as exc:
        return report_settings_problems(exc)
    except mt.ManagedFileError as exc:
        say(f"rosnet-tui: {exc}")
        return EXIT_FAIL
    if args.expect_digest and preview.digest != args.expect_digest:
        say(f"rosnet-tui: {path} changed since the preview was made; nothing was written")
        return EXIT_FAIL
    role = "the ROS master" if settings.is_master else f"a member (master: {settings.master_name})"
    print(f"ROS settings for {settings.this.name}, {role}, in {path}:")
    show_preview(preview)
    for p in jumps:
        show_preview(p)
    for n in notes:
        print(f"note: {n}")
    rc = EXIT_OK
    changed = [p for p in (preview, *jumps) if p.changed]
    if changed:
        stop = confirm(args, f"Write these changes to {', '.join(str(p.path) for p in changed)}?",
                       dry_run="nothing was written")
        if stop is not None:
            return stop
        rc = (write_preview(args, preview, None) if changed == [preview]
              else _write_all(args, [preview, *jumps], "ROS environment"))
    if rc == EXIT_OK:
        print("New shells get it from the file. For this shell, run:")
        for line in lines:
            print(f"  {line}")
        if not args.no_checks:
            rerun_checks(affected.ROS_ENV, settings, paths_of(args, bashrc_path=path))
    return rc


def _write_all(args: argparse.Namespace, previews: list[mf.Preview], label: str) -> int:
    """Write every changed preview as one undo entry; say what was written."""
    try:
        result = mf.apply_previews(previews, state_dir=state_dir_of(args), label=label)
    except mt.ManagedFileError as exc:
        say(f"rosnet-tui: {exc}")
        return EXIT_FAIL
    print(f"Wrote {', '.join(str(p.path) for p in previews if p.changed)}. Backups: "
          f"{', '.join(str(b) for b in result.backups) or 'none (new files)'}. "
          f"Undo with: {command_line(args, 'undo')}")
    return EXIT_OK


def run_export(args: argparse.Namespace) -> int:
    settings = load_settings_for(args)
    if settings is None:
        return EXIT_USAGE
    try:
        lines = (ros2.shell_lines(settings, client=args.client) if settings.ros2
                 else shell_lines(settings, os.environ))
        for line in lines:
            print(line)
    except WriterSettingsError as exc:
        return report_settings_problems(exc)
    return EXIT_OK


def _apply_ros2(args: argparse.Namespace, settings) -> int:
    """ROS 2: the ~/.bashrc block and the router's config, previewed, written as one apply."""
    path = file_of(args, default_bashrc_path())
    rc = Path(args.router_config).expanduser().absolute() if args.router_config else None
    try:
        previews = ros2.previews(settings, path, client=args.client, router_config_path=rc,
                                 state_dir=state_dir_of(args))
        jumps, notes = ssh_config_previews(settings, state_dir=state_dir_of(args))
        previews += jumps
        lines = ros2.shell_lines(settings, client=args.client)
    except WriterSettingsError as exc:
        return report_settings_problems(exc)
    except mt.ManagedFileError as exc:
        say(f"rosnet-tui: {exc}")
        return EXIT_FAIL
    role = ("the master (its router is the hub)" if settings.is_master else
            f"a member (master: {settings.master_name})")
    print(f"ROS 2 (rmw_zenoh) settings for {settings.this.name}, {role}:")
    for p in previews:
        show_preview(p)
    for n in notes:
        print(f"note: {n}")
    tls = _tls_plan(settings) if ros2.mtls(settings) else ""
    if tls:
        print(tls)
    changed = [p for p in previews if p.changed]
    if args.dry_run:    # before anything is made: the TLS files are made even with no file to write
        print("Dry run: nothing was written" + (", and no key or certificate made." if tls
                                                 else "."))
        return EXIT_OK
    if changed:
        stop = confirm(args, "Write these changes?")
        if stop is not None:
            return stop
        if _write_all(args, previews, "ROS 2 environment and Zenoh config") != EXIT_OK:
            return EXIT_FAIL
    print("New shells get it from the file. For this shell, run:")
    for line in lines:
        print(f"  {line}")
    if not (args.client and not settings.is_master):
        print("Then start the router: ros2 run rmw_zenoh_cpp rmw_zenohd")
    rc = _fleet_tls(settings) if ros2.mtls(settings) else EXIT_OK
    if rc == EXIT_OK and settings.is_master and settings.relay.host:
        print(f"Next, the relay {settings.relay.host}: `rosnet-tui relay apply` sets it up from "
              "here (its certificate, router config and unit, over SSH).")
    if not ros2.mtls(settings):
        print("Security is off ([ros] security = \"none\"): anyone who reaches the master's "
              f"port {settings.ros.zenoh_port} can join the ROS graph.")
    if not args.no_checks:
        rerun_checks(affected.ros2_write(ros2.mtls(settings)), settings,
                     paths_of(args, bashrc_path=path))
    return rc


def _tls_plan(settings) -> str:
    """What the apply does for mutual TLS besides the files above (nothing is done here)."""
    from rosnet_tui.core.ros import fleet_tls, pairing

    paths = fleet_tls.tls_paths(default_config_dir())
    if settings.is_master:
        plan = pairing.master_plan(settings, paths)
        return ("Mutual TLS: this apply also makes " + "; ".join(plan) + ". `rosnet-tui undo` "
                "does not remove them.") if plan else ""
    why = pairing.needs_pairing(settings, paths)
    if why is None:
        return ""
    return (f"Mutual TLS: this apply then pairs with the master {settings.master_name} over SSH "
            f"({why}): a key made here (it stays here) and a certificate the master signs, in "
            f"{paths.dir}.")


def _fleet_tls(settings) -> int:
    """Mutual TLS: the fleet CA and the master's certificate on the master; on a member, its
    certificate signed by the master over SSH (when it has none good for 30 days more)."""
    import asyncio

    from rosnet_tui.core.ros import fleet_tls, pairing

    paths = fleet_tls.tls_paths(default_config_dir())
    try:
        if settings.is_master:
            for what in pairing.prepare_master(settings, paths):
                print(f"Made {what}.")
            return EXIT_OK
        why = pairing.needs_pairing(settings, paths)
        if why is None:
            return EXIT_OK
        print(f"Pairing with the master ({why}):")
        res = asyncio.run(pairing.pair_over_ssh(settings, paths, options_for(settings.relay)))
    except (fleet_tls.TlsError, OSError) as exc:
        say(f"rosnet-tui: {exc}")
        return EXIT_FAIL
    if res.ok:
        print(f"  {res.detail} ({res.seconds:.1f} s).")
        return EXIT_OK
    say(f"rosnet-tui: pairing failed: {res.detail}\n  Without SSH to the master: "
        "`rosnet-tui ros pair --print-request` here, paste it into `rosnet-tui ros pair --sign` "
        "on the master, and what that prints into `rosnet-tui ros pair --install` here.")
    return EXIT_FAIL
