"""The four steps of a remote ROS network, as data: what to expect, what to configure, what to check.

Every step is done on every component and on its own modem. The configuration text is Markdown,
tailored to the connection type and role in the settings; one generic screen renders any step, and
the CLI and report render the same text.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

from rosnet_tui.core.config.settings_model import PORT_MAX, PORT_MIN, Settings
from rosnet_tui.core.procedure import STEP_IDS, STEP_TITLES, step_number
from rosnet_tui.core.ros import rosbridge


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
    if s.ros2:
        return configure_isp_ros2(s)
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
def configure_lan_router(s: Settings) -> str:
    """The Router step on a LAN profile (office, portable): nothing is forwarded."""
    lan = {"office": "the office LAN",
           "portable": "the portable hotspot's LAN"}.get(s.this.profile, "one LAN")
    return "\n\n".join([
        f"**Nothing to forward on {lan}** (profile *{s.this.profile}*). Every component is on "
        "the same LAN and reaches the others directly at their LAN addresses: no port "
        "forwarding, no DMZ, and no exposure to the internet. A phone hotspot cannot forward "
        "ports at all, and here it does not need to.",
        f"What still matters:\n\n"
        f"1. Keep **{_this_ip(s)}** for this machine (a DHCP reservation, where the router "
        "or hotspot allows it): the hosts entries of the others use it.\n" + (
            f"2. ROS 2: the master's Zenoh router listens on TCP **{s.ros.zenoh_port}** and "
            "the members' routers connect to it by name, across the LAN." if s.ros2 else
            f"2. Keep the test port **{s.probe.port}** free for the Linux step's chat test."),
        "**To verify:** the outside port test is skipped on this profile; the Linux step tests "
        "the LAN itself (ping, SSH and " + (
            "each member's connection by name to the master's router port" if s.ros2 else
            "a chat by name, both ways") + "). Switch to the *remote* profile (`rosnet-tui "
        "hosts use remote`) before the robot leaves this LAN.",
    ])


def configure_router(s: Settings) -> str:
    if s.this.profile != "remote":      # a LAN profile: nothing needs forwarding
        return configure_lan_router(s)
    bridge = rosbridge.router_text(s)
    if s.ros2 and bridge and not s.is_master:   # a member running rosbridge: only its port
        return (f"**Only rosbridge needs a forward on {_name(s)}'s modem.** Its Zenoh router "
                "connects out to the master's, so ROS 2 itself needs nothing here.\n\n"
                f"{bridge}\n\n**To verify:** the other components' ROS step opens "
                f"`{rosbridge.url(s)}` through this forward.")
    if s.ros2:
        return configure_router_ros2(s) + (f"\n\n{bridge}" if bridge else "")
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
    from rosnet_tui.core.exposure.router_card import ros1_exposure

    parts.append("**Exposure.** Forwarding every port shows the ROS master and SSH to the "
                 "internet. " + ros1_exposure(s) + " Use SSH keys, not passwords.")
    parts.append(_source_restriction(s))
    if bridge:
        parts.append(bridge)
    parts.append("**To verify:** a port tested from outside the modem is reported *Open* while "
                 "a listener runs on it, and *Closed* when nothing listens.")
    return "\n\n".join(parts)


def _source_restriction(s: Settings) -> str:
    """ROS 1: restricting the forward by source on the modem (the better place, where it can),
    and the peers-only firewall of the Linux step (where it cannot)."""
    peers = ", ".join(f"**{p.public_ip}** ({p.name})" for p in s.peers if p.public_ip)
    return (
        "**Only the peers, better on the modem.** Some modems let a forwarding rule name a "
        "source (fields like *Remote IP*, *Source IP*, *Allowed remote host* or *External "
        "host*; business routers: an access list on the rule). Where yours does, give each "
        "forward (the range, 22) one rule per peer, with the peer's public address as the "
        f"source{': ' + peers if peers else ''}. The modem then drops strangers before they reach "
        "this machine. When a peer's public address changes, that rule must change too (the "
        "modem has no sync). Where the modem cannot, the Linux step's firewall "
        "(`rosnet-tui firewall apply`) does the same on this machine, and the sync service "
        "keeps it current.")


# --------------------------------------------------------------------------- step 3: Linux
def configure_linux(s: Settings) -> str:
    profile = s.this.profile
    from rosnet_tui.core.files.hosts import hosts_entries  # with the Linux step, not at start-up

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
    if not s.ros2:
        from rosnet_tui.core.exposure import firewall

        parts.insert(-1, "**Only the peers get in (ROS 1).** " + (
            "`rosnet-tui firewall apply` (or `w`, after the hosts set) loads an nftables table "
            f"of ours, `{firewall.TABLE}`: on the forwarded ports (22, {PORT_MIN}-{PORT_MAX}, "
            f"{s.ros.port}) it lets in only your peers, your LAN, the addresses you allow and the "
            "SSH session that loads it (and loopback, and replies); no other table is "
            "touched, and `rosnet-tui undo` removes it." if firewall.wanted(s) else
            "`[ros] security = \"none\"`: no firewall; the forwarded ports answer anyone."))
    if s.ros2:
        parts[-1] = (f"**To verify (ROS 2):** ping and SSH by name, and the one connection ROS 2 "
                     f"needs: from each member, by name, to the master's router port "
                     f"(`{s.master_name or 'master'}:{s.ros.zenoh_port}`). Nothing connects to a "
                     "member, so its inbound chat is skipped.")
    return "\n\n".join(parts)


# --------------------------------------------------------------------------- step 4: ROS
def configure_ros(s: Settings) -> str:
    """The ROS step's text for the settings' ROS version, with rosbridge's when it is on."""
    bridge = rosbridge.ros_step_text(s)
    text = configure_ros2(s) if s.ros2 else configure_ros1(s)
    return text + (f"\n\n{bridge}" if bridge else "")


