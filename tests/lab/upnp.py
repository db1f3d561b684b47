"""The robot's modem as a real UPnP IGD / NAT-PMP / PCP gateway: Debian's own miniupnpd.

``with UpnpModem(lab) as m:`` runs miniupnpd 2.x (the nftables build) inside the robot modem's
namespace, unmodified, for the block:

- its rules live in a table of our own (``inet rnl_upnp``: a forward chain with policy accept
  jumping to ``miniupnpd``, nat prerouting/postrouting jumping to its nat chains); Debian's
  ``nft_init.sh`` is not used (on bookworm it creates nothing, and its forward policy is drop).
  The modem's iptables FORWARD already accepts ``ctstate DNAT`` from the WAN, so mapped
  connections pass;
- miniupnpd treats the documentation ranges the lab uses as "public" addresses as reserved (it
  would report an empty external address and refuse every mapping, as behind carrier NAT), so a
  STUN server (Debian's ``stund``) runs on the internet side (192.0.2.10 and .11) and miniupnpd
  learns the WAN address through it (``stun=False`` leaves it out: the reserved-address case);
- options: ``secure_mode`` (a LAN host may only map to itself), ``upnp`` / ``natpmp`` (NAT-PMP and
  PCP share the switch), allow 1024-65535 from 10.10.10.0/24 and deny everything else;
- the modem's manual forwards are set to ``forward`` for the block (default ``"ssh"``: TCP 22
  only, the path the checks use to reach the robot; nothing for ROS);
- ``second_host=True`` adds another LAN host (namespace ``lan2``, 10.10.10.3) behind the same
  modem, on a link of its own (``lan1`` on the modem), to hold conflicting mappings.

Leaving the block stops miniupnpd and stund, deletes the table (miniupnpd leaves its DNAT rules
behind when it stops) and the second host. Bring-up takes about a quarter of a second.
"""

from __future__ import annotations

import subprocess
import time
from pathlib import Path
from typing import Any

from . import procs
from .lab import Lab, wait_links_settled
from .topology import ADDR

TABLE = "rnl_upnp"
HTTP_PORT = 5000
STUN_OTHER_IP = "192.0.2.11"        # stund's second address (the NAT-type test needs two)
LAN2_IP = "10.10.10.3"
UUID = "1f0c3c2e-5a0b-4a40-9c1d-7e2f00000018"
MINIUPNPD = "/usr/sbin/miniupnpd"
STUND = "/usr/sbin/stund"
NFT = "/usr/sbin/nft"
NATPMPC = "/usr/bin/natpmpc"   # the second LAN host's own NAT-PMP client


def upnp_available() -> tuple[bool, str]:
    missing = [p for p in (MINIUPNPD, STUND, NFT, NATPMPC) if not Path(p).exists()]
    if missing:
        return False, ("the UPnP lab needs Debian's miniupnpd, stun-server, nftables and natpmpc: "
                       + ", ".join(missing) + " missing")
    return True, ""


def nft_ruleset() -> str:
    return "\n".join([
        f"table inet {TABLE} {{",
        "  chain forward { type filter hook forward priority 0; policy accept; jump miniupnpd; }",
        "  chain miniupnpd { }",
        "  chain prerouting { type nat hook prerouting priority -100; policy accept; "
        "jump prerouting_miniupnpd; }",
        "  chain postrouting { type nat hook postrouting priority 100; policy accept; "
        "jump postrouting_miniupnpd; }",
        "  chain prerouting_miniupnpd { }",
        "  chain postrouting_miniupnpd { }",
        "}", ""])


def miniupnpd_conf(*, secure: bool, upnp: bool, natpmp: bool, stun: bool) -> str:
    yes = {True: "yes", False: "no"}
    lines = [
        "ext_ifname=wan0",
        "listening_ip=lan0",
        f"http_port={HTTP_PORT}",
        f"enable_upnp={yes[upnp]}",
        f"enable_natpmp={yes[natpmp]}",
        f"secure_mode={yes[secure]}",
        "system_uptime=yes",
        f"uuid={UUID}",
        "friendly_name=rosnet-tui lab modem",
        f"upnp_table_name={TABLE}",
        f"upnp_nat_table_name={TABLE}",
        "upnp_forward_chain=miniupnpd",
        "upnp_nat_chain=prerouting_miniupnpd",
        "upnp_nat_postrouting_chain=postrouting_miniupnpd",
        "min_lifetime=120",
        "max_lifetime=86400",
        "allow 1024-65535 10.10.10.0/24 1024-65535",
        "deny 0-65535 0.0.0.0/0 0-65535",
    ]
    if stun:
        lines += ["ext_perform_stun=yes", f"ext_stun_host={ADDR.PROBE_IP}"]
    return "\n".join(lines) + "\n"


