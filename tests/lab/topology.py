"""The lab's addresses, names and the text of its configuration (links, firewalls, files).

Only documentation ranges are "public" here (192.0.2.0/24, 198.51.100.0/24, 203.0.113.0/24),
plus the private LANs of the procedure and 100.64.0.0/10 behind the carrier in the CGNAT variant.

    robot 10.10.10.1 --- robot_modem 10.10.10.254 | 203.0.113.2 ---.
      (turtlebot)                                                   |  internet 203.0.113.1
                                 carrier 203.0.113.3 (cgnat only) --'            198.51.100.1
    laptop 192.168.1.10 - laptop_modem 192.168.1.254 | 198.51.100.2 ---  services 192.0.2.10/.53
      (sami)                                                            |
                       laptop_carrier 198.51.100.3 (cgnat_both only) ---|
                                    outsider 192.0.2.66 (no peer) ------|
                                    relay 192.0.2.77 (a VPS) -----------'

The outsider is an address on the internet that is no peer (issue 22): what a stranger tries
against the forwarded ports comes from there (tests/lab/outsider.py). The relay is a public
server of the user's own (issue 30): both sites' routers dial out to it (tests/lab/relay.py);
it has a name, its own sshd and HOME with rosnet-tui installed as the README says (a server:
no ROS, no settings of its own). In the cgnat_both variant the laptop's modem is behind a
carrier's NAT as well (its WAN 100.65.0.2, the carrier's public address 198.51.100.3): no site
can forward anything, only the relay takes connections.

In the double_nat variant a travel router of the user's own sits between the robot and its modem:
robot 10.10.10.1 - travel_router 10.10.10.254 | 192.168.0.2 - robot_modem 192.168.0.1 | public.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Addresses:
    ROBOT_LOCAL: str = "10.10.10.1"
    ROBOT_PUBLIC: str = "203.0.113.2"
    ROBOT_GW: str = "10.10.10.254"
    LAPTOP_LOCAL: str = "192.168.1.10"
    LAPTOP_PUBLIC: str = "198.51.100.2"
    LAPTOP_GW: str = "192.168.1.254"
    PROBE_IP: str = "192.0.2.10"
    DNS_IP: str = "192.0.2.53"
    # Beyond the common contract:
    INTERNET_ROBOT_SIDE: str = "203.0.113.1"     # the robot modem's (and carrier's) gateway
    INTERNET_LAPTOP_SIDE: str = "198.51.100.1"   # the laptop modem's gateway
    CARRIER_PUBLIC: str = "203.0.113.3"          # the robot's public IP in the cgnat variant
    CARRIER_LAN: str = "100.64.0.1"
    ROBOT_MODEM_CGNAT_WAN: str = "100.64.0.2"
    STALE_ROBOT_PUBLIC: str = "203.0.113.99"     # nothing answers there (stale_hosts)
    ROBOT_WRONG_FORWARD: str = "10.10.10.2"      # nobody lives there (wrong_forward)
    LAPTOP_WRONG_FORWARD: str = "192.168.1.11"
    ROBOT_NEW_LOCAL: str = "10.10.10.5"          # the robot's new DHCP lease (stale_dhcp)
    OUTER_LAN_GW: str = "192.168.0.1"            # the robot modem's LAN side (double_nat)
    TRAVEL_WAN: str = "192.168.0.2"              # the travel router's WAN side (double_nat)
    ROBOT_SSHD_PORT: str = "2222"                # where the robot's sshd listens (sshd_port)
    OUTSIDER_IP: str = "192.0.2.66"              # a stranger on the internet (no peer)
    OUTSIDER_GW: str = "192.0.2.65"              # the internet's end of the outsider's link
    RELAY_IP: str = "192.0.2.77"                 # the relay, a public server (issue 30)
    RELAY_GW: str = "192.0.2.76"                 # the internet's end of the relay's link
    RELAY_NAME: str = "relay"
    LAPTOP_CARRIER_PUBLIC: str = "198.51.100.3"  # the laptop's public IP in cgnat_both
    LAPTOP_CARRIER_LAN: str = "100.65.0.1"
    LAPTOP_MODEM_CGNAT_WAN: str = "100.65.0.2"
    PROBE_NAME: str = "probe.lab.test"
    PROBE_URL: str = "http://probe.lab.test"
    PUBLIC_IP_URL: str = "http://probe.lab.test/ip"
    ROBOT_NAME: str = "turtlebot"
    LAPTOP_NAME: str = "sami"
    ROS_MASTER_URI: str = "http://turtlebot:11311"


ADDR = Addresses()

HOSTS = ("robot", "laptop", "robot_modem", "laptop_modem", "internet", "carrier", "travel_router",
         "outsider", "relay", "laptop_carrier")
COMPUTERS = ("robot", "laptop")          # the hosts with a name, sshd, HOME and ROS
SERVERS = ("relay",)                     # a name, sshd and HOME with rosnet-tui; no ROS, no settings
HOSTNAMES = {"robot": ADDR.ROBOT_NAME, "laptop": ADDR.LAPTOP_NAME, "robot_modem": "robot-modem",
             "laptop_modem": "laptop-modem", "internet": "internet", "carrier": "carrier",
             "travel_router": "travel-router", "outsider": "outsider", "relay": ADDR.RELAY_NAME,
             "laptop_carrier": "laptop-carrier"}
PEER = {"robot": "laptop", "laptop": "robot"}
MODEM = {"robot": "robot_modem", "laptop": "laptop_modem"}
LOCAL_IP = {"robot": ADDR.ROBOT_LOCAL, "laptop": ADDR.LAPTOP_LOCAL}
PUBLIC_IP = {"robot": ADDR.ROBOT_PUBLIC, "laptop": ADDR.LAPTOP_PUBLIC}
GATEWAY = {"robot": ADDR.ROBOT_GW, "laptop": ADDR.LAPTOP_GW}
WRONG_FORWARD = {"robot": ADDR.ROBOT_WRONG_FORWARD, "laptop": ADDR.LAPTOP_WRONG_FORWARD}
UPSTREAM = {"robot_modem": ADDR.INTERNET_ROBOT_SIDE, "laptop_modem": ADDR.INTERNET_LAPTOP_SIDE}

VARIANTS = ("healthy", "no_forwarding", "wrong_forward", "cgnat", "ros_ip_laptop", "stale_hosts",
            "lossy", "unplugged", "stale_dhcp", "double_nat", "sshd_port", "cgnat_both")

# veth pairs: (host A, interface in A, host B, interface in B)
LINKS = (
    ("robot", "eth0", "robot_modem", "lan0"),
    ("laptop", "eth0", "laptop_modem", "lan0"),
    ("robot_modem", "wan0", "internet", "r-wan"),
    ("laptop_modem", "wan0", "internet", "l-wan"),
    ("carrier", "wan0", "internet", "c-wan"),
    ("outsider", "eth0", "internet", "o-wan"),
    ("relay", "eth0", "internet", "v-wan"),
    ("laptop_carrier", "wan0", "internet", "lc-wan"),
)
OUTSIDER_LINK = ("outsider", "eth0", "internet", "o-wan")

ROUTERS = ("robot_modem", "laptop_modem", "internet", "carrier", "travel_router",
           "laptop_carrier")


def ip_batch(host: str, robot_wan: str = ADDR.ROBOT_PUBLIC) -> list[str]:
    """`ip -batch` lines that address and route *host* (its links already exist)."""
    lines = ["link set lo up"]
    if host in COMPUTERS:
        lines += [f"addr add {LOCAL_IP[host]}/24 dev eth0", "link set eth0 up",
                  f"route add default via {GATEWAY[host]}"]
    elif host in ("robot_modem", "laptop_modem"):
        side = "robot" if host == "robot_modem" else "laptop"
        wan = robot_wan if side == "robot" else ADDR.LAPTOP_PUBLIC
        lines += [f"addr add {GATEWAY[side]}/24 dev lan0", "link set lan0 up",
                  f"addr add {wan}/24 dev wan0", "link set wan0 up",
                  f"route add default via {UPSTREAM[host]}"]
    elif host == "internet":
        # Point-to-point links, no bridge (a bridge port only forwards once the kernel's link
        # watcher has seen its carrier, up to a second after build). The carrier's link borrows
        # the robot side's gateway address with a host route to the carrier.
        lines += [f"addr add {ADDR.PROBE_IP}/32 dev lo", f"addr add {ADDR.DNS_IP}/32 dev lo",
                  f"addr add {ADDR.INTERNET_ROBOT_SIDE}/24 dev r-wan", "link set r-wan up",
                  f"addr add {ADDR.INTERNET_LAPTOP_SIDE}/24 dev l-wan", "link set l-wan up",
                  f"addr add {ADDR.INTERNET_ROBOT_SIDE}/32 dev c-wan", "link set c-wan up",
                  f"route add {ADDR.CARRIER_PUBLIC}/32 dev c-wan",
                  f"addr add {ADDR.INTERNET_LAPTOP_SIDE}/32 dev lc-wan", "link set lc-wan up",
                  f"route add {ADDR.LAPTOP_CARRIER_PUBLIC}/32 dev lc-wan", *outsider_internet_lines(),
                  *relay_internet_lines()]
    elif host == "outsider":
        lines += outsider_lines()
    elif host == "relay":
        lines += [f"addr add {ADDR.RELAY_IP}/32 dev eth0", "link set eth0 up",
                  f"route add {ADDR.RELAY_GW}/32 dev eth0", f"route add default via {ADDR.RELAY_GW}"]
    elif host == "carrier":
        lines += [f"addr add {ADDR.CARRIER_PUBLIC}/32 dev wan0", "link set wan0 up",
                  f"route add {ADDR.INTERNET_ROBOT_SIDE}/32 dev wan0",
                  f"route add default via {ADDR.INTERNET_ROBOT_SIDE}"]
    elif host == "laptop_carrier":
        lines += [f"addr add {ADDR.LAPTOP_CARRIER_PUBLIC}/32 dev wan0", "link set wan0 up",
                  f"route add {ADDR.INTERNET_LAPTOP_SIDE}/32 dev wan0",
                  f"route add default via {ADDR.INTERNET_LAPTOP_SIDE}"]
    return lines


def outsider_lines() -> list[str]:
    """The outsider's own addressing: a point-to-point link to the internet."""
    return [f"addr add {ADDR.OUTSIDER_IP}/32 dev eth0", "link set eth0 up",
            f"route add {ADDR.OUTSIDER_GW}/32 dev eth0",
            f"route add default via {ADDR.OUTSIDER_GW}"]