def configure_ros1(s: Settings) -> str:
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


# --------------------------------------------------------------------------- ROS 2 (rmw_zenoh)
def _master_word(s: Settings) -> str:
    return s.master_name or "<master>"


def configure_isp_ros2(s: Settings) -> str:
    c, port = s.this.connection, s.ros.zenoh_port
    kind = {"corporate": "**Corporate or university network.** Ask the network administrator",
            "home": "**Home connection.** You manage the modem yourself",
            "telecom": "**Telecom (mobile hotspot or tethered phone).** Ask the carrier's "
                       "networking department (not first-line support)"}[c]
    if s.relayed:
        need = (f"Under the relay *{s.relay.host}* every router, *{_name(s)}*'s too, connects "
                "**out** to it: this connection needs no port forwarding and no public IP of "
                "its own; any internet access works, carrier-grade NAT included.")
        cg = (f"Only the relay needs a public address, with TCP {s.relay.zenoh_port} and SSH "
              "open (the Router step says what it needs).")
    elif s.is_master:
        need = (f"*{_name(s)}* is the ROS 2 master: its Zenoh router is the hub every member "
                f"connects to, so this connection must accept **one** incoming TCP port "
                f"({port}) and needs a public IP. {kind}: is port forwarding allowed, and is the "
                "public IP really yours (not shared by carrier-grade NAT, 100.64.0.0/10)?")
        cg = ("**Carrier-grade NAT on the master** makes it unreachable. Make another "
              "component with a public address the master (under ROS 2 the master is only the "
              "hub), or, when every site is behind carrier NAT, use a relay: a small server "
              "with a public address (a VPS) every component's router connects to (set-up: "
              "Relay; README \"Robots on a mobile line\").")
    else:
        need = (f"*{_name(s)}* is a member: its router only connects **out** to the master's "
                f"(*{_master_word(s)}*), so this connection needs no port forwarding and no "
                "public IP of its own; any internet access works, carrier-grade NAT included.")
        cg = ("A changing public IP does not matter here either; only the master's address "
              "must be known (address sync keeps it right).")
    return "\n\n".join([need, cg, "**To verify:** this machine reaches the internet and learns "
                                  "its public IP."])


