"""A delay between the two sites of the ROS 1 lab (this kernel has no netem): every TCP
connection between them, whatever its port, goes through one userspace hop on the robot's
modem (tests/lab/delay_relay.py in its ORIGINAL mode) that holds each chunk DELAY ms each way.

ROS 1 needs more than one port: XML-RPC to the master (11311) and to every node's own port, and
TCPROS to each publisher's port, chosen when the node starts, in both directions (the robot's
subscriber dials the laptop's publisher through the laptop's modem). So the hop is not on one
forwarded port: iptables REDIRECTs every TCP connection to the forwarded range, from the internet
to the robot and from the robot to the laptop's public address, to the hop, which dials where
each was going (the modem's own public address mapped to the robot it forwards to). SSH (22)
is left alone: the checks' peer side starts as fast as before.
"""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Iterator
from pathlib import Path

from .topology import ADDR

DELAY_RELAY = Path(__file__).resolve().parent / "delay_relay.py"


@contextlib.contextmanager
def delay_between_sites(lab, delay_ms: float, port: int = 17311,
                        max_s: float = 300) -> Iterator[None]:
    """Every new TCP connection between the laptop's site and the robot's (ports 1024-65000)
    held *delay_ms* ms each way by a hop on the robot's modem; taken off after the block."""
    redirects = [f"PREROUTING -i wan0 -p tcp -d {ADDR.ROBOT_PUBLIC} --dport 1024:65000 "
                 f"-j REDIRECT --to-ports {port}",
                 f"PREROUTING -i lan0 -p tcp -d {ADDR.LAPTOP_PUBLIC} --dport 1024:65000 "
                 f"-j REDIRECT --to-ports {port}"]
    accept = f"INPUT -i wan0 -p tcp --dport {port} -j ACCEPT"
    relay = lab.spawn("robot_modem", [
        sys.executable, str(DELAY_RELAY), "0.0.0.0", str(port), "ORIGINAL",
        f"{ADDR.ROBOT_PUBLIC}={ADDR.ROBOT_LOCAL}", f"{delay_ms:g}", f"{max_s:g}", "4000"])
    added: list[str] = []
    try:
        if not lab.wait_output(relay, r"RELAY READY", timeout=10):
            raise RuntimeError(f"the delay relay did not start: {lab.output(relay)}")
        lab._in_ns("robot_modem", f"iptables -I {accept}")
        added.append(f"iptables -D {accept}")
        for rule in redirects:
            lab._in_ns("robot_modem", f"iptables -t nat -I {rule}")
            added.append(f"iptables -t nat -D {rule}")
        yield
    finally:
        for undo in reversed(added):
            lab._in_ns("robot_modem", undo, check=False)
        lab.kill(relay, grace=0.5)
