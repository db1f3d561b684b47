"""`rosnet-tui relay`: the relay a fleet behind carrier NAT meets at (ROS 2, issue 30)."""

from __future__ import annotations

import argparse
import signal
import threading
from pathlib import Path

from rosnet_tui.cli import relay_apply, relay_tunnel
from rosnet_tui.cli.common import EXIT_FAIL, EXIT_OK, EXIT_USAGE, say


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "relay",
        help="ROS 2 across carrier NAT: the relay's Zenoh router every component dials out to",
        description="When no site can forward a port (both behind carrier-grade NAT), every "
                    "component's Zenoh router dials out to a relay: a small public server you "
                    "own. The settings' [relay] section names it (docs/SETTINGS.md).")
    cmds = p.add_subparsers(dest="relay_command", metavar="COMMAND", required=True)
    serve = cmds.add_parser(
        "serve", help="run the relay's Zenoh router in the foreground (on the relay)",
        description="Run the relay's Zenoh router (eclipse-zenoh in router mode: the real "
                    "router; no ROS needed) from the config written for it, until Ctrl-C or "
                    "SIGTERM. It takes only sessions with a fleet certificate (mutual TLS).")
    serve.add_argument("--router-config", type=Path, metavar="FILE",
                       help="the relay's router config (default: "
                            "~/.config/rosnet-tui/zenoh-relay.json5)")
    serve.set_defaults(func=run_serve)
    relay_tunnel.register(cmds)
    relay_apply.register(cmds)


def run_serve(args: argparse.Namespace) -> int:
    from rosnet_tui.core.ros import relay

    path = args.router_config or relay.default_relay_config_path()
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    try:
        session = relay.open_relay(path)
    except relay.RelayConfigError as exc:
        say(f"rosnet-tui: the relay cannot start: {exc}")
        return EXIT_USAGE
    except relay.RelayStartError as exc:
        say(f"rosnet-tui: Zenoh did not start the relay's router: {exc}")
        return EXIT_FAIL
    try:
        listen = relay.listen_endpoints(path)
        print(f"Relay router {session.zid()} listening on {', '.join(listen)} (mutual TLS, "
              "fleet certificates only). Ctrl-C stops it.", flush=True)
        stop.wait()
    finally:
        session.close()
    print("Relay router stopped.", flush=True)
    return EXIT_OK
