"""`rosnet-tui ros pair`: this component's fleet certificate for ROS 2's mutual TLS.

- ``ros pair`` (a member): the master signs this member's request over SSH; ``--renew`` even when
  the certificate is still good.
- Without SSH to the master, by text: ``--print-request`` here, ``--sign`` on the master (reads
  the request on stdin or pasted), ``--install`` here (reads what ``--sign`` printed).
- On the master, ``ros pair`` makes the CA and the master's certificate (as ``ros apply`` does);
  ``--remove NAME`` takes a member out of the fleet: a new CA, and every other member re-paired.
  It says what will happen first and asks (``--yes`` for scripts, ``--dry-run`` to only look).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import sys

from rosnet_tui.cli.common import (
    EXIT_FAIL,
    EXIT_OK,
    EXIT_USAGE,
    add_config_option,
    config_path,
    say,
)
from rosnet_tui.cli.writing import confirm, load_settings_for
from rosnet_tui.core.config.paths import default_config_dir
from rosnet_tui.core.config.settings_model import SettingsError
from rosnet_tui.core.ros import fleet_tls, pair_access, pairing
from rosnet_tui.core.ros.fleet_tls import TlsError
from rosnet_tui.core.ssh.options import options_for


def register(rs: argparse._SubParsersAction) -> None:
    p = rs.add_parser("pair", help="ROS 2 mutual TLS: get this component's fleet certificate "
                                   "from the master (over SSH, or by pasting text)")
    add_config_option(p)
    g = p.add_mutually_exclusive_group()
    g.add_argument("--renew", action="store_true",
                   help="sign a new certificate even when the current one is still good")
    g.add_argument("--print-request", action="store_true",
                   help="print this component's certificate request (paste it into "
                        "`ros pair --sign` on the master)")
    g.add_argument("--sign", action="store_true",
                   help="on the master: read a member's request on stdin, print its "
                        "certificate (paste that into `ros pair --install` on the member)")
    g.add_argument("--install", action="store_true",
                   help="read what `ros pair --sign` printed on stdin and install it here")
    g.add_argument("--remove", metavar="NAME",
                   help="on the master: take member NAME out of the fleet (a new CA; the other "
                        "members are re-paired over SSH; NAME's pairing key removed); says what "
                        "will happen and asks first")
    g.add_argument("--admit", metavar="NAME",
                   help="on the master: let the SSH public key read on stdin pair member NAME "
                        "through a forced command in ~/.ssh/authorized_keys (it can only sign "
                        "NAME's request, no shell)")
    g.add_argument("--serve", metavar="NAME",
                   help="on the master, run by a member over SSH (the forced command): sign "
                        "NAME's request read on stdin, print one ROSNET_TLS line")
    p.add_argument("--yes", "-y", action="store_true",
                   help="with --sign or --remove: go ahead without asking (needed where there "
                        "is no terminal)")
    p.add_argument("--dry-run", action="store_true",
                   help="with --remove: show what would happen, change nothing")
    p.add_argument("--timeout", type=float, default=pairing.PAIR_TIMEOUT_S,
                   help="seconds for pairing over SSH (default: %(default)s)")
    p.set_defaults(func=run_pair)


def _read_stdin(what: str) -> str:
    if sys.stdin.isatty():
        print(f"Paste {what}, then press Ctrl-D:", file=sys.stderr)
    return sys.stdin.read(65536)


def run_pair(args: argparse.Namespace) -> int:
    settings = load_settings_for(args)
    if settings is None:
        return EXIT_USAGE
    if not settings.ros2:
        say("rosnet-tui: pairing is for ROS 2 ([ros] version = 2); ROS 1 uses the firewall")
        return EXIT_USAGE
    if args.dry_run and not args.remove:
        say("rosnet-tui: --dry-run goes with --remove (the other pairing actions show nothing "
            "first)")
        return EXIT_USAGE
    paths = fleet_tls.tls_paths(default_config_dir())
    try:
        if args.serve:
            return _serve(args, settings, paths)
        if args.sign:
            return _sign(args, settings, paths)
        if args.admit:
            return _admit(args, settings)
        if args.print_request:
            pem = fleet_tls.make_request(paths, settings.this.name)
            print(pem, end="")
            fp = fleet_tls.key_fingerprint(fleet_tls.load_request_key(pem))
            say(f"(this key's fingerprint, which `ros pair --sign` on the master shows: {fp})")
            return EXIT_OK
        if args.install:
            pems = fleet_tls.split_pems(_read_stdin("what `ros pair --sign` printed"))
            if len(pems) != 2:
                say("rosnet-tui: expected two certificates (this component's and the CA's), "
                    f"found {len(pems)}")
                return EXIT_USAGE
            cert, ca = pems
            summ = fleet_tls.install(paths, ca, cert)
            print(f"Installed {paths.node_crt} ({summ['cn']}, valid until "
                  f"{summ['not_after'][:10]}) and {paths.ca_crt}.")
            return EXIT_OK
        if args.remove:
            return _remove(args, settings, paths)
        if settings.is_master:
            made = pairing.prepare_master(settings, paths, renew=args.renew)
            print("Made " + "; ".join(made) + "." if made else
                  f"The fleet CA and this router's certificate are in place ({paths.dir}).")
            return EXIT_OK
        why = pairing.needs_pairing(settings, paths)
        if why is None and not args.renew:
            s = fleet_tls.cert_summary(paths.node_crt)
            print(f"Already paired: {paths.node_crt} names {s['cn']}, valid until "
                  f"{s['not_after'][:10]} (--renew signs a new one).")
            return EXIT_OK
        res = asyncio.run(pairing.pair_over_ssh(settings, paths, options_for(settings.relay),
                                                timeout=args.timeout))
    except TlsError as exc:
        say(f"rosnet-tui: {exc}")
        return EXIT_USAGE if args.sign or args.install or args.admit else EXIT_FAIL
    except OSError as exc:
        say(f"rosnet-tui: {exc}")
        return EXIT_FAIL
    if not res.ok:
        say(f"rosnet-tui: pairing failed: {res.detail}")
        return EXIT_FAIL
    print(f"{res.detail[:1].upper()}{res.detail[1:]} ({res.seconds:.1f} s). Restart the router "
          "to use it.")
    if res.master_sync_key:
        from rosnet_tui.core.sync.pin import pin_from_pairing

        try:
            said = pin_from_pairing(config_path(args).expanduser().absolute(),
                                    settings.master_name, res.master_sync_key)
        except (SettingsError, OSError) as exc:
            said = f"the master's sync key was not pinned ({exc}): `rosnet-tui sync pin`"
        if said:
            print(said)
    return EXIT_OK


NOT_SIGNING = ("rosnet-tui: not signing without a confirmation, and there is no terminal to ask "
               "on: compare the name and fingerprint above, then run the same command with --yes")


def _sign(args: argparse.Namespace, settings, paths) -> int:
    """--sign: the request read, checked, shown (name, key fingerprint), asked, signed."""
    if not settings.is_master:
        say("rosnet-tui: --sign runs on the master (it holds the fleet CA)")
        return EXIT_USAGE
    text = _read_stdin("the member's request")
    pairing.prepare_master(settings, paths)
    req = fleet_tls.read_request(text, master=settings.this.name,
                                 members=pairing.member_names(settings),
                                 removed=fleet_tls.removed_members(paths),
                                 relay=settings.relay.host)
    what = "the relay in the settings" if req.role == "relay" else "a member in the settings"
    say(f"The request names {req.name}, {what}; its key's fingerprint:\n"
        f"  {req.fingerprint}\n(`ros pair --print-request` on {req.name} printed the same.)")
    stop = confirm(args, f"Sign a certificate for {req.name}?", cancelled="Not signed.",
                   no_terminal=NOT_SIGNING)
    if stop is not None:
        return stop
    ca, cert = fleet_tls.sign_checked(paths, req)
    summ = fleet_tls.cert_summary(cert.encode())
    print(f"# Certificate for {summ['cn']}, valid until {summ['not_after'][:10]}. Paste "
          "everything below into `rosnet-tui ros pair --install` on that member.")
    sys.stdout.write(cert + ca)
    return EXIT_OK


def _serve(args: argparse.Namespace, settings, paths) -> int:
    """--serve NAME (a member's forced command): one ROSNET_TLS line, never a question."""
    rep = pairing.serve(settings, paths, args.serve, sys.stdin.read(65536))
    if "error" not in rep:
        from rosnet_tui.core.sync.signing import key_path, load_or_make_key, public_text

        try:        # the member pins it in the same session (an older member ignores it)
            rep["sync_key"] = public_text(load_or_make_key(key_path(config_path(args))))
        except (OSError, ValueError):
            pass    # pairing does not depend on it: `sync pin` asks again
    print(fleet_tls.REPORT_PREFIX + json.dumps(rep), flush=True)
    return EXIT_FAIL if "error" in rep else EXIT_OK


def _admit(args: argparse.Namespace, settings) -> int:
    """--admit NAME: the public key on stdin gets NAME's forced pairing command."""
    if not settings.is_master:
        say("rosnet-tui: --admit runs on the master (members pair with it)")
        return EXIT_USAGE
    if args.admit.lower() not in {n.lower() for n in pairing.member_names(settings)}:
        say(f"rosnet-tui: {args.admit} is not a peer in the settings: add it there first")
        return EXIT_USAGE
    keys = pair_access.authorized_keys_path()
    try:
        pair_access.admit(args.admit, _read_stdin(f"{args.admit}'s SSH public key (.pub)"),
                          path=keys, config=getattr(args, "config", None))
    except pair_access.AccessError as exc:
        say(f"rosnet-tui: {exc}")
        return EXIT_USAGE
    print(f"{keys}: that key can now only ask this master to sign {args.admit}'s certificate "
          f"(a forced command, no shell). On {args.admit}: `rosnet-tui ros pair` with that key.")
    return EXIT_OK


NOT_ROTATING = ("rosnet-tui: not rotating the fleet CA without a confirmation, and there is no "
                "terminal to ask on: read the above, then run the same command with --yes")


def _remove(args: argparse.Namespace, settings, paths) -> int:
    """A new CA: the removed member's certificate stops being trusted; the others re-pair.
    Said first, then asked (or --yes, --dry-run)."""
    if not settings.is_master:
        say("rosnet-tui: --remove runs on the master (it holds the fleet CA)")
        return EXIT_USAGE
    if args.remove.lower() not in {n.lower() for n in pairing.member_names(settings)} and \
            args.remove.lower() not in fleet_tls.removed_members(paths):
        say(f"rosnet-tui: {args.remove} is not a peer in the settings")
        return EXIT_USAGE
    others = [p for p in settings.peers if p.name.lower() != args.remove.lower()]
    _preview_remove(args.remove, settings, paths, others)
    stop = confirm(args, "Rotate the fleet CA now?", dry_run="nothing was changed",
                   cancelled="Cancelled: nothing was changed.", no_terminal=NOT_ROTATING)
    if stop is not None:
        return stop
    fleet_tls.set_removed(paths, args.remove)
    fleet_tls.rotate_ca(paths, settings.this.name)
    pairing.prepare_master(settings, paths)
    keys = pair_access.authorized_keys_path()
    try:
        gone = pair_access.revoke(args.remove, path=keys)
        others_in = pair_access.other_keys(keys)
    except pair_access.AccessError as exc:
        say(f"rosnet-tui: {exc}; {args.remove}'s pairing lines there were not removed: delete "
            "the lines ending in its name by hand")
        return EXIT_FAIL
    print(f"Removed {gone} pairing key(s) of {args.remove} from {keys}; this CA never signs for "
          f"{args.remove} again (its name is in {paths.dir / fleet_tls.REMOVED_FILE}).")
    if others_in:
        print(f"  {keys} holds other keys too: if one is {args.remove}'s (its checks' SSH), "
              "delete that line by hand; a password login on this account is another way in.")
    rc = EXIT_OK
    results = asyncio.run(pairing.repair_members(settings, paths, others,
                                                 options_for(settings.relay),
                                                 timeout=args.timeout))
    for name, ok, detail in results:
        print(f"  {name}: {'re-paired' if ok else 'NOT re-paired'}: {detail}")
        rc = rc if ok else EXIT_FAIL
    print(f"{args.remove} is out of the fleet: a new CA signed this router's certificate; restart "
          "the router here (and on each re-paired member). Remove it from [[peer]] too.")
    return rc


def _preview_remove(name: str, settings, paths, others: list) -> None:
    """What --remove NAME will do, before it asks."""
    ca = "a new fleet CA replaces" if paths.ca_crt.exists() else "a new fleet CA is made in"
    print(f"Taking {name} out of the fleet, on {settings.this.name} (the master):")
    print(f"  - {name}'s pairing key leaves {pair_access.authorized_keys_path()}, and this CA "
          f"will refuse to sign for {name} again.")
    print(f"  - {ca} {paths.dir}: every certificate the old CA signed stops being trusted, "
          f"{name}'s too. The old CA is deleted; `rosnet-tui undo` cannot bring it back.")
    print("  - this router's certificate is signed again by the new CA: restart the router here "
          "afterwards.")
    if not others:
        print("  - no other member to pair again.")
        return
    print(f"  - every other member must pair again: {', '.join(p.name for p in others)}. It "
          "happens now, over SSH; each restarts its router afterwards.")
    no_ssh = [p.name for p in others if not p.ssh_user]
    if no_ssh:
        print(f"    No SSH user in the settings for {', '.join(no_ssh)}: run `rosnet-tui ros "
              "pair` there afterwards (or the text way: --print-request, --sign, --install).")
    print("    Until a member is paired again, its router cannot link to this one.")