def outsider_internet_lines() -> list[str]:
    """The internet's end of the outsider's link (``o-wan``)."""
    return [f"addr add {ADDR.OUTSIDER_GW}/32 dev o-wan", "link set o-wan up",
            f"route add {ADDR.OUTSIDER_IP}/32 dev o-wan"]


def relay_internet_lines() -> list[str]:
    """The internet's end of the relay's link (``v-wan``)."""
    return [f"addr add {ADDR.RELAY_GW}/32 dev v-wan", "link set v-wan up",
            f"route add {ADDR.RELAY_IP}/32 dev v-wan"]


def sysctl_script(host: str) -> str:
    """Shell lines setting this namespace's kernel knobs (run inside the namespace)."""
    fwd = "1" if host in ROUTERS else "0"
    return "\n".join([
        f"echo {fwd} > /proc/sys/net/ipv4/ip_forward",
        "echo 0 > /proc/sys/net/ipv4/icmp_ratelimit",
        "for f in /proc/sys/net/ipv4/conf/*/rp_filter; do echo 0 > $f; done",
    ])


ZENOH_PORT = 7447
ROSBRIDGE_PORT = 9090


def forward_rules(side: str, mode: str) -> list[str]:
    """The modem's port-forwarding (DNAT) rules, for chain RNL_PF of the nat table.

    *mode*: "healthy" (22 and 1024-65000 to the computer, ROS 1), "none", "wrong" (the same, to a
    local IP where nobody is), "refuse" (none, and the modem answers every TCP connection with a
    reset), "travel" (to the travel router's WAN address, double_nat); and for ROS 2: "ros2" (TCP
    22 and TCP 7447 only: the master's router) and "ssh" (TCP 22 only: the SSH path the checks
    use to run the peer's side; no ROS traffic comes in); and for web clients: "bridge" (TCP 22
    and TCP 9090 only: SSH and the rosbridge stand-in, tests/lab/rosbridge.py).
    """
    if mode in ("none", "refuse"):
        return []
    if mode == "bridge":
        return [f"-A RNL_PF -p tcp --dport {port} -j DNAT --to-destination {LOCAL_IP[side]}"
                for port in (22, ROSBRIDGE_PORT)]
    if mode in ("ros2", "ssh"):
        rules = [f"-A RNL_PF -p tcp --dport 22 -j DNAT --to-destination {LOCAL_IP[side]}"]
        if mode == "ros2":
            rules.append(f"-A RNL_PF -p tcp --dport {ZENOH_PORT} -j DNAT --to-destination "
                         f"{LOCAL_IP[side]}")
        return rules
    target = {"healthy": LOCAL_IP[side], "travel": ADDR.TRAVEL_WAN}.get(mode, WRONG_FORWARD[side])
    return [f"-A RNL_PF -p tcp --dport 22 -j DNAT --to-destination {target}",
            f"-A RNL_PF -p tcp --dport 1024:65000 -j DNAT --to-destination {target}",
            f"-A RNL_PF -p udp --dport 1024:65000 -j DNAT --to-destination {target}"]


