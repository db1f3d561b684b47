"""`rosnet-tui relay tunnel`: keep this component's sshd reachable on the relay (a reverse SSH
tunnel to the relay's loopback), in the foreground or as a systemd service."""

from __future__ import annotations

import argparse
import getpass
import shutil
import signal
import threading
from pathlib import Path

from rosnet_tui.cli.common import (
    EXIT_FAIL,
    EXIT_OK,
    EXIT_USAGE,
    add_config_option,
    config_path,
    say,
)
from rosnet_tui.cli.units import exec_lines, install_unit, restart_lines
from rosnet_tui.cli.writing import load_settings_for
from rosnet_tui.core.files import privilege
from rosnet_tui.core.ssh.options import SshOptions
from rosnet_tui.core.ssh.tunnel import TunnelKeeper, tunnel_argv

UNIT_NAME = "rosnet-tui-tunnel.service"


def register(cmds: argparse._SubParsersAction) -> None:
    p = cmds.add_parser(
        "tunnel", help="keep this component's sshd reachable on the relay (a reverse SSH tunnel)",
        description="Keep a reverse SSH tunnel to the relay: this component's sshd answers at "
                    "the relay's 127.0.0.1:<port> ([relay.tunnels] in the settings), never on "
                    "the relay's public address, so peers reach it with the relay as a jump "
                    "host. Runs in the foreground and starts the tunnel again within seconds "
                    "when the link drops; Ctrl-C or SIGTERM ends it. The relay's host key must "
                    "be in known_hosts already (ssh to the relay once and compare it).")
    add_config_option(p)
    p.add_argument("--sshd-port", type=int, default=22, metavar="PORT",
                   help="the port of this machine's sshd the tunnel leads to (default: 22)")
    p.add_argument("--ssh-dir", type=Path, default=None, metavar="DIR",
                   help="the folder with the key and known_hosts the tunnel uses (default: "
                        "~/.ssh of the user running it)")
    p.add_argument("--install-service", action="store_true",
                   help="write a systemd unit that keeps the tunnel, instead of running it here")
    p.add_argument("--yes", "-y", action="store_true",
                   help="with --install-service: write without asking")
    p.add_argument("--dry-run", action="store_true",
                   help="with --install-service: show the unit, write nothing")
    p.add_argument("--unit-dir", metavar="DIR", type=Path, default=None,
                   help="with --install-service: write the unit into DIR instead of "
                        "/etc/systemd/system")
    p.set_defaults(func=run_tunnel)


def run_tunnel(args: argparse.Namespace) -> int:
    if not 0 < args.sshd_port < 65536:
        say(f"rosnet-tui: --sshd-port must be 1-65535, not {args.sshd_port}")
        return EXIT_USAGE
    settings = load_settings_for(args)
    if settings is None:
        return EXIT_USAGE
    try:
        opts = SshOptions(ssh_dir=args.ssh_dir.expanduser().absolute()) if args.ssh_dir else None
        argv = tunnel_argv(settings.relay, settings.this.name, args.sshd_port, opts)
    except ValueError as exc:
        say(f"rosnet-tui: {exc}")
        return EXIT_USAGE
    if args.install_service:
        return install(args)
    if shutil.which(argv[0]) is None:
        say("rosnet-tui: the tunnel needs OpenSSH's client (ssh): sudo apt install "
            "openssh-client")
        return EXIT_FAIL
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())

    def tell(line: str) -> None:
        print(f"relay tunnel: {line}", flush=True)

    tell(f"keeping {settings.this.name}'s sshd (port {args.sshd_port}) reachable at "
         f"127.0.0.1:{settings.relay.tunnels[settings.this.name]} on {settings.relay.host}; "
         "Ctrl-C ends it")
    TunnelKeeper(argv, tell, stop).run()
    return EXIT_OK


def unit_text(args: argparse.Namespace) -> str:
    """The systemd unit that runs this same command in the foreground, as this user (whose keys
    and known_hosts the tunnel uses)."""
    cfg = config_path(args).absolute()
    argv = privilege.self_argv(["--config", str(cfg), "relay", "tunnel",
                                "--sshd-port", str(args.sshd_port)])
    if getattr(args, "ssh_dir", None):
        argv += ["--ssh-dir", str(Path(args.ssh_dir).expanduser().absolute())]
    lines = ["# Written by 'rosnet-tui relay tunnel --install-service'.",
             "[Unit]",
             "Description=rosnet-tui reverse SSH tunnel: this component's sshd on the relay",
             "Wants=network-online.target",
             "After=network-online.target",
             "",
             "[Service]",
             "Type=simple",
             f"User={getpass.getuser()}",
             *exec_lines(argv),
             *restart_lines("always", 5)]
    lines += ["", "[Install]", "WantedBy=multi-user.target", ""]
    return "\n".join(lines)


def install(args: argparse.Namespace) -> int:
    path = (args.unit_dir or Path("/etc/systemd/system")).expanduser().absolute() / UNIT_NAME
    return install_unit(args, path, unit_text(args), denied=lambda: (
        f"rosnet-tui: this user may not write {path} (the system folder needs root: sudo, "
        "keeping the same --config)"))
