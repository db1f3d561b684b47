"""`rosnet-tui router mappings|map|unmap`: the forward this component needs, made by the modem
itself where it allows it (UPnP IGD, PCP, NAT-PMP), with consent, recorded for undo.

Exit codes: 0 done (or nothing to do), 1 the modem refused or did not answer (its own error
explained in words; nothing is left half-done), 2 bad usage or settings.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

from rosnet_tui.cli.common import (
    EXIT_FAIL,
    EXIT_OK,
    EXIT_USAGE,
    add_config_option,
    add_state_dir_option,
    load_settings_or_say,
    say,
    state_dir_of,
)
from rosnet_tui.cli.writing import command_line, confirm, paths_of, rerun_checks
from rosnet_tui.core import affected
from rosnet_tui.core.config.settings_model import Settings
from rosnet_tui.core.upnp import forwards as fw
from rosnet_tui.core.upnp import journal
from rosnet_tui.core.upnp.modem import LEASE_MAX_S, LEASE_MIN_S, Modem, find_modem
from rosnet_tui.core.upnp.wire import ModemError, label

PROTOCOL_CHOICES = ("auto", "upnp", "pcp", "natpmp")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("router", help="let the modem forward this component's port itself (UPnP "
                                      "IGD, NAT-PMP, PCP)",
                       description="Ask the modem (the default gateway) over UPnP IGD, PCP or "
                                   "NAT-PMP: what it forwards, and to forward the port this "
                                   "component needs (ROS 2: the master's zenoh_port). Only with "
                                   "consent, only to this machine, only ports from 1024, always "
                                   "with a lease; undo removes it.",
                       epilog="Exit codes: 0 done, 1 the modem refused or did not answer, "
                              "2 usage or settings error.")
    p.set_defaults(func=lambda a: (p.print_help(sys.stderr), EXIT_USAGE)[1])
    rs = p.add_subparsers(dest="router_command", metavar="ACTION", parser_class=type(p))

    m = rs.add_parser("mappings", help="what the modem says and the forwards it holds (ours "
                                       "marked)")
    _common(m)
    m.add_argument("--json", action="store_true", help="print it as JSON")
    m.set_defaults(func=run_mappings)

    a = rs.add_parser("map", help="forward what the settings call for (asks first)")
    _common(a)
    a.add_argument("--protocol", choices=PROTOCOL_CHOICES, default="auto",
                   help="which protocol to ask with (default: UPnP IGD, else PCP, else NAT-PMP)")
    a.add_argument("--dry-run", action="store_true", help="show what would be asked, ask nothing")
    a.add_argument("--yes", "-y", action="store_true",
                   help="ask the modem without asking you (needed where there is no terminal)")
    a.add_argument("--lease", type=int, metavar="S", default=fw.LEASE_S,
                   help=f"lease of the forward in seconds ({LEASE_MIN_S}-{LEASE_MAX_S}; default "
                        f"{fw.LEASE_S}); the sync service renews it")
    a.add_argument("--no-test-port", action="store_true",
                   help="do not forward the test port for the checks")
    a.add_argument("--no-checks", action="store_true",
                   help="do not re-run router.upnp and router.port_open afterwards")
    a.set_defaults(func=run_map)

    u = rs.add_parser("unmap", help="remove the forwards rosnet-tui made (never others)")
    _common(u)
    u.add_argument("--yes", "-y", action="store_true",
                   help="remove without asking (needed where there is no terminal)")
    u.add_argument("--force", action="store_true",
                   help="forget forwards whose modem is gone or is another one (their lease "
                        "ends them)")
    u.set_defaults(func=run_unmap)


def _common(p: argparse.ArgumentParser) -> None:
    add_config_option(p)
    p.add_argument("--timeout", type=float, metavar="S", default=None,
                   help="seconds to find the modem (default: checks.timeout_s, 3)")
    add_state_dir_option(p, "where the undo journal lives")


def _timeout(args: argparse.Namespace, settings: Settings) -> float | None:
    t = args.timeout if args.timeout is not None else float(settings.checks.timeout_s)
    if not 0.5 <= t <= 60:
        say("rosnet-tui router: --timeout must be between 0.5 and 60 seconds")
        return None
    return t


def _settings_and_timeout(args: argparse.Namespace) -> tuple[Settings, float] | None:
    """The settings and the modem's timeout, or None when either is refused (said on stderr)."""
    settings = load_settings_or_say(args)
    timeout = None if settings is None else _timeout(args, settings)
    return None if settings is None or timeout is None else (settings, timeout)


