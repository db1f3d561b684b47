"""`rosnet-tui sync`: keep every component's names right when public addresses change.

``sync`` runs the service in the foreground (logs on stderr, stops cleanly on SIGTERM/Ctrl-C);
``sync --once`` does one round; ``sync status`` shows what it saw and did; ``sync
install-service`` writes a systemd unit that runs it at boot.
"""

from __future__ import annotations

import argparse
import difflib
import json
import logging
import pwd
import sys
import time
from pathlib import Path

from rosnet_tui.cli.common import (
    EXIT_FAIL,
    EXIT_OK,
    EXIT_USAGE,
    add_config_option,
    add_state_dir_option,
    config_path,
    interactive,
    number_in,
    say,
    state_dir_of,
    state_dir_problem,
)
from rosnet_tui.cli.units import exec_lines, install_unit, restart_lines
from rosnet_tui.cli.writing import ask, confirm
from rosnet_tui.core.config.paths import Paths, xdg_config_home
from rosnet_tui.core.config.settings_model import SettingsError
from rosnet_tui.core.files import privilege

UNIT_NAME = "rosnet-tui-sync.service"

_DESCRIPTION = (
    "Publish this component's addresses (local IP, public IP) to a shared record store and "
    "follow the peers' records: when a peer's address changes, rewrite this component's hosts "
    "set and, under ROS 1, ROS_MASTER_URI (the safe writer: our block only, atomic, with a "
    "backup), then run the affected checks again. It also renews the leases of the forwards "
    "`router map` made and, under ROS 2's mutual TLS, this component's fleet certificate before "
    "it expires. The store is set in the settings' [sync] table: a shared folder (Syncthing, "
    "Dropbox, NFS) or a DNS zone taking TSIG-signed dynamic updates.")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("sync", help="keep hosts entries (and ROS 1's ROS_MASTER_URI) right when "
                                    "public IPs change; renew forwards and certificates (a "
                                    "service)",
                       description=_DESCRIPTION,
                       epilog="Exit codes: 0 stopped cleanly (or --once went well), 1 a round "
                              "failed, 2 usage or settings error.")
    add_config_option(p)
    _service_options(p)
    p.add_argument("--once", action="store_true",
                   help="one round (publish, read, apply, check), then exit (for cron or tests)")
    p.add_argument("--unmap-on-stop", action="store_true",
                   help="when stopped, remove the forwards `rosnet-tui router map` made on the "
                        "modem (they are renewed while the service runs)")
    p.add_argument("--interval", type=number_in(1, 86400), metavar="S", default=None,
                   help="public-IP poll interval in seconds, 1-86400 (default: "
                        "sync.interval_s, 60)")
    p.add_argument("-v", "--verbose", action="store_true", help="log every step (debug)")
    p.add_argument("-q", "--quiet", action="store_true", help="log only warnings and errors")
    p.set_defaults(func=run_service)
    ss = p.add_subparsers(dest="sync_command", metavar="ACTION", parser_class=type(p))

    st = ss.add_parser("status", help="show each component's last record, the last change and "
                                      "the last error",
                       description="What the sync service of this component last saw and did "
                                   "(read from its state dir; the service need not run).")
    st.add_argument("--json", action="store_true", help="print the status as JSON")
    add_state_dir_option(st, "state dir of the service")
    st.set_defaults(func=run_status)

    key = ss.add_parser("key", help="print this component's sync key: the line each peer puts "
                                    "in this component's [[peer]] table",
                        description="A record in the store counts only when signed by its "
                                    "component's own key (made here on first use, beside the "
                                    "settings file). Every peer pins the public half: copy the "
                                    "printed line into this component's [[peer]] table on each.")
    add_config_option(key)
    key.set_defaults(func=run_key)

    pin = ss.add_parser("pin", help="ask the peers for their sync keys over SSH and pin them in "
                                    "this component's settings",
                        description="For each peer (default: every peer with an ssh_user), run "
                                    "its own rosnet-tui's `sync key` over SSH (host key verified, "
                                    "as for the checks), show its key and fingerprint and the "
                                    "change to the settings, then write its sync_key (comments "
                                    "and layout kept). A key that differs from the one pinned is "
                                    "replaced only on an explicit yes (or --yes).",
                        epilog="Exit codes: 0 every peer's key is pinned, 1 some peer failed "
                               "(each says why), 2 usage or settings error.")
    add_config_option(pin)
    pin.add_argument("peers", nargs="*", metavar="PEER", help="the peers to ask (default: every "
                                                              "peer with an ssh_user)")
    pin.add_argument("--yes", "-y", action="store_true",
                     help="write without asking, a changed key too (scripts)")
    pin.add_argument("--dry-run", action="store_true", help="ask the peers and show the change; "
                                                             "write nothing")
    pin.add_argument("--timeout", type=number_in(1, 120), metavar="S", default=None,
                     help="seconds for each peer, 1-120 (default 10)")
    pin.set_defaults(func=run_pin)

    ins = ss.add_parser("install-service", help="write a systemd unit that runs the sync service",
                        description="Write a systemd unit (Restart=on-failure) that runs "
                                    "'rosnet-tui sync' with this component's settings. It is shown "
                                    "before it is written. Writing /etc/hosts needs root, so the "
                                    "system unit is the usual choice; --user writes a user unit.")
    add_config_option(ins)
    ins.add_argument("--user", action="store_true",
                     help="a user unit in ~/.config/systemd/user (it can only write files this "
                          "user may write)")
    ins.add_argument("--yes", "-y", action="store_true",
                     help="write without asking (needed where there is no terminal)")
    ins.add_argument("--dry-run", action="store_true", help="show the unit, write nothing")
    ins.add_argument("--unit-dir", metavar="DIR", type=Path, default=None,
                     help="write the unit into DIR instead of the systemd folder")
    _service_options(ins)
    ins.set_defaults(func=run_install)


