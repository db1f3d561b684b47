"""An N-site lab: a master and N-1 members (N = 2..9), each a computer behind its own modem.

    from tests.lab.fleet import Fleet   # in pytest: the `fleet` fixture (tests/lab/fixtures.py)

Same conventions as the two-site lab (tests/lab/lab.py, of which Fleet is a subclass): namespaces
named ``rnl-<pid>-<n>-<host>`` (tests/lab/cleanup.py sweeps them), each computer with its own
hostname, /etc/netns hosts and resolv.conf, HOME (.bashrc, .ssh) and sshd; the "internet"
namespace carries the product's probe server (http://probe.lab.test = 192.0.2.10: what-is-my-IP
and port checks) and the resolver (192.0.2.53).

    turtlebot 10.10.10.1 - turtlebot-modem 10.10.10.254 | 203.0.113.2 -- w0 -.
      (the master)                                                        |  internet
    sami 192.168.1.10    - sami-modem 192.168.1.254     | 198.51.100.2 -- w1 -+  203.0.113.1
    member2 192.168.2.10 - member2-modem 192.168.2.254  | 198.51.100.3 -- w2 -+  198.51.100.1
    ...                                                                       |  192.0.2.10/.53
    member8 192.168.8.10 - member8-modem 192.168.8.254  | 198.51.100.9 -- w8 -'

Each modem's WAN is a point-to-point link to the internet (a /32 and a host route each way, no
bridge), so the number of sites changes nothing but the count. Every computer's hosts file maps
its own name to its local address and every other computer's name to that one's public address;
every computer trusts every other's user key and knows its host key by name.

A modem masquerades and forwards by *mode* (:meth:`Fleet.set_forwarding`): ``ros1`` (TCP 22 and
TCP/UDP 1024-65000 to its computer: ROS 1, where every component needs inbound ports), ``ros2``
(TCP 22 and TCP 7447, the master's Zenoh router), ``ssh`` (TCP 22 only) or ``none``. The build
sets ``ros1`` everywhere; tests/lab/fleet_ros2.py switches to ROS 2.
"""

from __future__ import annotations

import subprocess
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from . import readme_install, topology
from .lab import Lab
from .topology import ADDR, ZENOH_PORT

MAX_SITES = 9
NAMES = ("turtlebot", "sami", *(f"member{i}" for i in range(2, MAX_SITES)))
FORWARD_MODES = ("ros1", "ros2", "ssh", "none")


@dataclass(frozen=True)
class Site:
    """One site: a computer (host key = its hostname) behind its modem."""

    index: int
    name: str
    local_ip: str
    gateway: str
    public_ip: str
    upstream: str        # the internet's address on the modem's WAN link

    @property
    def modem(self) -> str:
        return f"{self.name}-modem"

    @property
    def wan_if(self) -> str:
        """The internet side's interface of this site's WAN link."""
        return f"w{self.index}"

    @property
    def is_master(self) -> bool:
        return self.index == 0


def site(index: int) -> Site:
    if index == 0:
        return Site(0, NAMES[0], ADDR.ROBOT_LOCAL, ADDR.ROBOT_GW, ADDR.ROBOT_PUBLIC,
                    ADDR.INTERNET_ROBOT_SIDE)
    return Site(index, NAMES[index], f"192.168.{index}.10", f"192.168.{index}.254",
                f"198.51.100.{index + 1}", ADDR.INTERNET_LAPTOP_SIDE)


def forward_rules(local_ip: str, mode: str) -> list[str]:
    """A modem's DNAT rules (chain RNL_PF of the nat table) for *mode* (see the module doc)."""
    if mode not in FORWARD_MODES:
        raise ValueError(f"unknown forwarding mode {mode!r} (known: {', '.join(FORWARD_MODES)})")
    if mode == "none":
        return []
    rules = [f"-A RNL_PF -p tcp --dport 22 -j DNAT --to-destination {local_ip}"]
    if mode == "ros2":
        rules.append(f"-A RNL_PF -p tcp --dport {ZENOH_PORT} -j DNAT --to-destination {local_ip}")
    elif mode == "ros1":
        rules += [f"-A RNL_PF -p {p} --dport 1024:65000 -j DNAT --to-destination {local_ip}"
                  for p in ("tcp", "udp")]
    return rules


