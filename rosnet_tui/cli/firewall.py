"""`rosnet-tui firewall apply|show|undo`: ROS 1, only the peers reach the forwarded ports.

The table is rosnet_tui.core.exposure.firewall's (`table inet rosnet_tui`, nothing else touched). Like the
hosts writer: a preview first, then the change through sudo when this user is not root (our own
writer re-run under this very Python, with the digest of the previewed ruleset), ONE `nft -f`
transaction, and an undo journal entry (`rosnet-tui undo` reverses it).

The SSH session that runs `apply` is never locked out: its address is read here, on the user's
side (sudo's env_reset drops SSH_CONNECTION), named in the preview and handed to the privileged
re-run with --session-ip, so the digest covers it.
"""

from __future__ import annotations

import argparse
import ipaddress
import sys
from pathlib import Path

from rosnet_tui.cli.common import (
    EXIT_FAIL,
    EXIT_OK,
    EXIT_USAGE,
    add_config_option,
    add_state_dir_option,
    config_path,
    say,
    state_dir_of,
)
from rosnet_tui.cli.writing import (
    command_line,
    confirm,
    load_settings_for,
    paths_of,
    report_settings_problems,
    rerun_checks,
    run_as_root,
)
from rosnet_tui.core import affected
from rosnet_tui.core.config.settings_model import PROFILES, Settings
from rosnet_tui.core.exposure import firewall as fw
from rosnet_tui.core.files import privilege
from rosnet_tui.core.ssh import origin


def _common(p: argparse.ArgumentParser) -> None:
    add_config_option(p)
    add_state_dir_option(p, "where the undo journal lives")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("firewall", help="ROS 1: let only the peers reach the forwarded ports",
                       description="An nftables table of rosnet-tui's own (table inet "
                                   "rosnet_tui): on the forwarded TCP ports (22, the ROS range, "
                                   "the master's port) only the peers' addresses, this machine's "
                                   "LAN, [firewall] allow (SSH), the SSH session that applies it "
                                   "(SSH), loopback and established traffic get in. No other "
                                   "table is touched.")
    p.set_defaults(func=lambda a: (p.print_help(sys.stderr), EXIT_USAGE)[1])
    fs = p.add_subparsers(dest="firewall_command", metavar="ACTION", parser_class=type(p))

    a = fs.add_parser("apply", help="load the table (preview first; through sudo if needed)")
    a.add_argument("--profile", choices=PROFILES, default=None,
                   help="whose addresses to allow: the peers' public IPs (remote) or their LAN "
                        "addresses (office, portable); default: this.profile")
    _common(a)
    a.add_argument("--dry-run", action="store_true", help="show the ruleset, change nothing")
    a.add_argument("--yes", "-y", action="store_true",
                   help="load without asking (needed where there is no terminal)")
    a.add_argument("--expect-digest", metavar="SHA256", default=None,
                   help="refuse unless the ruleset is still the one previewed (used with sudo)")
    a.add_argument("--no-checks", action="store_true",
                   help="do not re-run linux.firewall afterwards")
    a.add_argument("--session-ip", metavar="ADDR", default=None,
                   help="the SSH session to keep in on SSH until the next apply (default: the "
                        "first field of SSH_CONNECTION or SSH_CLIENT; under sudo, the shell's "
                        "that ran it; else the terminal's login record); 'none': keep none")
    a.add_argument("--session-port", metavar="PORT", type=int, default=fw.SSH_PORT,
                   help="the sshd port of that session (default: 22)")
    a.set_defaults(func=run_apply)

    s = fs.add_parser("show", help="the ruleset for the settings, and what is loaded now")
    s.add_argument("--profile", choices=PROFILES, default=None)
    _common(s)
    s.set_defaults(func=run_show)

    u = fs.add_parser("undo", help="remove our table (journaled: `rosnet-tui undo` loads it "
                                   "again)")
    _common(u)
    u.add_argument("--yes", "-y", action="store_true",
                   help="remove without asking (needed where there is no terminal)")
    u.add_argument("--no-checks", action="store_true",
                   help="do not re-run linux.firewall afterwards")
    u.set_defaults(func=run_undo)