def refuse_rules() -> list[str]:
    """Chain RNL_REFUSE of the filter table: a modem that answers unforwarded TCP with a reset."""
    return ["-A RNL_REFUSE -i wan0 -p tcp -j REJECT --reject-with tcp-reset"]


def modem_ruleset(side: str | None) -> str:
    """A consumer modem: masquerade, port forwarding, stateful firewall (iptables-restore).

    *side* None: a router of the user's own that forwards nothing (the travel router).
    """
    return "\n".join([
        "*nat",
        ":PREROUTING ACCEPT [0:0]", ":INPUT ACCEPT [0:0]", ":OUTPUT ACCEPT [0:0]",
        ":POSTROUTING ACCEPT [0:0]", ":RNL_PF - [0:0]",
        "-A PREROUTING -i wan0 -j RNL_PF",
        "-A POSTROUTING -o wan0 -j MASQUERADE",
        *(forward_rules(side, "healthy") if side else []),
        "COMMIT",
        "*filter",
        ":INPUT DROP [0:0]", ":FORWARD DROP [0:0]", ":OUTPUT ACCEPT [0:0]", ":RNL_REFUSE - [0:0]",
        ":RNL_UNPLUG - [0:0]",
        "-A INPUT -i lo -j ACCEPT",
        "-A INPUT -m conntrack --ctstate ESTABLISHED,RELATED -j ACCEPT",
        "-A INPUT -i lan0 -j ACCEPT",
        "-A INPUT -p icmp --icmp-type echo-request -j ACCEPT",
        "-A INPUT -j RNL_REFUSE",
        "-A FORWARD -j RNL_UNPLUG",
        "-A FORWARD -m conntrack --ctstate ESTABLISHED,RELATED -j ACCEPT",
        "-A FORWARD -i lan0 -o wan0 -j ACCEPT",
        "-A FORWARD -i wan0 -o lan0 -m conntrack --ctstate DNAT -j ACCEPT",
        "COMMIT",
        "*mangle",
        ":RNL_LOSS - [0:0]",
        "-A PREROUTING -i wan0 -j RNL_LOSS",
        "-A POSTROUTING -o wan0 -j RNL_LOSS",
        "COMMIT",
        "",
    ])


