"""The lab's ROS 2 network through the relay (issue 30): ``with RelayWorld(lab) as w:``.

- the relay (192.0.2.77 on the lab's internet, named ``relay`` in both computers' hosts files)
  runs `rosnet-tui relay serve` with the router config the product writes for it
  (core/ros/relay.py) and its certificate signed by the master's fleet CA as the relay;
- both computers' settings have ``[relay] host = "relay"``: their routers (real Zenoh routers
  from the config `ros apply` writes) dial ``tls/relay:7447`` and listen on loopback only;
- neither modem forwards the Zenoh port: only TCP 22, the SSH the checks use for a peer's side.

Leaving the block stops the relay and puts the ROS 2 world back as Ros2World leaves it.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from . import topology
from .lab import Lab
from .ros2 import Ros2World
from .topology import ADDR, COMPUTERS

RELAY = "relay"


class RelayWorld(Ros2World):
    def __init__(self, lab: Lab, distro: str = "jazzy") -> None:
        super().__init__(lab, distro)
        self.relay_proc: Any = None

    def settings(self, host: str, **ros: Any):
        from rosnet_tui.core.config.settings_model import RelaySettings

        s = super().settings(host, **ros)
        s.relay = RelaySettings(host=ADDR.RELAY_NAME, ssh_user="root",
                                zenoh_port=topology.ZENOH_PORT)
        return s

    def forward(self, robot: str = "ssh", laptop: str = "ssh") -> None:
        super().forward(robot, laptop)      # nothing of Zenoh is forwarded anywhere

    def relay_dir(self) -> Path:
        assert self.lab.dir is not None
        d = self.lab.dir / RELAY / "rosnet-tui"
        d.mkdir(parents=True, exist_ok=True)
        return d

    def relay_config_path(self) -> Path:
        return self.relay_dir() / "zenoh-relay.json5"

    def write_relay_config(self) -> Path:
        """The relay's key made there, signed by the master's fleet CA (as the relay), and its
        router config as the product writes it."""
        from rosnet_tui.core.ros import fleet_tls, pairing, relay

        m = self.master_host()
        mp = self.tls_paths(m)
        pairing.prepare_master(self.settings(m), mp)
        rp = fleet_tls.tls_paths(self.relay_dir())
        ca, cert = fleet_tls.sign_request(mp, fleet_tls.make_request(rp, ADDR.RELAY_NAME),
                                          master=self.settings(m).this.name,
                                          members=pairing.member_names(self.settings(m)),
                                          relay=ADDR.RELAY_NAME)
        fleet_tls.install(rp, ca, cert)
        path = self.relay_config_path()
        path.write_text(relay.render_relay_config(ADDR.RELAY_NAME, topology.ZENOH_PORT, rp))
        return path

    def start_relay(self, timeout: float = 15.0) -> Any:
        self.stop_relay()
        log = open(self.lab.log_path("relay-serve"), "w")  # noqa: SIM115
        self.relay_proc = self.lab.spawn(RELAY, [sys.executable, "-m", "rosnet_tui", "relay",
                                                 "serve", "--router-config",
                                                 str(self.relay_config_path())],
                                         stdout=log, stderr=log)
        log.close()
        if not self.lab.wait_listening(RELAY, topology.ZENOH_PORT, timeout=timeout,
                                       proc=self.relay_proc):
            raise RuntimeError("relay serve did not start: "
                               + self.lab.log_path("relay-serve").read_text()[-2000:])
        return self.relay_proc

    def stop_relay(self) -> None:
        if self.relay_proc is not None:
            self.lab.kill(self.relay_proc, grace=2.0)
            self.relay_proc = None

    def write_hosts_with_relay(self) -> None:
        for h in COMPUTERS:
            self.lab.write_hosts(h, topology.hosts_text(h) + f"{ADDR.RELAY_IP}\t{ADDR.RELAY_NAME}\n")

    def __enter__(self) -> RelayWorld:
        self.lab.reset()
        try:
            self.write_hosts_with_relay()
            self.write_relay_config()
            self.start_relay()
            super().__enter__()
            self.write_hosts_with_relay()     # Ros2World's reset wrote the lab's own
            for h in COMPUTERS:               # routers that resolve the relay from the start
                self.start_router(h)
        except BaseException:
            self.__exit__()
            raise
        return self

    def __exit__(self, *exc: Any) -> None:
        self.stop_relay()
        super().__exit__(*exc)
