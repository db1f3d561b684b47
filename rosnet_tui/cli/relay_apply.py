"""`rosnet-tui relay apply`: on the master, set the relay up over SSH (its key made there, its
certificate signed by the fleet CA here, its router config and systemd unit written there), after
a preview and a question, in an undo entry."""

from __future__ import annotations

import argparse
import asyncio
import difflib
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
)
from rosnet_tui.cli.units import exec_lines, restart_lines
from rosnet_tui.cli.writing import command_line, confirm, load_settings_for
from rosnet_tui.core.config.paths import default_config_dir
from rosnet_tui.core.files.managed_text import ManagedFileError
from rosnet_tui.core.ros import fleet_tls
from rosnet_tui.core.ros import relay_apply as ra


def register(cmds: argparse._SubParsersAction) -> None:
    p = cmds.add_parser(
        "apply", help="on the master: set the relay up over SSH (its key, certificate, router "
                      "config and systemd unit)",
        description="Run on the master, after `rosnet-tui ros apply` made the fleet CA. Over SSH "
                    "to the relay ([relay] host, ssh_user, ssh_port; its host key must be in "
                    "known_hosts): the relay makes its own TLS key (it never leaves the relay), "
                    "the fleet CA here signs its certificate for the relay's name, and the "
                    "relay's router config and a systemd unit running `rosnet-tui relay serve` "
                    "are written there, and where systemd runs the unit is enabled and "
                    "(re)started (systemctl, as root or through sudo; otherwise the command "
                    "is shown). Shows everything first. `rosnet-tui undo` puts the "
                    "config and unit back (not the key and certificate).")
    add_config_option(p)
    p.add_argument("--yes", "-y", action="store_true", help="do it without asking")
    p.add_argument("--dry-run", action="store_true", help="show what would be done, do nothing")
    add_state_dir_option(p, "where the undo journal lives")
    p.add_argument("--unit-dir", metavar="DIR", type=Path, default=None,
                   help="the folder on the relay for the unit (default: /etc/systemd/system)")
    p.set_defaults(func=run_apply)


def unit_text(python: str, root: str, user: str, config: str) -> str:
    """The relay's systemd unit: `relay serve` with the relay's own install, as its user."""
    argv = [python, "-m", "rosnet_tui", "relay", "serve", "--router-config", config]
    return "\n".join([
        "# Written by 'rosnet-tui relay apply' on the master.",
        "[Unit]",
        "Description=rosnet-tui relay: the Zenoh router the fleet's routers dial (mutual TLS)",
        "Wants=network-online.target",
        "After=network-online.target",
        "",
        "[Service]",
        "Type=simple",
        f"User={user}",
        *exec_lines(argv, Path(root) if root else Path()),
        *restart_lines("always", 5),
        "",
        "[Install]",
        "WantedBy=multi-user.target",
        ""])


def _show(f: ra.RemoteFile) -> None:
    print(f"{f.what[0].upper()}{f.what[1:]}, {f.path} on the relay:")
    if f.old is None:
        for line in f.new.splitlines():
            print(f"  {line}")
    elif not f.changed:
        print("  (already there, exactly this content; nothing to write)")
    else:
        sys.stdout.writelines(difflib.unified_diff(
            f.old.splitlines(True), f.new.splitlines(True), f"{f.path} (now)",
            f"{f.path} (after)"))


def run_apply(args: argparse.Namespace) -> int:
    settings = load_settings_for(args)
    if settings is None:
        return EXIT_USAGE
    tls = fleet_tls.tls_paths(default_config_dir())
    why = ra.refusal(settings, tls)
    if why:
        say(f"rosnet-tui relay apply: {why}")
        return EXIT_USAGE
    unit_dir = (args.unit_dir or ra.UNIT_DIR)
    if not unit_dir.is_absolute():
        say(f"rosnet-tui relay apply: --unit-dir must be an absolute path on the relay, not "
            f"{unit_dir}")
        return EXIT_USAGE
    unit = unit_dir / ra.UNIT_NAME
    try:
        plan = asyncio.run(ra.plan(settings, tls, None, unit, unit_text))
    except ra.RelayApplyError as exc:
        say(f"rosnet-tui: {exc}")
        return EXIT_FAIL
    host = settings.relay.host
    peer = ra.relay_peer(settings)
    print(f"Relay {host} ({peer.ssh_user}@{host}:{peer.ssh_port}), set up from the master "
          f"{settings.this.name}:")
    if plan.cert_why is None:
        print(f"TLS: the relay's certificate is good: kept ({plan.cert_kept}).")
    else:
        print(f"TLS ({plan.cert_why}): the relay makes its own key there "
              f"({plan.look.node_key}; it never leaves the relay), the fleet CA here "
              f"signs its certificate for {host} ({plan.look.node_crt}), with the CA's "
              f"certificate ({plan.look.ca_crt}).")
    for f in plan.files:
        _show(f)
    if args.dry_run:
        print("Dry run: nothing was done on the relay.")
        if plan.look.systemd:
            print(f"Then, on the relay, the apply runs: {ra.start_line(plan, unit)}")
        return EXIT_OK
    if plan.changed:
        stop = confirm(args, f"Set the relay {host} up like this?",
                       cancelled="Nothing was done on the relay.",
                       no_terminal="rosnet-tui: not changing the relay without a terminal to "
                                   "ask on: read the above, then run the same command with "
                                   "--yes")
        if stop is not None:
            return stop
        try:
            done = asyncio.run(ra.apply(settings, tls, None, plan, state_dir_of(args)))
        except (ra.RelayApplyError, ManagedFileError) as exc:
            say(f"rosnet-tui: {exc}")
            return EXIT_FAIL
        for line in done:
            print(f"Done: {line}.")
        if any(f.changed for f in plan.files):
            print(f"Undo (the config and unit, not the key) with: {command_line(args, 'undo')}")
    else:
        print("The relay is already set up: nothing to change.")
    if not plan.look.systemd:
        print("No systemd runs on the relay: start its router there with "
              "`rosnet-tui relay serve`.")
        return EXIT_OK
    if not (plan.changed or args.yes):    # nobody said yes to this apply: only say it
        print(f"To run the relay's router, on the relay: {ra.start_line(plan, unit)}")
        return EXIT_OK
    ok, words = asyncio.run(ra.start_unit(settings, None, plan, unit))
    if ok:
        print(f"Done: {words}; its router runs as {ra.UNIT_NAME}.")
        return EXIT_OK
    line = ra.start_line(plan, unit)
    if ok is None:
        print(f"Not started: {words}. Run on the relay: {line}")
        return EXIT_OK
    say(f"rosnet-tui: {words}. Its files are written; run on the relay: {line}")
    return EXIT_FAIL
