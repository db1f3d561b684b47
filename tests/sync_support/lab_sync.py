"""The sync service on the network lab: settings with a [sync] table, the service started on
robot and laptop, bounded waits on what it records in its state dir."""

from __future__ import annotations

import contextlib
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rosnet_tui.core.config.settings_model import SyncSettings
from rosnet_tui.core.saved.settings import atomic_write_text, render_settings
from rosnet_tui.core.sync.status import load_status
from tests.builders import sync_key_text, write_sync_key

from .bind import BindServer

COMPUTERS = ("robot", "laptop")
# A stock hosts file: localhost only; sync writes its block above it.
STOCK_HOSTS = "127.0.0.1\tlocalhost\n::1\tlocalhost ip6-localhost ip6-loopback\n"
AFFECTED_PASS = ("linux.hosts", "linux.resolve", "linux.ssh", "ros.master")


def write_sync_config(lab, host: str, path: Path, *, store: str, folder: Path | None = None,
                      bind: BindServer | None = None, interval_s: float = 2.0) -> Path:
    """The lab's settings of *host* with a [sync] table for *store* (*bind*: anything with the
    server's ip, zone and key_file, even before the server runs)."""
    s = lab.settings(host)
    s.sync = SyncSettings(store=store, interval_s=interval_s,
                          folder=str(folder) if folder else "",
                          dns_server=bind.ip if bind else "", zone=bind.zone if bind else "",
                          tsig_key_file=str(bind.key_file) if bind else "")
    s.has_sync = True
    return write_pinned(s, path)


def write_pinned(s, path: Path) -> Path:
    """Settings *s* written to *path*, each peer's sync key pinned, this component's own key
    beside them (every component's test key: tests.builders.sync_key)."""
    for peer in s.peers:
        peer.sync_key = sync_key_text(peer.name)
    atomic_write_text(path, render_settings(s), mode=0o644)
    write_sync_key(path, s.this.name)
    return path


def sync_env(lab, host: str) -> dict[str, str]:
    """The host's ROS environment without XDG dirs (each host keeps its state where we say)."""
    return {k: v for k, v in lab.ros_env(host).items() if not k.startswith("XDG_")}


def sync_argv(config: Path, state_dir: Path, *args: str, python: list[str] | None = None
              ) -> list[str]:
    base = python or [sys.executable, "-m", "rosnet_tui"]
    return [*base, "sync", "--config", str(config), "--state-dir", str(state_dir), *args]


def wait_for(fn: Callable[[], Any], timeout: float, step: float = 0.05) -> Any:
    """Poll *fn* until it returns something truthy (returned), or None after *timeout*."""
    deadline = time.monotonic() + timeout
    while True:
        got = fn()
        if got:
            return got
        if time.monotonic() >= deadline:
            return None
        time.sleep(step)


def hosts_entry(lab, host: str, name: str) -> str | None:
    """The address the first line of *host*'s /etc/hosts gives *name* (what glibc returns)."""
    for line in lab.hosts_path(host).read_text().splitlines():
        f = line.split("#", 1)[0].split()
        if len(f) >= 2 and name in f[1:]:
            return f[0]
    return None


def resolve(lab, host: str, name: str) -> str:
    r = lab.run(host, ["getent", "ahostsv4", name], timeout=10)
    return r.stdout.split()[0] if r.returncode == 0 and r.stdout.split() else ""


def checks_of(status: dict | None) -> dict[str, str]:
    ch = (status or {}).get("last_change") or {}
    return {c["id"]: c["status"] for c in ch.get("checks") or []}


@dataclass
class SyncRig:
    """`rosnet-tui sync` running on robot and laptop, one store, state dirs under *workdir*."""

    lab: Any
    workdir: Path
    store: str
    folder: Path | None = None
    bind: BindServer | None = None
    interval_s: float = 2.0
    procs: dict[str, Any] = field(default_factory=dict)
    configs: dict[str, Path] = field(default_factory=dict)
    states: dict[str, Path] = field(default_factory=dict)

    def configure(self) -> None:
        for h in COMPUTERS:
            self.configs[h] = write_sync_config(
                self.lab, h, self.workdir / f"{h}.toml", store=self.store, folder=self.folder,
                bind=self.bind, interval_s=self.interval_s)
            self.states[h] = self.workdir / f"state-{h}"

    def start(self, *hosts: str, extra: tuple[str, ...] = ()) -> None:
        if not self.configs:
            self.configure()
        for h in hosts or COMPUTERS:
            self.procs[h] = self.lab.spawn(h, sync_argv(
                self.configs[h], self.states[h], "--bashrc", str(self.lab.bashrc_path(h)),
                *extra), env=sync_env(self.lab, h))

    def status(self, host: str) -> dict | None:
        return load_status(self.states[host])

    def log(self, host: str) -> str:
        return self.lab.output(self.procs[host])

    def wait_status(self, host: str, pred: Callable[[dict], Any], timeout: float) -> dict | None:
        def probe():
            st = self.status(host)
            with contextlib.suppress(KeyError, TypeError, AttributeError):
                if st is not None and pred(st):
                    return st
            return None
        return wait_for(probe, timeout)

    def published(self, host: str, public_ip: str, timeout: float) -> dict | None:
        """Wait until *host* has published a record with *public_ip*."""
        return self.wait_status(host, lambda st: st["own"]["record"]["public_ip"] == public_ip,
                                timeout)

    def followed(self, public_ip: str, timeout: float, since: float = 0.0) -> dict | None:
        """Wait until the laptop has written turtlebot -> *public_ip* and run the checks."""
        def done(st: dict) -> bool:
            ch = st["last_change"]
            return (ch["at"] >= since and f"-> {public_ip}" in ch["summary"]
                    and bool(ch.get("checked_at")))
        return self.wait_status("laptop", done, timeout)

    def stop(self) -> dict[str, int | None]:
        """SIGTERM each service (a clean stop), bounded; their exit codes."""
        codes = {}
        for h, p in self.procs.items():
            if p.poll() is None:
                with contextlib.suppress(ProcessLookupError):
                    p.terminate()
                with contextlib.suppress(Exception):
                    p.wait(timeout=10)
            codes[h] = p.poll()
            self.lab.kill(p)
        return codes


def prepare_lab(lab) -> None:
    """Healthy network, roscore on the robot, and hosts files that know nothing of the peer:
    the laptop's is stock, the robot's names only itself (roslaunch gives up when its own
    name stops resolving), as on a robot set up for a LAN. The hosts files are written before
    roscore starts: it looks the master's name up while it starts, and exits if that fails."""
    lab.reset()
    lab.write_hosts("laptop", STOCK_HOSTS)
    lab.write_hosts("robot", STOCK_HOSTS + f"{lab.addr.ROBOT_LOCAL}\t{lab.addr.ROBOT_NAME}\n")
    lab.start_roscore()