class Fleet(Lab):
    """A master and ``sites - 1`` members. Lab's running, output and tear-down methods apply;
    hosts are the computers' names (``fleet.master``, ``fleet.members``), their modems
    (``<name>-modem``) and ``internet``. The two-site lab's variants do not apply here."""

    def __init__(self, sites: int = 3) -> None:
        if not 2 <= sites <= MAX_SITES:
            raise ValueError(f"a fleet has 2 to {MAX_SITES} sites, not {sites}")
        super().__init__()
        self.sites = [site(i) for i in range(sites)]
        self.by_name = {s.name: s for s in self.sites}
        self.COMPUTERS = tuple(s.name for s in self.sites)
        self.SERVERS = ()                 # no relay in a fleet
        self.HOSTS = (*self.COMPUTERS, *(s.modem for s in self.sites), "internet", "outsider")
        self.ROUTERS = (*(s.modem for s in self.sites), "internet")
        self.forwarding = {s.name: "ros1" for s in self.sites}
        self.slowed: dict[str, str | None] = {}   # host -> its line's rate (set_rate)
        self.wan_ip: dict[str, str] = {}    # host -> its modem's public address (set_public_ip)
        self.build_s: dict[str, float] = {}    # seconds per build phase, and "total"

    # ------------------------------------------------------------------ names
    @property
    def master(self) -> str:
        return self.sites[0].name

    @property
    def members(self) -> list[str]:
        return [s.name for s in self.sites[1:]]

    def hostname(self, host: str) -> str:
        self.ns(host)  # refuses an unknown host
        return host

    def _computer(self, host: str) -> None:
        if host not in self.COMPUTERS:
            raise ValueError(f"{host!r} is not a computer of this fleet "
                             f"(known: {', '.join(self.COMPUTERS)})")

    def public_ip(self, host: str) -> str:
        self._computer(host)
        return self.by_name[host].public_ip

    def local_ip(self, host: str) -> str:
        self._computer(host)
        return self.by_name[host].local_ip

    def settings_public_ip(self, host: str) -> str:
        return self.public_ip(host)

    def peers_of(self, host: str) -> list[str]:
        """Every other computer of the fleet."""
        self._computer(host)
        return [o for o in self.COMPUTERS if o != host]

    # ------------------------------------------------------------------ configuration text
    def ip_batch(self, host: str) -> list[str]:
        """`ip -batch` lines that address and route *host* (its links already exist)."""
        lines = ["link set lo up"]
        if host in self.COMPUTERS:
            s = self.by_name[host]
            return lines + [f"addr add {s.local_ip}/24 dev eth0", "link set eth0 up",
                            f"route add default via {s.gateway}"]
        if host == "internet":
            lines += [f"addr add {ADDR.PROBE_IP}/32 dev lo", f"addr add {ADDR.DNS_IP}/32 dev lo"]
            for s in self.sites:
                lines += [f"addr add {s.upstream}/32 dev {s.wan_if}", f"link set {s.wan_if} up",
                          f"route add {s.public_ip}/32 dev {s.wan_if}"]
            return lines + topology.outsider_internet_lines()
        if host == "outsider":
            return lines + topology.outsider_lines()
        s = next(x for x in self.sites if x.modem == host)
        return lines + [f"addr add {s.gateway}/24 dev lan0", "link set lan0 up",
                        f"addr add {s.public_ip}/32 dev wan0", "link set wan0 up",
                        f"route add {s.upstream}/32 dev wan0",
                        f"route add default via {s.upstream}"]

    def modem_ruleset(self, name: str) -> str:
        """The consumer modem of the two-site lab, forwarding as self.forwarding[name] says."""
        text = topology.modem_ruleset(None)
        rules = forward_rules(self.by_name[name].local_ip, self.forwarding[name])
        head, sep, tail = text.partition("COMMIT\n*filter")
        return head + "".join(r + "\n" for r in rules) + sep + tail

    def hosts_text(self, host: str) -> str:
        """*host*'s /etc/hosts: its own name -> local IP, every other computer -> public IP."""
        if host not in self.COMPUTERS:
            return topology.hosts_text(host)
        lines = ["127.0.0.1\tlocalhost", "::1\tlocalhost ip6-localhost ip6-loopback"]
        lines += [f"{s.local_ip if s.name == host else s.public_ip}\t{s.name}" for s in self.sites]
        return "\n".join(lines) + "\n"

    def bashrc_text(self, host: str) -> str:
        return (f"# ~/.bashrc of {host} (rosnet-tui network lab, fleet)\n"
                f"export ROS_MASTER_URI=http://{self.master}:11311\n")

    # ------------------------------------------------------------------ build
    def _build(self) -> None:
        assert self.dir is not None
        t0 = time.monotonic()
        (self.dir / "logs").mkdir()
        lines = [f"netns add {self.ns(h)}" for h in self.HOSTS]
        for s in self.sites:
            lines += [f"link add name eth0 netns {self.ns(s.name)} type veth peer name lan0 "
                      f"netns {self.ns(s.modem)}",
                      f"link add name wan0 netns {self.ns(s.modem)} type veth peer name "
                      f"{s.wan_if} netns {self.ns('internet')}"]
        a, ia, b, ib = topology.OUTSIDER_LINK   # a stranger on the internet (issue 22)
        lines.append(f"link add name {ia} netns {self.ns(a)} type veth peer name {ib} "
                     f"netns {self.ns(b)}")
        self._create_links(lines)
        t1 = time.monotonic()
        self._write_files()
        t2 = time.monotonic()
        self._configure_namespaces()
        t3 = time.monotonic()
        self._start_services()
        self.settle_links()
        t4 = time.monotonic()
        for name in self.COMPUTERS:
            self.install_rosnet(name)
        t5 = time.monotonic()
        self.build_s = {"namespaces": t1 - t0, "files": t2 - t1, "network": t3 - t2,
                        "services": t4 - t3, "install": t5 - t4, "total": t5 - t0}

    def install_rosnet(self, host: str) -> None:
        """Install rosnet-tui on *host* the README's way (a pipx-style venv in its home on the
        distribution's python3, which has no eclipse-zenoh): the peer side of the ROS 2 checks
        runs with it, as on a real fleet."""
        readme_install.install(self.home(host))

    def _namespace_script(self, host: str, hdir: Path) -> list[str]:
        fwd = "1" if host in self.ROUTERS else "0"
        sysctl = [f"echo {fwd} > /proc/sys/net/ipv4/ip_forward",
                  *topology.sysctl_script(host).splitlines()[1:]]
        script = [*sysctl, f"ip -batch {hdir / 'ip.batch'}", *sysctl]
        if host.endswith("-modem"):
            (hdir / "rules.v4").write_text(self.modem_ruleset(host[:-len("-modem")]))
            script.append(f"iptables-restore {hdir / 'rules.v4'}")
        return script

    # ------------------------------------------------------------------ the network
    def set_forwarding(self, host: str, mode: str) -> None:
        """Port forwarding of *host*'s modem: 'ros1', 'ros2', 'ssh' or 'none'."""
        s = self.by_name[host]
        rules = "\n".join(["*nat", "-F RNL_PF", *forward_rules(s.local_ip, mode), "COMMIT", ""])
        r = subprocess.run(["ip", "netns", "exec", self.ns(s.modem), "iptables-restore",
                            "--noflush"], input=rules, text=True, capture_output=True, timeout=10)
        if r.returncode != 0:
            raise RuntimeError(f"forwarding on {s.modem}: {r.stderr.strip()}")
        self.forwarding[host] = mode

    def set_rate(self, host: str, rate: str | None) -> None:
        """A slow line at *host*'s site: its modem passes at most *rate* (tc tbf, e.g. "200kbit")
        each way, queueing (not dropping) up to 2 s; None: full speed again."""
        modem = self.by_name[host].modem
        script = "\n".join(f"tc qdisc replace dev {dev} root tbf rate {rate} burst 16kbit "
                           f"latency 2000ms" if rate else
                           f"tc qdisc del dev {dev} root 2>/dev/null || true"
                           for dev in ("wan0", "lan0"))
        self._in_ns(modem, script)
        self.slowed[host] = rate

    def set_public_ip(self, host: str, ip: str | None) -> None:
        """Give *host*'s modem a new public address now (a modem restart with a new IP from its
        provider); None: the one it was built with. Hosts files and settings are not touched
        (that is the sync service's work)."""
        s = self.by_name[host]
        ip = ip or s.public_ip
        if not ip.startswith(("198.51.100.", "203.0.113.")) or ip in (
                ADDR.INTERNET_ROBOT_SIDE, ADDR.INTERNET_LAPTOP_SIDE) or any(
                o.public_ip == ip for o in self.sites if o is not s):
            raise ValueError(f"{ip} is not a free lab public address")
        old = self.wan_ip.get(host, s.public_ip)
        if old == ip:
            return
        self._ip(s.modem, ["addr flush dev wan0", f"addr add {ip}/32 dev wan0",
                           f"route add {s.upstream}/32 dev wan0",
                           f"route replace default via {s.upstream}"])
        self._ip("internet", [f"route del {old}/32 dev {s.wan_if}",
                              f"route add {ip}/32 dev {s.wan_if}"])
        self.wan_ip[host] = ip

    def reset(self) -> None:
        """Back to the network as built: ROS 1 forwarding, full speed, public addresses, hosts
        files, ~/.bashrc, settings."""
        if not self.built or self.destroyed:
            return
        for h in list(self.wan_ip):
            self.set_public_ip(h, None)
            del self.wan_ip[h]
        for h in [h for h, rate in self.slowed.items() if rate]:
            self.set_rate(h, None)
        for h in self.COMPUTERS:
            if self.forwarding[h] != "ros1":
                self.set_forwarding(h, "ros1")
            if self.hosts_path(h).read_text() != self.hosts_text(h):
                self.write_hosts(h, self.hosts_text(h))
            if self.bashrc_path(h).read_text() != self.bashrc_text(h):
                self.bashrc_path(h).write_text(self.bashrc_text(h))
            self.config_path(h)
        self._reset_state()

    def variant(self, name: str, **options: Any):
        raise NotImplementedError("the fleet has no variants (see tests/lab/lab.py for them)")

    # ------------------------------------------------------------------ ROS 1
    def ros_env(self, host: str) -> dict[str, str]:
        self._computer(host)
        env = self.env(host)
        env["ROS_MASTER_URI"] = f"http://{self.master}:11311"
        return env


__all__ = ["FORWARD_MODES", "MAX_SITES", "NAMES", "Fleet", "Site", "forward_rules", "site"]