def _service_options(p: argparse.ArgumentParser) -> None:
    add_state_dir_option(p, "where status, journal and backups go")
    p.add_argument("--hosts-file", metavar="PATH", type=Path, default=None,
                   help="hosts file to keep right (default: /etc/hosts)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--bashrc", metavar="PATH", type=Path, default=None,
                   help="shell file for the ROS_MASTER_URI block (default: ~/.bashrc)")
    g.add_argument("--no-bashrc", action="store_true", help="leave the shell files alone")
    p.add_argument("--no-checks", action="store_true",
                   help="do not run the affected checks after a change")
    p.add_argument("--no-save-settings", action="store_true",
                   help="do not keep the learned addresses in the settings file")


def _paths(args: argparse.Namespace) -> Paths:
    """The service's files: --config, --state-dir, --hosts-file, --bashrc (its checks read the
    everyday ~/.bashrc under --no-bashrc)."""
    files = {}
    if args.hosts_file:
        files["hosts_path"] = Path(args.hosts_file).expanduser().absolute()
    if getattr(args, "bashrc", None) and not getattr(args, "no_bashrc", False):
        files["bashrc_path"] = Path(args.bashrc).expanduser().absolute()
    return Paths(config_path=config_path(args), state_dir=state_dir_of(args), **files)


def _setup_logging(args: argparse.Namespace) -> None:
    logger = logging.getLogger("rosnet_tui.sync")
    logger.handlers.clear()
    h = logging.StreamHandler(sys.stderr)
    h.setFormatter(logging.Formatter("%(asctime)s %(levelname)-7s %(message)s",
                                     datefmt="%Y-%m-%d %H:%M:%S"))
    logger.addHandler(h)
    logger.propagate = False
    logger.setLevel(logging.DEBUG if args.verbose else
                    logging.WARNING if args.quiet else logging.INFO)


def run_key(args: argparse.Namespace) -> int:
    """`sync key`: this component's public sync key, as a peer's settings line."""
    from rosnet_tui.core.sync.signing import key_path, load_or_make_key, public_text

    path = key_path(config_path(args))
    try:
        key = load_or_make_key(path)
    except (OSError, ValueError) as exc:
        say(f"rosnet-tui: cannot use the sync key {path}: {exc}")
        return EXIT_FAIL
    print(f'sync_key = "{public_text(key)}"')
    say(f"(the public half of {path}; put that line in this component's [[peer]] table on "
        "every peer)")
    return EXIT_OK