def _settings(args: argparse.Namespace) -> Settings | None:
    settings = load_settings_for(args)
    if settings is None:
        return None
    if settings.ros2:
        say("rosnet-tui: the firewall is for ROS 1 (the ROS range forwarded); with ROS 2 only "
            "the Zenoh port is forwarded and mutual TLS guards it ([ros] security = \"mtls\")")
        return None
    return settings


def _abs(p: Path) -> str:
    return str(Path(p).expanduser().absolute())


def _sudo_undo(args: argparse.Namespace) -> list[str]:
    return privilege.sudo_argv(["--config", _abs(config_path(args)), "firewall", "undo",
                                "--yes", "--state-dir", _abs(state_dir_of(args)),
                                "--no-checks"])


def _session(args: argparse.Namespace) -> tuple[origin.Session | None, bool]:
    """(the session --session-ip names, whether to detect one instead); raises
    origin.SessionError for a bad value."""
    value = args.session_ip
    if value is None:
        return None, True
    if value.strip().lower() == "none":
        return None, False
    try:
        addr = ipaddress.ip_address(value.strip())
    except ValueError:
        raise origin.SessionError(f"--session-ip '{value[:40]}' is not an IP address (or 'none')"
                              ) from None
    if not 0 < args.session_port < 65536:
        raise origin.SessionError(f"--session-port {args.session_port} is not a port (1-65535)")
    return origin.Session(str(addr), args.session_port, "--session-ip"), False


def _refuse_session(exc: origin.SessionError) -> int:
    say(f"rosnet-tui: nothing was changed: {exc}. The table would lock this session out once it "
        "drops. Name its address with --session-ip ADDR (or 'none' when this is no SSH "
        "session), or add it to [firewall] allow in the settings.")
    return EXIT_USAGE


def run_apply(args: argparse.Namespace) -> int:
    settings = _settings(args)
    if settings is None:
        return EXIT_USAGE
    profile = args.profile or settings.this.profile
    try:
        session, detect = _session(args)
        pv = fw.preview(settings, profile, session=session, detect=detect)
    except origin.SessionError as exc:
        return _refuse_session(exc)
    except fw.FirewallSettingsError as exc:
        return report_settings_problems(exc)
    except fw.FirewallError as exc:
        say(f"rosnet-tui: {exc}")
        return EXIT_FAIL
    if args.expect_digest and pv.digest != args.expect_digest:
        say("rosnet-tui: the ruleset is not the one previewed any more (the settings changed); "
            "nothing was changed. Look at the new preview and apply again.")
        return EXIT_FAIL
    if not fw.wanted(settings):
        print(f"note: [ros] security is \"{settings.ros.security}\" in the settings; the "
              "table is loaded because you asked (the check keeps reporting the setting)")
    print(f"Firewall for {settings.this.name or 'this component'}: table {fw.TABLE}.")
    for line in pv.who:
        print(line)
    for note in pv.notes[len(pv.who):]:
        print(f"note: {note}")
    if pv.readable and not pv.changed:
        print(f"The table {fw.TABLE} is already loaded exactly so: nothing to change.")
        return EXIT_OK
    sys.stdout.write(pv.diff() if pv.readable else pv.ruleset)
    sys.stdout.flush()
    kept = (f"; this SSH session, {pv.session.address}, keeps SSH"
            if pv.session is not None and not pv.session_in else "")
    stop = confirm(args, f"Load this table (one nft transaction{kept})?",
                   dry_run="nothing was changed")
    if stop is not None:
        return stop
    if not privilege.is_root():
        cmd = fw.apply_command(config=config_path(args), profile=profile, digest=pv.digest,
                               state_dir=state_dir_of(args), session=pv.session)
        rc = run_as_root(cmd, f"loading the table {fw.TABLE}", "firewall apply")
    else:
        try:
            entry = fw.apply(pv, state_dir=state_dir_of(args))
        except fw.FirewallError as exc:
            say(f"rosnet-tui: {exc}")
            return EXIT_FAIL
        rc = EXIT_OK
        if entry is None:
            print(f"The table {fw.TABLE} was already loaded exactly so.")
        else:
            print(f"Loaded the table {fw.TABLE} (journal #{entry}). Undo with: "
                  f"{command_line(args, 'undo')}")
    if rc == EXIT_OK and not args.no_checks:
        rerun_checks(affected.FIREWALL, settings, paths_of(args))
    return rc