def carrier_ruleset() -> str:
    """The carrier's NAT in front of the robot modem (cgnat; the laptop modem too in cgnat_both):
    no inbound forwarding at all."""
    return "\n".join([
        "*nat",
        ":PREROUTING ACCEPT [0:0]", ":INPUT ACCEPT [0:0]", ":OUTPUT ACCEPT [0:0]",
        ":POSTROUTING ACCEPT [0:0]",
        "-A POSTROUTING -s 100.64.0.0/10 -o wan0 -j MASQUERADE",
        "COMMIT",
        "*filter",
        ":INPUT DROP [0:0]", ":FORWARD DROP [0:0]", ":OUTPUT ACCEPT [0:0]",
        "-A INPUT -i lo -j ACCEPT",
        "-A INPUT -m conntrack --ctstate ESTABLISHED,RELATED -j ACCEPT",
        "-A INPUT -p icmp --icmp-type echo-request -j ACCEPT",
        "-A FORWARD -m conntrack --ctstate ESTABLISHED,RELATED -j ACCEPT",
        "-A FORWARD -o wan0 -s 100.64.0.0/10 -j ACCEPT",
        "COMMIT",
        "",
    ])


def hosts_text(host: str, *, robot_public: str = ADDR.ROBOT_PUBLIC) -> str:
    """/etc/hosts of *host* from its own point of view (own name -> local IP, peer -> public IP)."""
    lines = ["127.0.0.1\tlocalhost", "::1\tlocalhost ip6-localhost ip6-loopback"]
    if host == "robot":
        lines += [f"{ADDR.ROBOT_LOCAL}\t{ADDR.ROBOT_NAME}", f"{ADDR.LAPTOP_PUBLIC}\t{ADDR.LAPTOP_NAME}"]
    elif host == "laptop":
        lines += [f"{ADDR.LAPTOP_LOCAL}\t{ADDR.LAPTOP_NAME}", f"{robot_public}\t{ADDR.ROBOT_NAME}"]
    return "\n".join(lines) + "\n"