def run_pin(args: argparse.Namespace) -> int:
    """`sync pin`: the peers' sync keys, asked over SSH, pinned in the settings."""
    import asyncio

    from rosnet_tui.core.saved.settings import parse_settings
    from rosnet_tui.core.ssh.options import options_for
    from rosnet_tui.core.sync.pin import (
        PIN_TIMEOUT_S,
        ask_peers,
        choose_peers,
        pinned_text,
        read_for_pin,
        write_pins,
    )

    path = config_path(args).expanduser().absolute()
    try:
        before = read_for_pin(path)
        settings = parse_settings(before, path)
        peers, failed = choose_peers(settings, list(args.peers))
    except SettingsError as exc:
        say(f"rosnet-tui: {exc}")
        return EXIT_USAGE
    except ValueError as exc:
        say(f"rosnet-tui sync pin: {exc}")
        return EXIT_USAGE
    if not peers and not failed:
        say("rosnet-tui sync pin: no peer has an ssh_user in the settings: name one, or copy "
            "the line `rosnet-tui sync key` prints on it")
        return EXIT_USAGE
    print(f"Asking {len(peers)} peer(s) for their sync keys over SSH ...")
    got = asyncio.run(ask_peers(peers, options_for(settings.relay),
                                timeout=args.timeout or PIN_TIMEOUT_S))
    answers = sorted(got + failed, key=lambda a: a.name.lower())
    words = {"same": "already pinned", "new": "not pinned here yet: to pin",
             "changed": "KEY CHANGED"}
    for a in answers:
        if a.error:
            print(f"  {a.name}: failed: {a.error}")
        else:
            print(f"  {a.name}: {a.key} ({a.fingerprint}): {words[a.state]}")
    changed = [a for a in answers if a.state == "changed"]
    for a in changed:
        print(f"\nWARNING: {a.name}'s sync key is not the one pinned here.\n"
              f"  pinned: {a.pinned} ({a.pinned_fingerprint})\n"
              f"  now:    {a.key} ({a.fingerprint})\n"
              f"  Its key file may have been made again (a reinstall), or someone else answers "
              f"as {a.name}. Replace it only when you know which.")
    todo = {a.name: a.key for a in answers if a.state in ("new", "changed")}
    if todo:
        try:
            after = pinned_text(before, todo)
        except SettingsError as exc:
            say(f"rosnet-tui: {exc}")
            return EXIT_USAGE
        print()
        sys.stdout.writelines(difflib.unified_diff(before.splitlines(True),
                                                   after.splitlines(True),
                                                   f"{path} (now)", f"{path} (after)"))
    if args.dry_run:
        print("Dry run: nothing was written.")
        return EXIT_OK if all(a.state == "same" for a in answers) else EXIT_FAIL
    for a in changed:
        if args.yes:
            print(f"--yes: replacing {a.name}'s pinned key.")
        elif interactive() and ask(f"Replace the pinned sync key of {a.name} (KEY CHANGED)?"):
            continue
        else:
            del todo[a.name]
            a.error = "its key changed and was not replaced (say yes, or run with --yes)"
            print(f"Not replacing {a.name}'s pinned key.")
    if any(a.state == "new" for a in answers) and not args.yes:
        stop = confirm(args, f"Pin these keys in {path}?", cancelled="Nothing was written.",
                       no_terminal="rosnet-tui: not writing without a terminal to ask on; check "
                                   "the keys above, then run the same command with --yes")
        if stop is not None:
            return stop
    if todo:
        try:
            write_pins(path, before, todo)
        except SettingsError as exc:
            say(f"rosnet-tui: {exc}")
            return EXIT_FAIL
        except OSError as exc:
            say(f"rosnet-tui: cannot write {path}: {exc.strerror}")
            return EXIT_FAIL
        print(f"Pinned the sync key of {', '.join(todo)} in {path}.")
    bad = [a for a in answers if a.error]
    if bad:
        say(f"rosnet-tui sync pin: not pinned: {', '.join(a.name for a in bad)} (why: above)")
        return EXIT_FAIL
    print("Every asked peer's sync key is pinned here.")
    return EXIT_OK


# --------------------------------------------------------------------------- the service
def run_service(args: argparse.Namespace) -> int:
    from rosnet_tui.core.sync.loop import install_signal_handlers
    from rosnet_tui.core.sync.outcome import SyncError
    from rosnet_tui.core.sync.service import SyncService

    _setup_logging(args)
    bad_dir = state_dir_problem(state_dir_of(args))
    if bad_dir:
        say(f"rosnet-tui sync: {bad_dir}")
        return EXIT_USAGE
    try:
        service = SyncService(_paths(args), write_bashrc=not getattr(args, "no_bashrc", False),
                              run_checks=not args.no_checks,
                              interval_s=args.interval, save_learned=not args.no_save_settings,
                              unmap_on_stop=args.unmap_on_stop)
    except SyncError as exc:
        say(f"rosnet-tui sync: {exc}")
        return EXIT_USAGE
    try:
        if args.once:
            result = service.run_once()
            if not result.ok:
                for part, msg in result.errors.items():
                    say(f"rosnet-tui sync: {part}: {msg}")
            return EXIT_OK if result.ok else EXIT_FAIL
        install_signal_handlers(service)
        return service.run()
    except SyncError as exc:
        say(f"rosnet-tui sync: {exc}")
        return EXIT_FAIL


# --------------------------------------------------------------------------- status
def run_status(args: argparse.Namespace) -> int:
    from rosnet_tui.core.sync.status import load_status, render_status, status_path, with_ages

    sd = state_dir_of(args)
    status = load_status(sd)
    if status is None:
        msg = (f"sync has not run on this component yet (no {status_path(sd)}); start it with "
               "'rosnet-tui sync' or 'rosnet-tui sync install-service'")
        if args.json:
            print(json.dumps({"status": None, "message": msg}))
        else:
            print(msg)
        return EXIT_FAIL
    now = time.time()
    if args.json:
        print(json.dumps(with_ages(status, now), indent=2, sort_keys=True))
    else:
        for line in render_status(status, now):
            print(line)
    return EXIT_FAIL if status.get("errors") else EXIT_OK