def _find(timeout: float) -> tuple[Modem | None, list[str]]:
    """The modem over every protocol (each one tells something: IGD and NAT-PMP its address)."""
    notes: list[str] = []
    return find_modem(timeout, notes=notes), notes


def _no_modem(notes: list[str]) -> None:
    say("rosnet-tui: no modem answered UPnP IGD, PCP or NAT-PMP (tried the default gateway):")
    for n in notes:
        say(f"  {n}")
    say("Forward the port by hand in the modem's web page (see the Router step), or switch "
        "UPnP / NAT-PMP on there if it has them.")


NOT_ASKING = ("rosnet-tui: the modem is not asked without your consent, and there is no terminal "
              "to ask on: read the forwards above, then run the same command with --yes")
NOTHING_ASKED = "nothing was asked of the modem"


def _say_modem(modem: Modem) -> None:
    for line in fw.modem_lines(modem):
        print(line)


# --------------------------------------------------------------------------- mappings
def run_mappings(args: argparse.Namespace) -> int:
    got = _settings_and_timeout(args)
    if got is None:
        return EXIT_USAGE
    settings, timeout = got
    modem, notes = _find(timeout)
    sd = state_dir_of(args)
    if modem is None:
        if args.json:
            print(json.dumps({"modem": None, "tried": notes, "forwards": None}, indent=2))
        else:
            _no_modem(notes)
        return EXIT_FAIL
    recorded = fw.recorded_here(modem, sd)
    listed, why = None, ""
    if modem.can_list:
        try:
            listed = modem.forwards(time.monotonic() + max(timeout, 3.0))
        except ModemError as exc:
            why = str(exc)
    if args.json:
        rows = None if listed is None else [
            {**f.to_json(), "ours": fw.is_ours(f, modem, set(recorded))} for f in listed]
        print(json.dumps({"modem": {"gateway": modem.gateway, "protocols": modem.protocols,
                                    "external_ip": modem.external_ip, "mac": modem.mac,
                                    "local_ip": modem.local_ip,
                                    "wan": fw.wan_kind(modem.external_ip)},
                          "forwards": rows, "error": why or None,
                          "recorded": [{"protocol": m["protocol"], "port": m["port"],
                                        "via": m.get("via"), "lease_s": m.get("lease_s"),
                                        "renewed_at": m.get("renewed_at")}
                                       for m in recorded.values()]}, indent=2))
        return EXIT_OK if not why else EXIT_FAIL
    _say_modem(modem)
    if listed is None:
        print(f"  {why or label(modem.protocol) + ' cannot list what a modem forwards.'}")
        if recorded:
            print("Forwards rosnet-tui made on this modem:")
            for m in recorded.values():
                print(f"  * {m['protocol']} {m['port']} -> {m['internal_client']}:{m['port']} "
                      f"({m.get('via')}, lease {fw.lease_words(int(m.get('lease_s') or 0))})")
        return EXIT_OK if not why else EXIT_FAIL
    if not listed:
        print("The modem holds no forward.")
    else:
        print("Forwards the modem holds (* made by rosnet-tui for this machine):")
        for f in listed:
            mark = "*" if fw.is_ours(f, modem, set(recorded)) else " "
            lease = fw.lease_words(f.lease_s) if f.lease_s else "no expiry"
            print(f"  {mark} {f.protocol} {f.external_port} -> {f.internal_client}:"
                  f"{f.internal_port}  lease {lease}  '{f.description}'")
    return EXIT_OK


