"""Both sites behind carrier NAT, joined through the relay, set up with the product's own commands
(issue 30's first "done when"): ``with RelayCgnat(lab) as w:``.

In the lab's ``cgnat_both`` variant nothing reaches either site from the internet; only the relay
(192.0.2.77, named ``relay`` in both computers' hosts files) takes connections. From settings
with ``[relay]`` (tunnels for both computers) and default security, in this order:

1. ``rosnet-tui ros apply --yes`` on the master (the robot): the fleet CA, the router config;
2. ``rosnet-tui relay apply --yes`` on the master: the relay's key, certificate, router config
   and unit, over SSH with the relay's own install;
3. the relay's unit's command (``relay serve`` with the relay's install) on the relay;
4. ``rosnet-tui relay tunnel`` on both computers;
5. ``rosnet-tui ros apply --yes`` on the member (the laptop): pairing with the master through
   the relay (the master's sshd reached by the reverse tunnel).

Each computer's router is the lab's stand-in for rmw_zenohd (tests/lab/ros2_scripts/zrouter.py)
on the config ``ros apply`` wrote, started once that config is there. Nothing else is written
by the test: no key, certificate or config.
"""

from __future__ import annotations

import shlex
import subprocess
import sys
from pathlib import Path
from typing import Any

from .lab import Lab
from .ros2 import Ros2World
from .topology import ADDR, COMPUTERS

TUNNELS = {"robot": 2201, "laptop": 2202}


class RelayCgnat(Ros2World):
    def __init__(self, lab: Lab) -> None:
        super().__init__(lab)
        self.tunnels: dict[str, subprocess.Popen] = {}
        self.relay_proc: subprocess.Popen | None = None
        self.said: dict[str, subprocess.CompletedProcess] = {}
        self._variant: Any = None

    def settings(self, host: str, **ros: Any):
        from rosnet_tui.core.config.settings_model import RelaySettings

        s = super().settings(host, **ros)
        # The public addresses the sites show now (their carriers'), as the wizard measures them.
        s.this.public_ip = self.lab.public_ip(host)
        for p in s.peers:
            p.public_ip = self.lab.public_ip(self.lab.peers_of(host)[0])
        s.relay = RelaySettings(host=ADDR.RELAY_NAME, ssh_user="root", ssh_port=22,
                                zenoh_port=7447,
                                tunnels={self.lab.hostname(h): p for h, p in TUNNELS.items()})
        return s

    def env(self, host: str) -> dict[str, str]:
        """A shell on *host* that sourced the ~/.bashrc `ros apply` wrote (and ROS's setup)."""
        env = self.lab.env(host)
        env["ROS_DISTRO"] = self.distro
        r = self.lab.rosnet(host, "ros", "export", env=env, timeout=30)
        for line in r.stdout.splitlines():
            if line.startswith("export "):
                k, _, v = line[len("export "):].partition("=")
                env[k] = shlex.split(v)[0] if v else ""
        return env

    def unit_dir(self) -> Path:
        assert self.lab.dir is not None
        return self.lab.dir / "relay" / "units"    # the relay's unit folder (not this machine's)

    def rosnet(self, host: str, *args: str, timeout: float = 120) -> subprocess.CompletedProcess:
        r = self.lab.rosnet(host, *args, env=self.lab.env(host), timeout=timeout)
        self.said[f"{host}: {' '.join(args)}"] = r
        if r.returncode != 0:
            raise RuntimeError(f"`rosnet-tui {' '.join(args)}` on {host} exited "
                               f"{r.returncode}:\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}")
        return r

    def start_relay(self, timeout: float = 20.0) -> subprocess.Popen:
        """The relay's unit's own command (its ExecStart), run on the relay as systemd would."""
        self.stop_relay()
        unit = (self.unit_dir() / "rosnet-tui-relay.service").read_text()
        start = next(x for x in unit.splitlines() if x.startswith("ExecStart="))
        env = {"HOME": str(self.lab.home("relay")), "PATH": "/usr/bin:/bin",
               "PYTHONUNBUFFERED": "1"}
        log = open(self.lab.log_path("relay-serve"), "w")  # noqa: SIM115
        self.relay_proc = self.lab.spawn("relay", shlex.split(start[len("ExecStart="):]),
                                         env=env, stdout=log, stderr=subprocess.STDOUT)
        log.close()
        if not self.lab.wait_listening("relay", 7447, timeout=timeout, proc=self.relay_proc):
            raise RuntimeError("relay serve did not start: "
                               + self.lab.log_path("relay-serve").read_text()[-2000:])
        return self.relay_proc

    def stop_relay(self) -> None:
        if self.relay_proc is not None:
            self.lab.kill(self.relay_proc, grace=2.0)
            self.relay_proc = None

    def start_tunnel(self, host: str, timeout: float = 20.0) -> subprocess.Popen:
        log = open(self.lab.log_path(f"tunnel-{host}"), "w")  # noqa: SIM115
        proc = self.lab.spawn(host, [sys.executable, "-m", "rosnet_tui", "relay", "tunnel"],
                              stdout=log, stderr=subprocess.STDOUT)
        log.close()
        self.tunnels[host] = proc
        if not self.lab.wait_listening("relay", TUNNELS[host], timeout=timeout, proc=proc):
            raise RuntimeError(f"the tunnel of {host} did not come up: "
                               + self.lab.log_path(f"tunnel-{host}").read_text()[-2000:])
        return proc

    def __enter__(self) -> RelayCgnat:
        self._variant = self.lab.variant("cgnat_both")
        self._variant.__enter__()
        try:
            for h in COMPUTERS:
                self.lab.write_hosts(h, self.lab.hosts_text(h)
                                     + f"{ADDR.RELAY_IP}\t{ADDR.RELAY_NAME}\n")
                self.config_path(h)
            self.rosnet("robot", "ros", "apply", "--yes", "--no-checks")
            self.rosnet("robot", "relay", "apply", "--yes", "--unit-dir", str(self.unit_dir()))
            self.start_relay()
            for h in COMPUTERS:
                self.start_tunnel(h)
            self.start_router("robot")
            self.rosnet("laptop", "ros", "apply", "--yes", "--no-checks")
            self.start_router("laptop")
        except BaseException:
            self.__exit__()
            raise
        return self

    def __exit__(self, *exc: Any) -> None:
        for p in self.tunnels.values():
            self.lab.kill(p, grace=1.0)
        self.tunnels.clear()
        self.stop_relay()
        for p in self.nodes:
            self.lab.kill(p, grace=0.5)
        self.nodes.clear()
        for h in list(self.routers):
            self.stop_router(h)
        if self._variant is not None:
            self._variant.__exit__(None, None, None)
            self._variant = None
        for h in COMPUTERS:
            self.lab.config_path(h)
            self.router_config_path(h).unlink(missing_ok=True)
            self.remove_tls(h)
            (self.lab.home(h) / ".ssh" / "config").unlink(missing_ok=True)


__all__ = ["TUNNELS", "RelayCgnat"]
