"""The fleet (tests/lab/fleet.py) as a ROS 2 network over rmw_zenoh: the two-site Ros2World
(tests/lab/ros2.py) carried over to a master and N-1 members.

``with FleetRos2(fleet) as w:``

- a real Zenoh router (eclipse-zenoh in router mode) on every computer, started from the JSON5
  config `rosnet-tui ros apply` writes (ros2.render_router_config of that computer's settings):
  the master's listens on ``tcp/0.0.0.0:7447``; each member's connects out to
  ``tcp/turtlebot:7447``, which its hosts file maps to the master's public address;
- the master's modem forwards TCP 22 and 7447, each member's TCP 22 only (the SSH the checks use
  to run the peer's side);
- entering waits (bounded) until every member's router is linked to the master's, as the master
  router's admin space says (:meth:`FleetRos2.linked`);
- stand-in rmw_zenoh nodes (tests/lab/ros2_scripts/node.py) with ``w.node(host, role)``.

Leaving the block stops routers and nodes and puts the fleet back (ROS 1 forwarding).
"""

from __future__ import annotations

import subprocess
import sys
import time

from .fleet import Fleet
from .ros2 import ROS2_IDS, ZROUTER, Ros2World


class FleetRos2(Ros2World):
    lab: Fleet

    def __init__(self, fleet: Fleet, distro: str = "jazzy") -> None:
        super().__init__(fleet, distro)
        self.bash_extra = {h: {} for h in fleet.COMPUTERS}
        self.start_s = 0.0    # seconds the last __enter__ took (routers up and linked)

    def forward(self, master: str = "ros2", members: str = "ssh") -> None:
        for h in self.lab.COMPUTERS:
            self.lab.set_forwarding(h, master if h == self.lab.master else members)

    # ------------------------------------------------------------------ routers
    def _spawn_router(self, host: str) -> subprocess.Popen:
        self.stop_router(host)
        with open(self.lab.log_path(f"zrouter-{host}"), "w") as log:
            proc = self.lab.spawn(host, [sys.executable, str(ZROUTER),
                                         str(self.router_config_path(host))],
                                  stdout=log, stderr=subprocess.STDOUT)
        self.routers[host] = proc
        return proc

    def start_routers(self, hosts: list[str] | None = None, timeout: float = 20.0) -> None:
        """Start the routers of *hosts* (default: every computer): the master's first, then the
        members' all at once (each dials the master's at start, so the master's must listen)."""
        hosts = list(self.lab.COMPUTERS if hosts is None else hosts)
        waves = [[h for h in hosts if h == self.lab.master],
                 [h for h in hosts if h != self.lab.master]]
        deadline = time.monotonic() + timeout
        for wave in waves:
            procs = {h: self._spawn_router(h) for h in wave}
            for h, proc in procs.items():
                if not self.lab.wait_listening(h, 7447, timeout=max(0.1, deadline - time.monotonic()),
                                               proc=proc):
                    raise RuntimeError(f"the Zenoh router on {h} did not start: "
                                       + self.lab.log_path(f"zrouter-{h}").read_text()[-2000:])

    def master_host(self) -> str:
        return self.lab.master

    def member_hosts(self) -> list[str]:
        return list(self.lab.members)

    # ------------------------------------------------------------------ the world
    def _write_all(self) -> None:
        for h in self.lab.COMPUTERS:
            self.lab.write_hosts(h, self.lab.hosts_text(h))
            self.config_path(h)
            self.write_router_config(h)
            self.write_bashrc(h)

    def __enter__(self) -> FleetRos2:
        t0 = time.monotonic()
        self.lab.reset()
        try:
            self.forward()
            self._write_all()
            self.start_routers()
            self.wait_linked()
        except BaseException:
            self.__exit__()
            raise
        self.start_s = time.monotonic() - t0
        return self

    def healthy(self) -> None:
        """Back to the healthy ROS 2 fleet: no nodes, every router up and linked."""
        for p in self.nodes:
            self.lab.kill(p, grace=0.5)
        self.nodes.clear()
        self.bash_extra = {h: {} for h in self.lab.COMPUTERS}
        for h in [h for h, rate in self.lab.slowed.items() if rate]:
            self.lab.set_rate(h, None)
        self.forward()
        self._write_all()
        down = [h for h in self.lab.COMPUTERS
                if h not in self.routers or self.routers[h].poll() is not None]
        if down:
            self.start_routers(down)
            self.wait_linked()


__all__ = ["ROS2_IDS", "FleetRos2"]
