"""The order the advisor lists its rules in: one list, in one place.

:data:`RULE_ORDER` decides, for findings of the same severity and the same step, which comes
first (Table 1's three causes share the place of the first and are ranked by the evidence); it
is also the order of docs/TROUBLESHOOTING.md's tables and of ``python -m rosnet_tui.core.advisor
--ids`` (the catch-alls follow it). It does not decide which rule is *evaluated* first: a rule
that reads another's firing says so with ``after=(...)`` (see the engine).

The engine refuses a declared rule missing from this list, or a listed one never declared. A new
rule goes here next to the rules it should be read with; the order of the step modules, or of
the rules inside them, carries no meaning.
"""

from __future__ import annotations

RULE_ORDER: tuple[str, ...] = (
    # the link, then step 1 (ISP)
    "router.local_ip.no_link",              # symptom in step 1; reads router.local_ip
    "isp.no_internet.dns",
    "isp.no_internet.http",
    "isp.public_ip.unknown",
    "isp.public_ip.disagree",
    "isp.public_ip.changed",
    "isp.public_ip.differs",
    # ROS 2 under a relay: the relay's router carries every link (before the modem's rules)
    "relay.router.down",
    # step 2: Table 1 (the port test)
    "table1.open",
    "table1.no_listener",
    "table1.no_listener_open",
    "table1.listener_up_closed.port_in_use",  # cause (a) }
    "table1.listener_up_closed.isp",          # cause (b) } one group: ranked by the evidence
    "table1.listener_up_closed.forwarding",   # cause (c) }
    # step 1 again: carrier NAT on its own (after Table 1, whose cause (b) supersedes it)
    "isp.cgnat",
    "ros2.cgnat",                           # ROS 2: carrier NAT matters on the master only
    # step 2: the router's other checks
    "router.local_ip.differs",
    "router.port_in_use",
    "router.port_open.partial",
    "router.port_open.no_verdict",
    "ros2.port.not_forwarded",              # ROS 2: Table 1 read on the master's zenoh_port
    "router.upnp.conflict",                 # the modem's own word (UPnP IGD, PCP, NAT-PMP)
    "router.upnp.cgnat",
    "router.upnp.missing",
    # step 3: Linux
    "linux.name.loopback",
    "linux.name.unresolved",
    "linux.name.wrong",
    "linux.hosts.missing",
    "linux.hosts.duplicates",
    "linux.ping.icmp_filtered",
    "linux.peer.unreachable",
    "linux.ssh.relay",                      # a peer behind the relay: the relay or its tunnel
    "linux.ssh.refused",
    "linux.ssh.host_key_changed",
    "linux.ssh.host_key_unknown",
    "linux.ssh.auth",
    "linux.ssh.sshd",
    "linux.ssh.resolve",
    "linux.ssh.no_user",
    "linux.chat.in_fails",
    "linux.chat.out_fails",
    "linux.chat.both_fail",
    "relay.tunnel.down",                    # ROS 2 with a relay: this component's tunnel
    "security.firewall.stale",              # ROS 1: the peers-only table (linux.firewall)
    "security.firewall.lockout",
    "security.firewall.missing",
    "security.firewall.off",
    # step 4: ROS
    "ros.env.master_uri_unset",
    "ros.env.master_uri",
    "ros.env.bashrc",
    "ros.env.ros_ip",
    "ros.master.unreachable",
    "ros.master.peer_cannot_register",
    "ros.node_uri.local_ip",
    "ros.node_uri.loopback",
    "ros.node_uri.unknown_host",
    "ros.node_uri.unreachable",
    "ros.pubsub.out_fails",
    "ros.pubsub.in_fails",
    "ros.pubsub.both_fail",
    # step 4: ROS 2 over rmw_zenoh (the link measured first: it fires only when the path works)
    "ros2.link.large_dropped",
    "ros2.link.too_thin",
    "ros2.env.dds",
    "ros2.env.domain",
    "ros2.env.distro",
    "ros2.env.rmw_one_place",
    "ros2.env.no_distro",
    "ros2.env.leftovers",
    "ros2.router.not_running",
    "ros2.router.loopback",
    "ros2.router.ipv6_only",
    "ros2.peer_mode",
    "ros2.link.missing",
    "ros2.tls.missing",                     # ROS 2 mutual TLS: this component's certificate
    "ros2.tls.foreign_ca",
    "ros2.tls.expired",
    "ros2.tls.wrong_name",
    # step 4: web clients (rosbridge), both ROS versions: one rule per hop
    "rosbridge.name",
    "rosbridge.forward",
    "rosbridge.not_running",
    "rosbridge.upgrade",
    "rosbridge.rosapi",
    "rosbridge.round_trip",
    # security, what a stranger gets (issue 22): SSH (Linux step), the outsider (ROS step)
    "security.ssh.password",
    "security.ssh.root_password",
    "security.ssh.password_here",
    "security.outsider.off",
    "security.outsider.plain",
    "security.outsider.foreign_ca",
    "security.outsider.expired",
    "security.outsider.wrong_name",
    "security.outsider.no_fleet_cert",
    "security.outsider.firewall_missing",
    "security.outsider.insider_blocked",
    # security (step 2: what the forwarding exposes)
    "security.zenoh_exposed",
    "security.rosbridge_exposed",
    "security.exposed",
)