def configure_router_ros2(s: Settings) -> str:
    from rosnet_tui.core.ros import ros2  # not on the start-up path (ROS 1 never needs it)

    port = s.ros.zenoh_port
    if s.relayed:
        return (f"**Nothing to forward on {_name(s)}'s modem.** Every component's router, the "
                f"master's included, connects out to the relay *{s.relay.host}* "
                f"(`{ros2.relay_endpoint(s)}`, mutual TLS), so carrier-grade NAT on any site "
                "does not matter. Leave forwarding and DMZ off here.\n\n"
                f"**The relay needs** a public address its name resolves to, TCP "
                f"{s.relay.zenoh_port} open in its firewall (and its provider's), SSH, and "
                "`rosnet-tui relay serve` running there.\n\n"
                "**To verify:** the port test is skipped; relay.router (ROS step) proves the "
                "relay's port.")
    if not s.is_master:
        return (f"**Nothing to forward on {_name(s)}'s modem.** Under ROS 2 over rmw_zenoh only "
                f"the master's modem forwards a port (TCP {port}); a member's router connects "
                "out, as a browser does. Leave forwarding and DMZ off here.\n\n"
                "**To verify:** the port test is skipped on a member; the ROS step proves "
                "the link.")
    ip = _this_ip(s)
    return "\n\n".join([
        "Open the modem's web page (usually its gateway address in a browser), firewall or "
        "port-forwarding section. Then:\n\n"
        f"1. Forward **TCP {port}** (one port, no range, no UDP) to **{ip}**.\n"
        f"2. Reserve **{ip}** for this machine in the modem's DHCP settings.\n"
        f"3. The router (`rmw_zenohd`) must listen on an IPv4 address: "
        f"`{ros2.listen_endpoints(s)[0] if s.is_master else f'tcp/0.0.0.0:{port}'}` "
        "(the ROS step writes that config).",
        (f"**Only the fleet gets in.** The router takes a session on TCP {port} only with a "
         "certificate signed by the fleet's CA (mutual TLS, `[ros] security = \"mtls\"`, the "
         "default): the ROS step makes the CA here and pairs each member. If the modem can "
         "restrict the forward to your members' addresses, do that too."
         if ros2.mtls(s) else
         f"**Exposure.** `[ros] security = \"none\"`: whoever reaches TCP {port} joins this "
         "ROS 2 network (rmw_zenoh has no authentication of its own). Set it back to "
         "\"mtls\" (set-up: Security on), or at least allow only your members' addresses on "
         "the modem."),
        f"**To verify:** TCP {port} tested from outside reaches the router (or our stand-in "
        "listener while the router is not running)."])