def run_show(args: argparse.Namespace) -> int:
    settings = load_settings_for(args)
    if settings is None:
        return EXIT_USAGE
    profile = args.profile or settings.this.profile
    print(f"[ros] security: {settings.ros.security}"
          + ("" if fw.wanted(settings) else " (no firewall wanted by the settings)"))
    if settings.ros2:
        print("ROS 2: the firewall is not used (mutual TLS guards the Zenoh port).")
        return EXIT_OK
    try:
        try:
            session = origin.detect_session()
        except origin.SessionError as exc:
            print(f"note: {exc}")
            session = None
        adm, session_in = fw.admission(settings, profile, session)
    except fw.FirewallSettingsError as exc:
        return report_settings_problems(exc)
    print(f"Allowed on TCP {', '.join(fw.forwarded_ports(settings))} ({profile} profile):")
    for p in settings.peers:
        print(f"  {fw.peer_address(settings, p.name, profile):<15} {p.name}")
    for line in fw.who_gets_in(settings, adm, profile, session, session_in)[2:]:
        print(line)
    opened = fw.open_ports(settings)
    if opened:
        print(f"Left open to anyone: TCP {', '.join(map(str, opened))} (probe.port: only "
              "rosnet-tui's own listener answers there, during router.port_open)")
    print("\nThe table rosnet-tui loads:")
    ruleset = fw.render_ruleset(settings, adm)
    sys.stdout.write(ruleset)
    try:
        now = fw.current_ruleset()
    except fw.FirewallError as exc:
        print(f"\nThe table loaded now: not known ({exc}).")
        return EXIT_OK
    if now is None:
        print(f"\nNo table {fw.TABLE} is loaded. To load it: rosnet-tui firewall apply")
    elif fw.normalize(now) == fw.normalize(ruleset):
        print(f"\nThe table {fw.TABLE} is loaded, exactly so.")
    else:
        print(f"\nThe table {fw.TABLE} loaded now differs:")
        sys.stdout.write(fw.FirewallPreview(ruleset, now, adm.peers).diff())
    return EXIT_OK


def run_undo(args: argparse.Namespace) -> int:
    settings = load_settings_for(args)
    readable = True
    try:
        now = fw.current_ruleset()
    except fw.FirewallError:
        now, readable = None, False
    if readable and now is None:
        print(f"No table {fw.TABLE} is loaded: nothing to remove.")
        return EXIT_OK
    print(f"Removes the table {fw.TABLE} (and nothing else)"
          + (":" if now else "; its content is not shown without root."))
    if now:
        sys.stdout.write(now)
    stop = confirm(args, f"Remove the table {fw.TABLE}?")
    if stop is not None:
        return stop
    if not privilege.is_root():
        rc = run_as_root(_sudo_undo(args), f"removing the table {fw.TABLE}", "firewall undo")
    else:
        try:
            entry = fw.remove(state_dir=state_dir_of(args))
        except fw.FirewallError as exc:
            say(f"rosnet-tui: {exc}")
            return EXIT_FAIL
        rc = EXIT_OK
        print(f"Removed the table {fw.TABLE}" + (f" (journal #{entry}; `{command_line(args, 'undo')}` "
                                                 "loads it again)." if entry else "."))
    if rc == EXIT_OK and not args.no_checks:
        rerun_checks(affected.FIREWALL, settings, paths_of(args))
    return rc