# --------------------------------------------------------------------------- install-service
def _owner_home(path: Path) -> Path | None:
    """HOME of the user owning *path* (the settings file says whose component this is)."""
    try:
        return Path(pwd.getpwuid(path.stat().st_uid).pw_dir)
    except (OSError, KeyError):
        return None


def unit_text(args: argparse.Namespace, *, user: bool) -> tuple[str, list[str]]:
    """The unit file's text and the notes to show with it."""
    cfg = config_path(args).expanduser().absolute()
    notes: list[str] = []
    # This very install by its absolute path: systemd starts it with a clean environment.
    argv = privilege.self_argv(["--config", str(cfg), "sync"])
    if args.state_dir:
        argv += ["--state-dir", str(state_dir_of(args))]
    elif not user:
        # The settings owner's state dir (root hands what it writes there back to that user), so
        # 'rosnet-tui sync status' and 'rosnet-tui undo' as that user find it.
        home = _owner_home(cfg)
        sd = (home / ".local" / "state" / "rosnet-tui") if home and home != Path("/root") \
            else Path("/var/lib/rosnet-tui")
        argv += ["--state-dir", str(sd)]
    if args.hosts_file:
        argv += ["--hosts-file", str(Path(args.hosts_file).expanduser().absolute())]
    if args.no_bashrc:
        argv.append("--no-bashrc")
    else:
        bashrc = Path(args.bashrc).expanduser().absolute() if args.bashrc else None
        if bashrc is None:
            home = Path.home() if user else (_owner_home(cfg) or Path.home())
            bashrc = home / ".bashrc"
        argv += ["--bashrc", str(bashrc)]
    if args.no_checks:
        argv.append("--no-checks")
    if args.no_save_settings:
        argv.append("--no-save-settings")
    if not cfg.exists():
        notes.append(f"the settings file {cfg} does not exist yet: the service will not start "
                     "until it does (run 'rosnet-tui' first)")
    if user and not args.hosts_file:
        notes.append("a user service cannot write /etc/hosts: the hosts set will fail to apply "
                     "(use the system unit, without --user)")
    lines = [
        "# Written by 'rosnet-tui sync install-service'.",
        "[Unit]",
        "Description=rosnet-tui address sync (hosts entries and ROS_MASTER_URI follow public IP "
        "changes)",
        "Wants=network-online.target",
        "After=network-online.target",
        "",
        "[Service]",
        "Type=simple",
        *exec_lines(argv),
        *restart_lines("on-failure", 10),
    ]
    lines += ["", "[Install]", f"WantedBy={'default.target' if user else 'multi-user.target'}", ""]
    return "\n".join(lines), notes


def sudo_install_argv(args: argparse.Namespace) -> list[str]:
    """The sudo command that writes this same unit as root.

    Everything that depends on who runs it is spelled out: this install's interpreter by its
    absolute path (sudo's secure_path has no ~/.local/bin) and the settings file (under sudo ~ is
    root's home); the state dir and the shell file follow the settings file's owner, as here.
    """
    a = ["--config", str(config_path(args).expanduser().absolute()), "sync", "install-service"]
    if args.unit_dir:
        a += ["--unit-dir", str(_unit_dir(args))]
    if args.state_dir:
        a += ["--state-dir", str(state_dir_of(args))]
    if args.hosts_file:
        a += ["--hosts-file", str(Path(args.hosts_file).expanduser().absolute())]
    if args.no_bashrc:
        a.append("--no-bashrc")
    elif args.bashrc:
        a += ["--bashrc", str(Path(args.bashrc).expanduser().absolute())]
    for flag in ("no_checks", "no_save_settings", "yes"):
        if getattr(args, flag):
            a.append("--" + flag.replace("_", "-"))
    return privilege.sudo_argv(a)


def _unit_dir(args: argparse.Namespace) -> Path:
    if args.unit_dir:
        return Path(args.unit_dir).expanduser().absolute()
    if args.user:
        return xdg_config_home() / "systemd" / "user"
    return Path("/etc/systemd/system")


def run_install(args: argparse.Namespace) -> int:
    text, notes = unit_text(args, user=args.user)
    path = _unit_dir(args) / UNIT_NAME

    def denied() -> str:
        if args.user:
            return f"rosnet-tui: this user may not write {path}"
        return (f"rosnet-tui: this user may not write {path}; run it with sudo: "
                f"{privilege.format_command(sudo_install_argv(args))}")

    return install_unit(args, path, text, ctl="systemctl --user" if args.user else "systemctl",
                        notes=notes, denied=denied)