def configure_ros2(s: Settings) -> str:
    from rosnet_tui.core.ros import ros2  # not on the start-up path (ROS 1 never needs it)

    master = _master_word(s)
    head = ["**ROS 2 over rmw_zenoh**: a Zenoh router on every component, one TCP port on the "
            "master. DDS (ROS 2's default) cannot cross the modems: its discovery is multicast "
            "and its data goes to private addresses."]
    if s.relayed:
        head.append(f"**Through the relay** *{s.relay.host}*: every router, the master's "
                    f"included, connects out to `{ros2.relay_endpoint(s)}` with this machine's "
                    "fleet certificate and listens on loopback only (its own nodes). The fleet "
                    "CA stays on the master, which also signs the relay's certificate.")
    elif s.is_master:
        eps = " and ".join(f"`{e}`" for e in ros2.listen_endpoints(s))
        head.append(f"*{_name(s)}* is the master: its router listens on {eps} (IPv4: "
                    "rmw_zenohd's default `tcp/[::]` fails on hosts without IPv6) and every "
                    "member's router connects to it.")
        if ros2.mtls(s):
            head.append("**Mutual TLS** (`[ros] security = \"mtls\"`): `rosnet-tui ros apply` "
                        "makes the fleet's CA here (its key never leaves this machine) and this "
                        "router's certificate; only routers with a certificate from that CA get "
                        "in. Its own nodes stay on plain TCP over loopback.")
    else:
        head.append(f"*{_name(s)}* is a member: its router connects to "
                    f"`{ros2.master_endpoint(s)}` (the hosts file maps *{master}* to the "
                    "master's public IP; address sync keeps it right) and its nodes stay on it.")
        if ros2.mtls(s):
            head.append("**Mutual TLS**: `rosnet-tui ros apply` makes this machine's key here and "
                        "has the master sign its certificate over SSH (`rosnet-tui ros pair`; "
                        "without SSH to the master, `ros pair --print-request` gives a text to "
                        "paste there).")
    block = "\n".join(["export RMW_IMPLEMENTATION=rmw_zenoh_cpp",
                       f"export ROS_DOMAIN_ID={s.ros.domain_id}",
                       "export ZENOH_ROUTER_CONFIG_URI=~/.config/rosnet-tui/zenoh-router.json5"])
    head.append(f"In `~/.bashrc` (`rosnet-tui ros apply` writes it and the router's config):"
                f"\n\n```\n{block}\n```\n\nThen run `ros2 run rmw_zenoh_cpp rmw_zenohd`, "
                "and start the nodes as usual.")
    if not s.is_master:
        head.append(f"**A lone node** (no router here): client mode, straight to the master "
                    f"(`ros apply --client`): `ZENOH_CONFIG_OVERRIDE='mode=\"client\";"
                    f"connect/endpoints=[\"{ros2.master_endpoint(s)}\"]'` (with this machine's "
                    f"certificate under mutual TLS: `ros apply --client` writes it). Never peer mode: the "
                    "router passes no data between two peers (graph seen, no data).")
    head.append("**Same distro everywhere.** Humble next to Jazzy or later discovers but drops "
                "every message. On Humble, ZENOH_CONFIG_OVERRIDE needs rmw_zenoh 0.1.2: use a "
                "config file (ZENOH_SESSION_CONFIG_URI) before that.")
    head.append("**To verify:** the master's router answers by name, the graph shows every "
                "component's nodes, and a message goes through both ways.")
    return "\n\n".join(head)


ROS2_EXPECTED = ("Every component's Zenoh router links to the master's router through its one "
                 "forwarded port; every component's nodes are seen, and each can publish and "
                 "subscribe.")


# Every check of each step, in the order the step lists them, with the ROS version it belongs to
# (None: both) and the settings table that must be enabled for it (None: none). The checks
# register the same facts (CheckSpec.ros and .switch; tests/test_steps.py holds both to one
# answer), so a step lists exactly the checks the runner runs, before they are even imported.
STEP_CHECKS: dict[str, tuple[tuple[str, int | None, str | None], ...]] = {
    "isp": (("isp.internet", None, None), ("isp.public_ip", None, None),
            ("isp.cgnat", None, None)),
    "router": (("router.local_ip", None, None), ("router.port_free", None, None),
               ("router.listener", None, None), ("router.port_open", None, None),
               ("router.upnp", 2, None)),   # the modem's own word on ROS 2's one port
    "linux": (("linux.hosts", None, None), ("linux.resolve", None, None),
              ("linux.ping", None, None), ("linux.ssh", None, None),
              ("linux.chat_out", None, None), ("linux.chat_in", None, None),
              ("linux.firewall", 1, None), ("security.ssh_auth", None, None),
              ("relay.tunnel", 2, "relay")),
    "ros": (("ros.env", 1, None), ("ros.master", 1, None), ("ros.node_uris", 1, None),
            ("ros.pubsub_out", 1, None), ("ros.pubsub_in", 1, None), ("ros.link", 1, None),
            ("ros2.env", 2, None), ("ros2.router", 2, None), ("relay.router", 2, "relay"),
            ("ros2.graph", 2, None),
            ("ros2.pubsub_out", 2, None), ("ros2.pubsub_in", 2, None), ("ros2.link", 2, None),
            ("security.outsider", None, None), ("ros.rosbridge", None, "rosbridge")),
}