def resolv_text() -> str:
    return f"nameserver {ADDR.DNS_IP}\noptions timeout:1 attempts:2\n"


def bashrc_text(host: str, *, ros_ip: str | None = None) -> str:
    lines = [f"# ~/.bashrc of {HOSTNAMES[host]} (rosnet-tui network lab)",
             f"export ROS_MASTER_URI={ADDR.ROS_MASTER_URI}"]
    if ros_ip:
        lines.append(f"export ROS_IP={ros_ip}")
    return "\n".join(lines) + "\n"


# The PATH of an SSH session on a lab computer: sshd's own default for root, as on a robot. Not
# the development interpreter's folder: that python3 has eclipse-zenoh, a robot's has not (issue
# 21); the ROS 2 checks find the rosnet-tui installed in the home (tests/lab/readme_install.py).
SSH_SESSION_PATH = "/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin"


def sshd_config(host_key: str, home: str, path: str, pythonpath: str, port: int = 22) -> str:
    return "\n".join([
        f"Port {port}",
        "ListenAddress 0.0.0.0",
        f"HostKey {host_key}",
        "PidFile none",
        "PermitRootLogin prohibit-password",
        "PubkeyAuthentication yes",
        "PasswordAuthentication no",
        "KbdInteractiveAuthentication no",
        "AuthorizedKeysFile .ssh/authorized_keys",
        "UsePAM no",
        "UseDNS no",
        "PrintMotd no",
        "PrintLastLog no",
        "MaxStartups 64:30:128",
        "MaxSessions 32",
        "LogLevel INFO",
        f"SetEnv HOME={home} PATH={path}" + (f" PYTHONPATH={pythonpath}" if pythonpath else ""),
        "Subsystem sftp internal-sftp",
        "",
    ])