# --------------------------------------------------------------------------- map
def run_map(args: argparse.Namespace) -> int:
    settings = load_settings_or_say(args, complete=True)
    if settings is None:
        return EXIT_USAGE
    if not LEASE_MIN_S <= args.lease <= LEASE_MAX_S:
        say(f"rosnet-tui router map: --lease must be between {LEASE_MIN_S} and {LEASE_MAX_S} "
            "seconds (forwards are never made for ever)")
        return EXIT_USAGE
    timeout = _timeout(args, settings)
    if timeout is None:
        return EXIT_USAGE
    sd = state_dir_of(args)
    plan = fw.preview(settings, state_dir=sd, timeout=timeout, lease_s=args.lease,
                      test_port=not args.no_test_port, via=args.protocol)
    for line in plan.lines:
        print(line)
    if plan.blocked:
        if plan.modem is None and plan.need.forwards:
            _no_modem(plan.notes)
            return EXIT_FAIL
        if not plan.need.forwards and not plan.need.refusal:
            print(plan.blocked)
            return EXIT_OK
        say(f"rosnet-tui: nothing was asked of the modem. {plan.blocked}")
        return EXIT_FAIL
    modem, via = plan.modem, plan.via
    assert modem is not None
    for w in plan.warnings:
        print(f"warning: {w}")
    stop = confirm(args, "Ask the modem for these forwards?", dry_run=NOTHING_ASKED,
                   cancelled=f"Cancelled: {NOTHING_ASKED}.", no_terminal=NOT_ASKING)
    if stop is not None:
        return stop
    try:
        result = fw.map_forwards(settings, modem, plan.need.forwards, state_dir=sd, via=via,
                                 timeout=max(timeout * 2, 5.0))
    except fw.MapRefused as exc:
        say(f"rosnet-tui: {exc.told()}")
        return EXIT_FAIL
    except ModemError as exc:
        say(f"rosnet-tui: the modem did not give a usable answer, nothing was changed: {exc}")
        return EXIT_FAIL
    for w in result.warnings:
        print(f"warning: {w}")
    for m in result.made:
        print(f"Forwarded {m['protocol']} {m['port']} -> {m['internal_client']}:{m['port']} "
              f"({label(m['via'])}, lease {fw.lease_words(int(m['lease_s']))}).")
    for p in result.refreshed:
        print(f"Renewed the lease of TCP {p} (already forwarded by rosnet-tui).")
    if result.entry_id:
        print(f"Recorded as change #{result.entry_id}. Undo with: {command_line(args, 'undo')} "
              f"(or {command_line(args, 'router', 'unmap')}). The sync service renews the lease; "
              "so does running this again.")
    if not args.no_checks:
        rerun_checks(affected.FORWARD, settings, paths_of(args))
    return EXIT_OK


# --------------------------------------------------------------------------- unmap
def run_unmap(args: argparse.Namespace) -> int:
    got = _settings_and_timeout(args)
    if got is None:
        return EXIT_USAGE
    settings, timeout = got
    sd = state_dir_of(args)
    live = journal.live(sd)
    if not live:
        print("rosnet-tui made no forward that is still in place: nothing to remove.")
        return EXIT_OK
    print("Forwards rosnet-tui made (only these are removed):")
    for _e, m in live:
        print(f"  {journal.describe(m)}")
    stop = confirm(args, "Remove them from the modem?", cancelled=f"Cancelled: {NOTHING_ASKED}.",
                   no_terminal=NOT_ASKING)
    if stop is not None:
        return stop
    try:
        said = fw.unmap_ours(state_dir=sd, force=args.force, timeout=max(timeout * 2, 5.0))
    except journal.ForwardUndoError as exc:
        say(f"rosnet-tui: {exc}")
        return EXIT_FAIL
    for line in said:
        print(line)
    return EXIT_OK