def check_applies(ros: int | None, switch: str | None, settings: Settings) -> bool:
    """Whether a check of ROS version *ros* (None: every version), switched on by the settings
    table *switch* (None: always on), runs under *settings*."""
    if switch is not None and getattr(getattr(settings, switch, None), "enabled", False) \
            is not True:
        return False
    return ros is None or ros == settings.ros.version


def step_check_ids(step_id: str, settings: Settings) -> tuple[str, ...]:
    """The checks of *step_id* that run under *settings*, in the step's order."""
    return tuple(cid for cid, ros, switch in STEP_CHECKS[step_id]
                 if check_applies(ros, switch, settings))


def _ros1_ids(step_id: str) -> tuple[str, ...]:
    """The step's checks under ROS 1 with every switch off (the steps as declared below)."""
    return tuple(cid for cid, ros, switch in STEP_CHECKS[step_id]
                 if ros in (None, 1) and switch is None)


STEPS: tuple[Step, ...] = (
    Step("isp",
         "Your provider allows port forwarding on every port of this connection, and the modem "
         "has a public IP address that the other components can reach.",
         configure_isp, _ros1_ids("isp")),
    Step("router",
         "A port tested from outside the modem is reported Open: the modem forwards it to "
         "this component.",
         configure_router, _ros1_ids("router")),
    Step("linux",
         "The components ping each other by name, open SSH sessions by name, and exchange "
         "messages over TCP by name, whichever side starts.",
         configure_linux, _ros1_ids("linux")),
    Step("ros",
         "Every component registers with the one ROS master, and each can both publish and "
         "subscribe.",
         configure_ros, _ros1_ids("ros")),
)

STEP_BY_ID = {s.id: s for s in STEPS}
assert tuple(STEP_BY_ID) == STEP_IDS, "the steps are listed in the procedure's order"


def step_for(step_id: str, settings: Settings) -> Step:
    """The step as *settings* have it: its expected outcome for the ROS version, and the checks
    that run under them (ROS 2's ros2.*, ros.rosbridge when [rosbridge] is enabled...)."""
    return replace(_step_for_version(step_id, settings),
                   check_ids=step_check_ids(step_id, settings))


def _step_for_version(step_id: str, settings: Settings) -> Step:
    step = STEP_BY_ID[step_id]
    if not settings.ros2:
        return step
    master = settings.is_master and not settings.relayed   # the one that takes connections
    port = settings.ros.zenoh_port
    if step_id == "router" and settings.relayed:
        return replace(step, expected=(
            f"Nothing to forward: every router connects out to the relay {settings.relay.host}, "
            f"whose TCP {settings.relay.zenoh_port} is open to the internet."))
    if step_id == "isp":
        return replace(step, expected=(
            f"The provider allows one incoming TCP port ({port}) and the modem has a public IP "
            "the members can reach." if master else
            "This machine reaches the internet; nothing needs to reach it (any connection "
            "works, carrier-grade NAT included)."))
    if step_id == "router":
        return replace(step, expected=(
            f"Nothing to forward on the {settings.this.profile} LAN: every router reaches the "
            "master's directly." if settings.this.profile != "remote" else
            f"TCP {port}, tested from outside the modem, reaches this component's Zenoh router."
            if master else "Nothing to forward: this member's router connects out to the "
                           "master's."))
    if step_id == "linux":
        return replace(step, expected=(
            "The components ping each other by name and open SSH sessions by name; every member "
            f"reaches the master's router port ({port}) by name."))
    return replace(step, expected=ROS2_EXPECTED)
