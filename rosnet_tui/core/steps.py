"""The four steps of a remote ROS network, as data: what to expect, what to configure, what to check.

Every step is done on every component and on its own modem. The configuration text is Markdown,
tailored to the connection type and role in the settings; one generic screen renders any step, and
the CLI and report render the same text.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from rosnet_tui.core.procedure import STEP_IDS, STEP_TITLES, step_number
from rosnet_tui.core.settings import PORT_MAX, PORT_MIN, Settings


@dataclass(frozen=True)
class Step:
    id: str
    expected: str
    configure: Callable[[Settings], str]
    check_ids: tuple[str, ...]

    @property
    def number(self) -> int:
        return step_number(self.id)

    @property
    def title(self) -> str:
        return STEP_TITLES[self.id]


def _this_ip(s: Settings) -> str:
    return s.this.local_ip or "<this component's local IP>"


def _name(s: Settings) -> str:
    return s.this.name or "<this component>"


# --------------------------------------------------------------------------- step 1: ISP
def configure_isp(s: Settings) -> str:
    c = s.this.connection
    parts: list[str] = []
    if c == "corporate":
        parts.append(
            "**Corporate or university network.** You cannot change this network yourself. "
            "Ask the network administrator for:\n\n"
            f"- port forwarding of TCP and UDP {PORT_MIN}-{PORT_MAX} (or DMZ) to "
            f"`{_this_ip(s)}`, the address of *{_name(s)}*;\n"
            "- a public IP address that does not change;\n"
            "- who configures the router: usually the administrator does it too.\n\n"
            "Such networks are often cabled. A robot needs Wi-Fi: you may have to put a Wi-Fi "
            "router of your own behind the wall socket, and forward to it.")
    elif c == "home":
        parts.append(
            "**Home connection.** There is usually nobody to ask: you manage the modem yourself, "
            "and its internet address is your public IP.\n\n"
            "- Many home providers change that address when the modem restarts. The "
            "verification below records each address it sees, so you will know.\n"
            "- A few providers share one public address among customers (carrier-grade NAT); "
            "the carrier-NAT check below tells you if yours does.")
    else:
        parts.append(
            "**Telecom (mobile hotspot or tethered phone).** The only connection that moves with "
            "an outdoor robot, and the one with the most traps:\n\n"
            "- Call the provider and ask for the *networking* department: first-line support "
            "rarely knows what port forwarding is.\n"
            "- Ask whether port forwarding works on *your* modem and plan: many carriers allow it "
            "only on some devices or networks, or not at all.\n"
            "- Ask for a public IP. Many mobile carriers put customers behind carrier-grade NAT "
            "(addresses in 100.64.0.0/10): forwarding on the hotspot can never work there.\n"
            "- Expect the public IP to change; plan for address sync.\n"
            "- Check coverage where the robot will work, the speed (3G/4G/5G) and the data cost.")
    if s.is_master:
        parts.append(f"*{_name(s)}* runs the ROS master: every other component will reach it "
                     "through this connection, so it must accept connections from outside.")
    else:
        master = s.master_name or "the master"
        parts.append(f"*{_name(s)}* is a member: the master (*{master}*) connects back to it, so "
                     "its connection must accept connections from outside as well.")
    parts.append("**To verify:** this machine reaches the internet and learns its public IP.")
    return "\n\n".join(parts)


# --------------------------------------------------------------------------- step 2: router
def configure_router(s: Settings) -> str:
    ip = _this_ip(s)
    parts: list[str] = []
    if s.this.connection == "corporate":
        parts.append("**The administrator does this step.** Hand them these values; the "
                     "verification below tells you both whether it works.")
    parts.append(
        "Open the modem's web page (usually its gateway address in a browser) and find the "
        "firewall or port-forwarding section. Then:\n\n"
        f"1. Forward TCP (and UDP) ports **{PORT_MIN}-{PORT_MAX}** to **{ip}**, or make "
        f"**{ip}** the DMZ host (that forwards every port).\n"
        f"2. Reserve **{ip}** for this machine in the modem's DHCP settings, so the address the "
        "modem forwards to does not change after a restart.\n"
        f"3. Keep the test port **{s.probe.port}** free: nothing else should listen on it.")
    parts.append(
        "**Exposure.** Forwarding every port shows SSH and the ROS master (port "
        f"{s.ros.port}) to the whole internet, and ROS 1 has no authentication: anyone who "
        "reaches the master can drive the robot. Allow only your peers' addresses if the modem "
        "can, and use SSH keys, not passwords.")
    parts.append("**To verify:** a port tested from outside the modem is reported *Open* while "
                 "a listener runs on it, and *Closed* when nothing listens.")
    return "\n\n".join(parts)


# --------------------------------------------------------------------------- step 3: Linux
def configure_linux(s: Settings) -> str:
    profile = s.this.profile
    from rosnet_tui.core.hosts import hosts_entries  # with the Linux step, not at start-up

    entries = hosts_entries(s, profile)
    width = max((len(e.ip) for e in entries), default=0)
    block = "\n".join(f"{e.ip.ljust(width)}  {e.name}" for e in entries) or "(no entries yet)"
    where = {"remote": "peers by their public IPs (their modems)",
             "office": "everyone by their addresses on the office LAN",
             "portable": "everyone by their addresses on the portable hotspot's LAN"}[profile]
    parts = [
        f"Every component finds the others **by name**. On *{_name(s)}*, `/etc/hosts` maps its "
        f"own name to its own local IP, and {where} (profile *{profile}*):",
        f"```\n{block}\n```",
        "Use the same names on every component. `rosnet-tui hosts apply` writes these lines "
        "for you, inside a marked block, with a preview and a backup; `rosnet-tui hosts use "
        "office` (or `remote`, `portable`) switches the set when the robot changes network.",
        "SSH problems that are not network problems (keys, user names, sshd not installed) are "
        "easier to solve on a shared LAN first.",
        "**To verify:** ping, SSH and a TCP chat work by name, started from either side.",
    ]
    return "\n\n".join(parts)


# --------------------------------------------------------------------------- step 4: ROS
def configure_ros(s: Settings) -> str:
    port = s.ros.port
    if s.is_master:
        uri = f"http://{_name(s)}:{port}"
        head = (f"*{_name(s)}* is the ROS master. In `~/.bashrc`:\n\n"
                f"```\nexport ROS_MASTER_URI={uri}\n```\n\n"
                "Use its own name (or its local IP), never its public IP: roscore refuses to "
                "start on an address this machine does not have. Then start `roscore`.")
    else:
        master = s.master_name or "<master>"
        uri = f"http://{master}:{port}"
        head = (f"*{_name(s)}* is a member. In `~/.bashrc`:\n\n"
                f"```\nexport ROS_MASTER_URI={uri}\n```\n\n"
                f"The hosts file maps *{master}* to the master's public IP.")
    parts = [
        head,
        "**Do not set `ROS_IP` or `ROS_HOSTNAME`** on a remote network: they replace the names "
        "the hosts files agree on, and the result is a component that can publish but not "
        "subscribe, or the reverse. (On a single LAN they are harmless.) `rosnet-tui ros apply` "
        "writes the line above and offers to comment those out.",
        "**To verify**, in this order: the master answers (`rostopic list`); a talker on one "
        "side is heard on the other, then the reverse; finally the real robot: keyboard teleop "
        "from the laptop, and the camera in rviz (compressed or mono images spare the link).",
    ]
    return "\n\n".join(parts)


STEPS: tuple[Step, ...] = (
    Step("isp",
         "Your provider allows port forwarding on every port of this connection, and the modem "
         "has a public IP address that the other components can reach.",
         configure_isp, ("isp.internet", "isp.public_ip", "isp.cgnat")),
    Step("router",
         "A port tested from outside the modem is reported Open: the modem forwards it to "
         "this component.",
         configure_router,
         ("router.local_ip", "router.port_free", "router.listener", "router.port_open")),
    Step("linux",
         "The components ping each other by name, open SSH sessions by name, and exchange "
         "messages over TCP by name, whichever side starts.",
         configure_linux,
         ("linux.hosts", "linux.resolve", "linux.ping", "linux.ssh", "linux.chat_out",
          "linux.chat_in")),
    Step("ros",
         "Every component registers with the one ROS master, and each can both publish and "
         "subscribe.",
         configure_ros,
         ("ros.env", "ros.master", "ros.node_uris", "ros.pubsub_out", "ros.pubsub_in")),
)

STEP_BY_ID = {s.id: s for s in STEPS}
assert tuple(STEP_BY_ID) == STEP_IDS, "the steps are listed in the procedure's order"
