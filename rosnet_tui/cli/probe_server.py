"""`rosnet-tui probe-server`: host your own what-is-my-IP and port-check service."""

from __future__ import annotations

import argparse
import asyncio
import logging
import sys

from rosnet_tui.cli.common import number_in
from rosnet_tui.core.net.probe_server import (
    DEFAULT_LISTEN,
    ProbeLimits,
    parse_listen,
    run_probe_server,
)


def _listen(text: str) -> tuple[str, int]:
    try:
        return parse_listen(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "probe-server",
        help="run your own what-is-my-IP and port-check service (echoip-compatible)",
        description="Serve GET /ip (the caller's address) and GET /port/N (can this server open "
                    "a TCP connection back to the caller on port N?), the protocol of ifconfig.co. "
                    "Point probe.public_ip_urls and probe.port_check_url at it. It only ever "
                    "connects back to the address the request came from.")
    p.add_argument("--listen", type=_listen, default=DEFAULT_LISTEN, metavar="ADDR:PORT",
                   help=f"address and port to listen on (default {DEFAULT_LISTEN})")
    p.add_argument("--connect-timeout", type=number_in(0.1, 60), default=2.0, metavar="SECONDS",
                   help="how long one connect-back may take, 0.1-60 seconds (default 2)")
    p.add_argument("--rate-limit", type=number_in(1, 1_000_000, whole=True), default=30, metavar="N",
                   help="port checks allowed per caller address per minute, 1-1000000 "
                        "(default 30)")
    p.add_argument("--max-concurrent", type=number_in(1, 1024, whole=True), default=16,
                   metavar="N", help="connect-backs in progress at once, 1-1024 (default 16)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    host, port = args.listen
    limits = ProbeLimits(connect_timeout_s=args.connect_timeout,
                         checks_per_minute=args.rate_limit,
                         max_connect_backs=args.max_concurrent)
    logger = logging.getLogger("rosnet_tui.probe_server")
    if not logger.handlers:
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(logging.Formatter("%(asctime)s %(message)s", "%Y-%m-%dT%H:%M:%S"))
        logger.addHandler(handler)
        logger.setLevel(logging.INFO)
        logger.propagate = False

    def ready(bound: int) -> None:
        shown = f"[{host}]" if ":" in host else host
        print(f"probe server listening on http://{shown}:{bound}  (GET /ip, GET /port/N; "
              f"Ctrl-C stops it)", file=sys.stderr, flush=True)

    try:
        asyncio.run(run_probe_server(host, port, limits, ready))
    except OSError as exc:
        print(f"rosnet-tui probe-server: cannot listen on {host}:{port}: {exc.strerror or exc}",
              file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        pass
    print("probe server stopped", file=sys.stderr)
    return 0
