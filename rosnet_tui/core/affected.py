"""Which checks a write affects: the one table the wizard, the CLI, an undo and the sync service
read to know what to run again after they changed something."""

from __future__ import annotations

HOSTS = ("linux.hosts", "linux.resolve")          # the hosts file's marked block
ROS_ENV = ("ros.env",)                            # the ROS block of ~/.bashrc
ROS2_ENV = ("ros2.env",)                          # ROS 2: that block and the router's config
ROS2_TLS = ("ros2.router", "relay.router")       # ROS 2 under mTLS: the fleet certificates
FORWARD = ("router.upnp", "router.port_open")     # a forward mapped on (or removed from) the modem
FIREWALL = ("linux.firewall",)                    # our nftables table (ROS 1's peers-only set)
UNDO = (*HOSTS, *ROS_ENV, *ROS2_ENV, "router.upnp", *FIREWALL)   # an undo in the wizard: any of
                                                                   # the above
SYNC = (*HOSTS, "linux.ssh", "ros.master")        # the sync service: a peer's new address
SYNC_ROS2 = (*HOSTS, "linux.ssh", "ros2.router")  # the same under ROS 2 (the master's router)


def ros2_write(mtls: bool) -> tuple[str, ...]:
    """What `ros apply` (or the wizard's `w`) on a ROS 2 component affects."""
    return ROS2_ENV + ROS2_TLS if mtls else ROS2_ENV