class UpnpModem:
    def __init__(self, lab: Lab, *, secure: bool = True, upnp: bool = True, natpmp: bool = True,
                 stun: bool = True, second_host: bool = False, forward: str = "ssh") -> None:
        self.lab = lab
        self.secure, self.upnp, self.natpmp, self.stun = secure, upnp, natpmp, stun
        self.second_host = second_host
        self.forward = forward
        self._forward_before: str | None = None
        self.miniupnpd: subprocess.Popen | None = None
        self.stund: subprocess.Popen | None = None
        assert lab.dir is not None
        self.dir = lab.dir / "upnp"
        self.lan2 = lab.prefix + "lan2"

    # ------------------------------------------------------------------ where things are
    @property
    def gateway(self) -> str:
        return ADDR.ROBOT_GW

    @property
    def location(self) -> str:
        return f"http://{ADDR.ROBOT_GW}:{HTTP_PORT}/rootDesc.xml"

    def log(self) -> str:
        p = self.dir / "miniupnpd.log"
        return p.read_text(errors="replace") if p.exists() else ""

    def _sh(self, ns: str, script: str, check: bool = True) -> subprocess.CompletedProcess:
        r = subprocess.run(["ip", "netns", "exec", ns, "sh", "-ec", script], text=True,
                           capture_output=True, timeout=10)
        if check and r.returncode != 0:
            raise RuntimeError(f"in {ns}: {script!r}: {r.stderr.strip()}")
        return r

    def nat_rules(self) -> str:
        """miniupnpd's DNAT chain as nft lists it (what the modem forwards right now)."""
        r = self._sh(self.lab.ns("robot_modem"),
                     f"{NFT} list chain inet {TABLE} prerouting_miniupnpd", check=False)
        return r.stdout

    # ------------------------------------------------------------------ the second LAN host
    def run_lan2(self, argv: list[str], timeout: float = 20, env: dict | None = None
                 ) -> subprocess.CompletedProcess:
        """Run *argv* on the second LAN host (10.10.10.3)."""
        return subprocess.run(["ip", "netns", "exec", self.lan2, *argv], text=True,
                              capture_output=True, timeout=timeout,
                              env=env if env is not None else self.lab.env("robot_modem"))

    def _add_lan2(self) -> None:
        modem = self.lab.ns("robot_modem")
        lines = [f"netns add {self.lan2}",
                 f"link add name eth0 netns {self.lan2} type veth peer name lan1 netns {modem}"]
        r = subprocess.run(["ip", "-batch", "-"], input="\n".join(lines) + "\n", text=True,
                           capture_output=True, timeout=10)
        if r.returncode != 0:
            raise RuntimeError(f"second LAN host: {r.stderr.strip()}")
        self._sh(self.lan2, f"ip link set lo up; ip addr add {LAN2_IP}/24 dev eth0; "
                            f"ip link set eth0 up; ip route add default via {ADDR.ROBOT_GW}")
        self._sh(modem, f"ip addr add {ADDR.ROBOT_GW}/32 dev lan1; ip link set lan1 up; "
                        f"ip route add {LAN2_IP}/32 dev lan1; "
                        "echo 0 > /proc/sys/net/ipv4/conf/lan1/rp_filter; "
                        "iptables -I INPUT -i lan1 -j ACCEPT; "
                        "iptables -I FORWARD -i lan1 -o wan0 -j ACCEPT")
        wait_links_settled([self.lan2, modem])

    def _remove_lan2(self) -> None:
        modem = self.lab.ns("robot_modem")
        self._sh(modem, "iptables -D INPUT -i lan1 -j ACCEPT; "
                        "iptables -D FORWARD -i lan1 -o wan0 -j ACCEPT", check=False)
        r = subprocess.run(["ip", "netns", "pids", self.lan2], capture_output=True, text=True,
                           timeout=5)
        for pid in r.stdout.split():
            procs.signal_pids([int(pid)], 9)
        subprocess.run(["ip", "netns", "delete", self.lan2], capture_output=True, timeout=10)

    # ------------------------------------------------------------------ up and down
    def __enter__(self) -> UpnpModem:
        ok, why = upnp_available()
        if not ok:
            import pytest

            pytest.skip(why)
        try:
            self.start()
        except BaseException:
            self.stop()
            raise
        return self

    def start(self) -> None:
        self.dir.mkdir(exist_ok=True)
        modem, internet = self.lab.ns("robot_modem"), self.lab.ns("internet")
        # No manual forward (by default only SSH, the path the checks use to reach the robot).
        self._forward_before = self.lab._state["forward"]["robot"]
        self.lab._set_forwarding("robot", self.forward)
        if self.stun:
            self._sh(internet, f"ip addr replace {STUN_OTHER_IP}/32 dev lo")
            with open(self.dir / "stund.log", "w") as log:
                self.stund = self.lab.spawn("internet", [STUND, "-h", ADDR.PROBE_IP, "-a",
                                                         STUN_OTHER_IP],
                                            stdout=log, stderr=subprocess.STDOUT)
            if not self.lab.wait_listening("internet", 3478, "udp", timeout=5, proc=self.stund):
                raise RuntimeError("stund did not start: "
                                   + (self.dir / "stund.log").read_text(errors="replace"))
            # The modem's own firewall drops what it did not ask for; miniupnpd's NAT-type test
            # needs the answers stund sends from its other address and port.
            self._sh(modem, f"iptables -I INPUT -i wan0 -p udp -s {ADDR.PROBE_IP}/31 -j ACCEPT")
        (self.dir / "rules.nft").write_text(nft_ruleset())
        self._sh(modem, f"{NFT} delete table inet {TABLE} 2>/dev/null || true; "
                        f"{NFT} -f {self.dir / 'rules.nft'}")
        if self.second_host:
            self._add_lan2()
        conf = self.dir / "miniupnpd.conf"
        conf.write_text(miniupnpd_conf(secure=self.secure, upnp=self.upnp, natpmp=self.natpmp,
                                       stun=self.stun))
        with open(self.dir / "miniupnpd.log", "w") as log:
            self.miniupnpd = self.lab.spawn(
                "robot_modem", [MINIUPNPD, "-f", str(conf), "-d", "-P",
                                str(self.dir / "miniupnpd.pid")],
                stdout=log, stderr=subprocess.STDOUT)
        port, proto = (HTTP_PORT, "tcp") if self.upnp else (5351, "udp")
        if not self.lab.wait_listening("robot_modem", port, proto, timeout=10,
                                       proc=self.miniupnpd):
            raise RuntimeError("miniupnpd did not start:\n" + self.log()[-3000:])

    def stop(self) -> None:
        if self.miniupnpd is not None:
            self.lab.kill(self.miniupnpd, grace=1.0)
            self.miniupnpd = None
        if self.stund is not None:
            self.lab.kill(self.stund, grace=0.5)
            self.stund = None
        if not self.lab.destroyed:
            self._sh(self.lab.ns("robot_modem"),
                     f"{NFT} delete table inet {TABLE} 2>/dev/null || true", check=False)
            self._sh(self.lab.ns("robot_modem"), "conntrack -F 2>/dev/null || true", check=False)
            if self.stun:
                self._sh(self.lab.ns("robot_modem"), "iptables -D INPUT -i wan0 -p udp -s "
                                                     f"{ADDR.PROBE_IP}/31 -j ACCEPT", check=False)
                self._sh(self.lab.ns("internet"),
                         f"ip addr del {STUN_OTHER_IP}/32 dev lo 2>/dev/null || true",
                         check=False)
            if self.second_host:
                self._remove_lan2()
            if self._forward_before is not None:
                self.lab._set_forwarding("robot", self._forward_before)
                self._forward_before = None
        (self.dir / "miniupnpd.pid").unlink(missing_ok=True)

    def __exit__(self, *exc: Any) -> None:
        self.stop()

    def restart(self, **options: Any) -> None:
        """Stop and start again with other options (secure, upnp, natpmp, stun)."""
        self.stop()
        for k, v in options.items():
            setattr(self, k, v)
        self.start()

    def wait_mapped(self, port: int, present: bool = True, timeout: float = 5.0) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if (f"dport {port} " in self.nat_rules()) == present:
                return True
            time.sleep(0.05)
        return False


__all__ = ["LAN2_IP", "UpnpModem", "upnp_available"]
