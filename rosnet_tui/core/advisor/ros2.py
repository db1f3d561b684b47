"""Step 4 for ROS 2 over rmw_zenoh: the rules that read the ros2.* checks, the ROS 2 reading of
the master's port test (router.port_open on zenoh_port) and carrier NAT under ROS 2.

Under ROS 2 one TCP port on the master's modem carries everything, so the questions change: is
the master's router running and listening where the forward points, does the forward exist, do
the members' routers link to it, are the nodes where rmw_zenoh expects them (a router per
component, or client mode), and do all components run the same distro.
"""

from __future__ import annotations

from rosnet_tui.core.advisor.engine import Hit, rule
from rosnet_tui.core.advisor.evidence import Evidence, join_and
from rosnet_tui.core.advisor.ranking import peer_tcp
from rosnet_tui.core.ros.ros2 import RMW_ZENOH


def _on(ev: Evidence) -> bool:
    return ev.s.ros2


def _master(ev: Evidence) -> str:
    return ev.s.master_name or "the master"


def _port(ev: Evidence) -> int:
    return ev.s.ros.zenoh_port


def _hops(ev: Evidence, *hops: str) -> list[str]:
    """The pub/sub checks that failed at one of *hops*."""
    out, inn = ev.data("ros2.pubsub_out"), ev.data("ros2.pubsub_in")
    ids = []
    if out.get("ok") is False and out.get("failed_hop") in hops:
        ids.append("ros2.pubsub_out")
    if inn.get("ok") is False and inn.get("failed_hop") in hops:
        ids.append("ros2.pubsub_in")
    return ids


def site_closed(ev: Evidence) -> str:
    """A member found the master's Zenoh port refused and the master's SSH port refused or
    unanswered: what SSH did, in words ("" when that is not the case). A refusal alone cannot
    tell "nothing listens" from "the modem refuses"; both ports together point at the site."""
    if not _on(ev) or ev.s.is_master or ev.data("ros2.router").get("failure") != "refused":
        return ""
    master = _master(ev)
    ssh = (ev.data("linux.ssh").get("peers") or {}).get(master) or {}
    if ssh.get("ok") is True:
        return ""
    kind = peer_tcp(ev, master)
    if kind == "refused":
        return "refused too"
    if kind in ("timeout", "unreachable") or (kind is None and ssh.get("failure") in ("network",
                                                                                     "timeout")):
        return "did not answer either"
    return ""


def _start_router(ev: Evidence, where: str) -> list[str]:
    return [f"On {where}: `source ~/.bashrc` (ZENOH_ROUTER_CONFIG_URI names the config "
            "`rosnet-tui ros apply` wrote), then `ros2 run rmw_zenoh_cpp rmw_zenohd`; keep it "
            "running (a systemd user service or the robot's launch file).",
            "Then re-run the ROS step."]


@rule("ros2.env.dds", "ros", ("ros2.env",),
      "ROS 2 on DDS (no RMW_IMPLEMENTATION, or a DDS one)",
      "DDS discovers by UDP multicast, which no modem forwards, and each participant advertises "
      "its private addresses and its own UDP ports: across two modems nodes are not found, or "
      "are found and get no data.",
      "Use rmw_zenoh: install ros-<distro>-rmw-zenoh-cpp, `export RMW_IMPLEMENTATION="
      "rmw_zenoh_cpp` (`rosnet-tui ros apply`), run rmw_zenohd on every component.",
      "ros", "fail")
def _dds(ev: Evidence) -> list[Hit]:
    d = ev.data("ros2.env")
    if not _on(ev) or d.get("dds") is not True:
        return []
    got = d.get("rmw") or d.get("bashrc_rmw")
    now = f"RMW_IMPLEMENTATION={got}" if got else "no RMW_IMPLEMENTATION (ROS 2's default, DDS)"
    return [Hit(f"{ev.me} runs ROS 2 with {now}. DDS finds nodes by UDP multicast and then sends "
                "data to the private addresses and random UDP ports each node announces; no modem "
                "forwards multicast, and forwarding those ports by hand needs matching XML on "
                "every host. Across the internet that means nodes not found, or listed with no "
                "data.",
                [f"On {ev.me}: `sudo apt install ros-$ROS_DISTRO-rmw-zenoh-cpp`.",
                 "`rosnet-tui ros apply` writes RMW_IMPLEMENTATION=rmw_zenoh_cpp, ROS_DOMAIN_ID "
                 "and the router's config into ~/.bashrc; open a new shell.",
                 "Start the router (`ros2 run rmw_zenoh_cpp rmw_zenohd`) and restart the nodes; "
                 f"only TCP {_port(ev)} on {_master(ev)}'s modem needs forwarding."],
                evidence=[f"ros2.env: {now}"])]


@rule("ros2.env.domain", "ros", ("ros2.env", "ros2.graph", "ros2.pubsub_out", "ros2.pubsub_in"),
      "ROS_DOMAIN_ID differs from the settings or between components",
      "Nodes in different ROS 2 domains use different keys: they never see each other.",
      "Set the same ROS_DOMAIN_ID everywhere (domain_id under [ros]; `rosnet-tui ros apply`).",
      "ros", "fail")
def _domain(ev: Evidence) -> list[Hit]:
    if not _on(ev):
        return []
    d = ev.data("ros2.env")
    want = ev.s.ros.domain_id
    peers = [c for c in ("ros2.pubsub_out", "ros2.pubsub_in")
             if "ROS_DOMAIN_ID" in str(ev.data(c).get("detail") or "")]
    if d.get("domain_ok") is not False and not peers:
        return []
    where = ev.me if d.get("domain_ok") is False else "the peer"
    facts = ([f"ros2.env: ROS_DOMAIN_ID={d.get('domain_id')}, settings {want}"]
             if d.get("domain_ok") is False else [])
    facts += [f"{c}: {ev.data(c).get('detail')}" for c in peers]
    return [Hit(f"ROS_DOMAIN_ID on {where} is not {want}, the domain in the settings: nodes in "
                "different domains never see each other, whatever the network does.",
                [f"On every component: `export ROS_DOMAIN_ID={want}` in ~/.bashrc "
                 "(`rosnet-tui ros apply` writes it), then restart the nodes and the router.",
                 "Or change domain_id under [ros] on every component, if another domain is meant."],
                check_ids=["ros2.env", *peers, *(["ros2.graph"] if ev.is_fail("ros2.graph") else [])],
                evidence=facts)]


@rule("ros2.router.not_running", "ros", ("ros2.router", "ros2.graph", "ros2.pubsub_out",
                                         "ros2.pubsub_in"),
      "a Zenoh router is not running (the master's, or this component's own)",
      "rmw_zenoh needs a router: the master's is the hub every member links to, and each "
      "component's nodes sit on their own router. Without it nothing is discovered or delivered.",
      "Start `ros2 run rmw_zenoh_cpp rmw_zenohd` with ZENOH_ROUTER_CONFIG_URI set (`rosnet-tui "
      "ros apply` writes it).",
      "ros", "fail", superseded_by=("relay.router.down",))
def _not_running(ev: Evidence) -> list[Hit]:
    if not _on(ev):
        return []
    r = ev.data("ros2.router")
    local = r.get("local_router") or {}
    ids = ["ros2.router", *_hops(ev, "our_router", "master_router", "peer_router")]
    if ev.is_fail("ros2.graph"):
        ids.append("ros2.graph")
    if r.get("listen_problem") == "not_running":
        return [Hit(f"Nothing listens on TCP {_port(ev)} on {ev.me} (this machine, the master): "
                    "its Zenoh router is not running.", _start_router(ev, ev.me), check_ids=ids,
                    evidence=["ros2.router: not_running"])]
    if r.get("failure") == "refused" and not site_closed(ev):
        where = _master(ev)
        ssh = (ev.data("linux.ssh").get("peers") or {}).get(where) or {}
        seen = (f"{where} answers SSH at the same address, so its modem lets connections in"
                if ssh.get("ok") is True or peer_tcp(ev, where) == "connected" else
                f"a refusal alone cannot tell that from {where}'s modem refusing the port: "
                f"the port test of {where}'s own Router step tells them apart")
        return [Hit(f"A connection to {r.get('endpoint')} ({r.get('address')}) was refused: most "
                    f"likely no Zenoh router listens on {where} ({seen}).",
                    _start_router(ev, where), check_ids=ids,
                    evidence=[f"ros2.router: {r.get('failure')}"])]
    if local and local.get("reachable") is False:
        seen = "the master's router answers, but " if r.get("reachable") else ""
        return [Hit(f"{ev.me}'s own router is not running: {seen}nodes here look for their "
                    f"router at {local.get('endpoint')} and find nothing.",
                    _start_router(ev, ev.me) + [
                        f"Or, for a lone node without a router: client mode straight to "
                        f"{_master(ev)} (`rosnet-tui ros apply --client`)."],
                    check_ids=ids, evidence=[f"ros2.router: local router {local.get('failure')}"])]
    return []


@rule("ros2.router.loopback", "ros", ("ros2.router", "ros2.env"),
      "the master's router listens on loopback only",
      "A router listening on 127.0.0.1 accepts connections from its own machine only: the "
      "modem's forward of the Zenoh port reaches nothing.",
      "Listen on tcp/0.0.0.0:<zenoh_port> (`rosnet-tui ros apply` writes that config).",
      "ros", "fail")
def _loopback(ev: Evidence) -> list[Hit]:
    r, e = ev.data("ros2.router"), ev.data("ros2.env")
    conf = [p for p in e.get("config_problems") or [] if "loopback" in p]
    if not _on(ev) or not (r.get("listen_problem") == "loopback" or conf):
        return []
    return [Hit(f"The router on {ev.me} listens on loopback only, so the modem's forward of TCP "
                f"{_port(ev)} reaches nothing.",
                [f"In the router's config (ZENOH_ROUTER_CONFIG_URI): listen on "
                 f"`tcp/0.0.0.0:{_port(ev)}` (`rosnet-tui ros apply` writes it), then restart "
                 "rmw_zenohd."],
                check_ids=[c for c in ("ros2.router", "ros2.env") if ev.status(c)],
                evidence=[f"ros2.router: listening on {r.get('listening')}", *conf])]


@rule("ros2.router.ipv6_only", "ros", ("ros2.router", "ros2.env"),
      "the router listens on [::] on a host without IPv6",
      "rmw_zenohd's default endpoint tcp/[::]:7447 needs IPv6; on a host without it the router "
      "does not start (\"Address family not supported\").",
      "Listen on tcp/0.0.0.0:<zenoh_port> instead (`rosnet-tui ros apply` writes that config).",
      "ros", "fail")
def _ipv6(ev: Evidence) -> list[Hit]:
    r, e = ev.data("ros2.router"), ev.data("ros2.env")
    conf = [p for p in e.get("config_problems") or [] if "no IPv6" in p]
    if not _on(ev) or not (r.get("listen_problem") == "ipv6_only" or conf):
        return []
    return [Hit(f"The router's config on {ev.me} listens on tcp/[::]:{_port(ev)}, but this host "
                "has no IPv6: rmw_zenohd stops at start-up (\"Address family not supported\").",
                [f"Listen on `tcp/0.0.0.0:{_port(ev)}` (IPv4): `rosnet-tui ros apply` writes "
                 "that config and points ZENOH_ROUTER_CONFIG_URI at it; restart rmw_zenohd."],
                check_ids=[c for c in ("ros2.router", "ros2.env") if ev.status(c)],
                evidence=["ros2.router: ipv6=False", *conf])]


def _cgnat_master(ev: Evidence) -> bool:
    return ev.s.is_master and bool(ev.data("isp.cgnat").get("cgnat"))


@rule("ros2.port.not_forwarded", "router", ("router.port_open", "ros2.router", "ros2.graph",
                                            "ros2.pubsub_out", "ros2.pubsub_in"),
      "the master's Zenoh port is closed from outside (Table 1 under ROS 2)",
      "A connection from the internet does not reach the master's router: most likely its modem "
      "does not forward TCP zenoh_port to the master's local IP, or the provider stops it "
      "(carrier-grade NAT). From a member: the port gets no answer, or it is refused while the "
      "master's SSH is shut out too (the whole site takes no connection).",
      "Forward TCP <zenoh_port> (only that port) to the master's local IP, reserve that IP by "
      "DHCP; on the master, its ISP step tells carrier-grade NAT.",
      "router", "fail", superseded_by=("relay.router.down",))
def _not_forwarded(ev: Evidence) -> list[Hit]:
    if not _on(ev) or ev.s.relayed or _cgnat_master(ev):
        return []
    p, r = ev.data("router.port_open"), ev.data("ros2.router")
    port = _port(ev)
    if p.get("zenoh_port_open") is False:
        who = {"router": "the router listens", "ours": "our listener stood in for the router",
               "none": "nothing could listen"}.get(str(p.get("zenoh_listener")), "")
        seen = f"TCP {port} is closed from outside while {who} on {ev.me}"
        local = ev.my_local_ip()
    elif r.get("failure") == "timeout" and not ev.s.is_master:
        seen = (f"connections from {ev.me} to {r.get('endpoint')} ({r.get('address')}) get no "
                "answer at all (dropped, not refused)")
        local = ev.peer_local(_master(ev)) or f"{_master(ev)}'s local IP"
    elif said := site_closed(ev):
        return [_site_hit(ev, said)]
    else:
        return []
    ids = [c for c in ("router.port_open", "ros2.router") if ev.is_fail(c)]
    ids += _hops(ev, "master_router", "peer_router")
    return [Hit(f"{seen}: most likely {_master(ev)}'s modem does not forward TCP {port} to its "
                "router.",
                [f"In {_master(ev)}'s modem (firewall / NAT / port forwarding): forward TCP {port} "
                 f"to {local}; nothing else is needed for ROS 2 (no range, no UDP).",
                 f"Reserve {local} for {_master(ev)} by DHCP so the forward keeps pointing at it.",
                 "If the forward is there and still closed: the provider may block incoming "
                 "connections (carrier-grade NAT: see the ISP step).",
                 f"If {_master(ev)}'s modem speaks UPnP IGD, PCP or NAT-PMP, `rosnet-tui router "
                 f"map` on {_master(ev)} asks it for this forward (it shows the request and "
                 "waits for a yes)."],
                check_ids=ids or ["ros2.router"], evidence=[f"router.port_open/ros2.router: {seen}"])]


def _site_hit(ev: Evidence, ssh_said: str) -> Hit:
    """The master's whole site takes no connection from here: its modem or its provider."""
    master, port, r = _master(ev), _port(ev), ev.data("ros2.router")
    addr = r.get("address") or ev.expected_ip(master) or "its address"
    local = ev.peer_local(master) or f"{master}'s local IP"
    ssh = (ev.data("linux.ssh").get("peers") or {}).get(master) or {}
    ssh_port = ssh.get("port") or 22
    seen = (f"{master}'s Zenoh port ({addr}:{port}) refused {ev.me}'s connection and its SSH "
            f"port {ssh_port} {ssh_said}")
    ids = ["ros2.router", *_hops(ev, "master_router", "peer_router")]
    if ev.is_fail("ros2.graph"):
        ids.append("ros2.graph")
    return Hit(f"{seen}: nothing at {addr} takes a connection from here. That points at "
               f"{master}'s modem or its provider rather than at its router: the modem forwards "
               f"neither port (or its firewall rejects them), or {master} sits behind "
               "carrier-grade NAT and the carrier answers in its place. A refused Zenoh port "
               "alone could also mean that no router listens there; with SSH shut out too, the "
               "site is the first suspect.",
               [f"On {master}: run its ISP and Router steps (`rosnet-tui check --step isp "
                "--step router` there): isp.cgnat tells carrier-grade NAT, the port test "
                f"whether TCP {port} gets in from outside.",
                f"In {master}'s modem: forward TCP {port} (the router) and TCP {ssh_port} (SSH, "
                f"for the checks) to {local}, and let them through its firewall.",
                f"If {master} is behind carrier-grade NAT, no forward can work there: make a "
                "component with a public address the master, or run the hub router on a small "
                "public server (see ros2.cgnat).",
                f"Only then, if TCP {port} is open from outside: is rmw_zenohd running on "
                f"{master}? (`ss -tlnp | grep {port}` there)"],
               check_ids=ids, goto_step="router",
               evidence=[f"ros2.router: {r.get('endpoint')} ({addr}) refused",
                         f"linux.ssh: {master} port {ssh_port} {ssh_said} "
                         f"(tcp={peer_tcp(ev, master)}, ssh={ssh.get('failure')})"])


@rule("ros2.cgnat", "isp", ("isp.cgnat", "ros2.router"),
      "carrier-grade NAT under ROS 2 (harmless on a member, fatal on the master)",
      "A member's router only connects out, so carrier NAT there does not matter; the master's "
      "router must be reached from outside, which carrier NAT prevents. When every site is behind "
      "carrier NAT, a router with a public address is needed.",
      "Make a component with a public address the master, or run a Zenoh router on a small "
      "public server (VPS) and point every component's router at it.",
      "isp", "fail")
def _cgnat(ev: Evidence) -> list[Hit]:
    d = ev.data("isp.cgnat")
    if not _on(ev) or not d.get("cgnat"):
        return []
    if ev.s.relayed:
        return [Hit(f"{ev.me} is behind carrier-grade NAT, which the relay {ev.s.relay.host} "
                    "carries: every router dials out to it, so nothing needs to reach "
                    f"{ev.me}.", ["Nothing to do here."], severity="info", goto_step=None,
                    evidence=["isp.cgnat: cgnat=True (under a relay)"])]
    if not ev.s.is_master:
        return [Hit(f"{ev.me} is behind carrier-grade NAT, which does not matter under ROS 2: its "
                    f"router connects out to {_master(ev)}'s, and nothing needs to reach {ev.me}.",
                    ["Nothing to do here."], severity="info", goto_step=None,
                    evidence=["isp.cgnat: cgnat=True (a member)"])]
    return [Hit(f"{ev.me}, the master, is behind carrier-grade NAT: no forward on its modem can "
                f"be reached from the internet, so the members' routers cannot link to its router "
                f"on TCP {_port(ev)}.",
                ["Use a relay you own: a small server with a public address (a VPS) with SSH "
                 f"and TCP {_port(ev)} open. Give every component the same [relay] (set-up: "
                 "Relay), then: on the master `rosnet-tui ros apply --yes` and `rosnet-tui "
                 "relay apply --yes`; on the relay `rosnet-tui relay serve`; on each component "
                 "`rosnet-tui relay tunnel`; on each member `rosnet-tui ros apply --yes` "
                 "(README: Robots on a mobile line).",
                 "Or, under ROS 2 the 'master' is only the hub: make another component the "
                 "master if its own ISP step passes there (no carrier NAT) and its modem can "
                 "forward (role and ros.master in the settings of every component).",
                 "Or ask the carrier for a public IP on this line (its networking department)."],
                check_ids=["isp.cgnat", *[c for c in ("ros2.router",) if ev.is_fail(c)]],
                evidence=[f"isp.cgnat: cgnat=True, hop {d.get('hop')}, wan {d.get('wan_ip')}"])]


@rule("ros2.peer_mode", "ros", ("ros2.router", "ros2.env", "ros2.pubsub_out", "ros2.pubsub_in"),
      "a remote node in peer mode (graph seen, no data)",
      "A node without a router of its own, connected to the master's router as a peer: the "
      "router does not pass data between two peers, so the node is listed but gets no data.",
      "Run a router on that machine (nodes on it as peers), or put the lone node in client mode.",
      "ros", "fail", after=("ros2.env.distro",))
def _peer_mode(ev: Evidence) -> list[Hit]:
    if not _on(ev):
        return []
    r, e = ev.data("ros2.router"), ev.data("ros2.env")
    remote = list(r.get("remote_peers") or [])
    conf = [p for p in e.get("config_problems") or [] if "peers connected straight" in p]
    dropped = [] if ev.fired_any("ros2.env.distro") else _hops(ev, "data_dropped")
    if not (remote or conf or dropped):
        return []
    facts = ([f"ros2.router: peer sessions {join_and(remote)}"] if remote else []) + conf + \
        [f"{c}: graph seen, data dropped" for c in dropped]
    return [Hit("A node runs in peer mode attached straight to the master's router from another "
                "machine: the router does not pass data between two peers, so it appears in the "
                "graph (ros2 node list) but receives and delivers nothing"
                + (f" ({join_and(remote)})." if remote else "."),
                ["Best: run a router on that machine too (`rosnet-tui ros apply` there, then "
                 "`ros2 run rmw_zenoh_cpp rmw_zenohd`) and leave its nodes on it.",
                 "Or, for a lone node: client mode, `export ZENOH_CONFIG_OVERRIDE='mode=\"client\";"
                 f"connect/endpoints=[\"tcp/{_master(ev)}:{_port(ev)}\"]'` "
                 "(`rosnet-tui ros apply --client`)."],
                check_ids=[c for c in ("ros2.router", "ros2.env") if ev.status(c) and (
                    ev.is_fail(c) or c == "ros2.router" and remote)] + dropped,
                evidence=facts)]


@rule("ros2.env.distro", "ros", ("ros2.env", "ros2.graph", "ros2.pubsub_out", "ros2.pubsub_in"),
      "different ROS 2 distros (or rmw_zenoh versions) on the components",
      "Humble writes no type hash, Jazzy and later do: they discover each other but never match "
      "each other's data; mixed rmw_zenoh versions with different attachments crash.",
      "Run the same distro and the same rmw_zenoh version on every component.",
      "ros", "fail")
def _distro(ev: Evidence) -> list[Hit]:
    if not _on(ev):
        return []
    e, g = ev.data("ros2.env"), ev.data("ros2.graph")
    mism = list(e.get("distro_mismatch") or [])
    if not mism and g.get("mixed_hashes") is not True:
        return []
    peers = e.get("peer_distros") or {}
    facts = [f"ros2.env: here {e.get('distro')}, " + ", ".join(f"{n} {peers.get(n)}" for n in mism)]
    if g.get("mixed_hashes"):
        facts.append("ros2.graph: Humble (TypeHashNotSupported) next to RIHS01 type hashes")
    return [Hit(f"The components do not run the same ROS 2 distro ({ev.me}: {e.get('distro')}"
                + "".join(f", {n}: {peers.get(n)}" for n in mism) + "). Humble's rmw_zenoh puts "
                "no type hash in its keys and later distros do, so the nodes see each other and "
                "no message ever matches; different rmw_zenoh releases (Jazzy 0.2.3 vs 0.2.4+) "
                "even crash on each other's attachments.",
                ["Install the same distro on every component (Jazzy or later where possible), "
                 "and the same rmw_zenoh release (`apt policy ros-$ROS_DISTRO-rmw-zenoh-cpp`).",
                 "Then restart the routers and the nodes."],
                check_ids=[c for c in ("ros2.env", "ros2.graph") if ev.is_fail(c)]
                + _hops(ev, "data_dropped"), evidence=facts)]


@rule("ros2.env.rmw_one_place", "ros", ("ros2.env",),
      "RMW_IMPLEMENTATION=rmw_zenoh_cpp in this shell or in ~/.bashrc, not in both",
      "Shells that lack it run ROS 2 on DDS: nodes started there find no one across the modems, "
      "or are listed with no data.",
      "`rosnet-tui ros apply` writes the export into ~/.bashrc; `source ~/.bashrc` loads it "
      "into this shell.",
      "ros", "warn")
def _rmw_one_place(ev: Evidence) -> list[Hit]:
    d = ev.data("ros2.env")
    if not _on(ev) or d.get("dds") is not False or d.get("rmw_ok") is not False:
        return []
    here, there = d.get("rmw"), d.get("bashrc_rmw")
    if there != RMW_ZENOH:
        why = (f"this shell has RMW_IMPLEMENTATION={here}, ~/.bashrc "
               f"{'says ' + there if there else 'does not export it'}: every new shell (and "
               "what starts from one) runs ROS 2 on DDS")
    else:
        why = (f"~/.bashrc exports RMW_IMPLEMENTATION={there}, this shell "
               f"{'has ' + here if here else 'does not have it'} (it was opened before, or does "
               "not read ~/.bashrc): nodes started from it run ROS 2 on DDS")
    return [Hit(f"On {ev.me}, {why}, and DDS does not cross the modems.",
                [f"On {ev.me}: `rosnet-tui ros apply` writes RMW_IMPLEMENTATION=rmw_zenoh_cpp "
                 "into ~/.bashrc (a preview first).",
                 "Then `source ~/.bashrc` (or open a new shell) and restart the nodes started "
                 "from the old one."],
                evidence=[f"ros2.env: environment {here or 'not set'}, ~/.bashrc "
                          f"{there or 'not set'}"])]


@rule("ros2.env.no_distro", "ros", ("ros2.env",),
      "ROS_DISTRO is not set (no ROS 2 sourced)",
      "The shell that ran the checks has no ROS 2 set up: ros2, rmw_zenohd and the nodes are "
      "not found there, and the distro cannot be compared with the peers'.",
      "Install ROS 2 if needed and add `source /opt/ros/<distro>/setup.bash` to ~/.bashrc.",
      "ros", "warn")
def _no_distro(ev: Evidence) -> list[Hit]:
    d = ev.data("ros2.env")
    if not _on(ev) or "distro" not in d or d.get("distro"):
        return []
    return [Hit(f"ROS_DISTRO is not set on {ev.me}: no ROS 2 is sourced in the shell that ran "
                "the checks, so ros2, rmw_zenohd and the nodes are not found there, and nobody "
                "can tell whether its distro matches the peers'.",
                [f"On {ev.me}: install ROS 2 if it is missing (`ls /opt/ros`), then add "
                 "`source /opt/ros/<distro>/setup.bash` to ~/.bashrc, before the lines of "
                 "rosnet-tui.",
                 "Open a new shell and run the checks again."],
                evidence=["ros2.env: ROS_DISTRO not set"])]


LEFTOVERS = {
    "localhost_only": "ROS_LOCALHOST_ONLY keeps the nodes on this machine",
    "discovery_localhost": "ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST limits discovery to this "
                           "machine",
    "dds_settings": "DDS settings (CYCLONEDDS_URI, FASTRTPS_DEFAULT_PROFILES_FILE...) do nothing "
                    "under rmw_zenoh and mislead whoever reads them",
}


@rule("ros2.env.leftovers", "ros", ("ros2.env",),
      "localhost-only or DDS settings left in the environment",
      "ROS_LOCALHOST_ONLY or ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST keep nodes from other "
      "machines; DDS variables do nothing under rmw_zenoh.",
      "Remove them from ~/.bashrc (and the shell), then restart the nodes.",
      "ros", "warn")
def _leftovers(ev: Evidence) -> list[Hit]:
    codes = [c for c in ev.data("ros2.env").get("warnings") or [] if c in LEFTOVERS]
    if not _on(ev) or not codes:
        return []
    return [Hit(f"On {ev.me}: " + "; ".join(LEFTOVERS[c] for c in codes) + ".",
                [f"On {ev.me}: delete those exports from ~/.bashrc (and `unset` them in this "
                 "shell), then restart the router and the nodes.",
                 "The evidence of ros2.env names the values found."],
                evidence=[f"ros2.env: {', '.join(codes)}"])]


@rule("ros2.link.missing", "ros", ("ros2.router", "ros2.graph", "ros2.pubsub_out",
                                   "ros2.pubsub_in"),
      "a member's router is not linked to the master's",
      "Nodes on that member are not seen elsewhere and no data crosses: its router does not "
      "connect to the master's (wrong or missing connect endpoint, or it cannot reach it).",
      "In the member router's config: connect to tcp/<master name>:<zenoh_port> (`rosnet-tui "
      "ros apply`), restart it.",
      "ros", "fail", after=("ros2.router.not_running", "ros2.port.not_forwarded", "ros2.cgnat"))
def _link(ev: Evidence) -> list[Hit]:
    if not _on(ev) or ev.fired_any("ros2.router.not_running", "ros2.port.not_forwarded",
                                   "ros2.cgnat"):
        return []
    hops = _hops(ev, "master_router", "peer_router")
    r = ev.data("ros2.router")
    unlinked = r.get("failure") is None and r.get("reachable") and \
        (r.get("local_router") or {}).get("reachable") and ev.is_fail("ros2.router")
    if not hops and not unlinked:
        return []
    who = ev.me if (unlinked or ev.data(hops[0]).get("failed_hop") == "master_router") \
        else (ev.data(hops[0]).get("peer") or "the member")
    return [Hit(f"{who}'s router has no link to the master's router {_master(ev)}: its nodes are "
                "invisible elsewhere and no message crosses.",
                [f"On {who}: the router's config must connect to `tcp/{_master(ev)}:{_port(ev)}` "
                 "(`rosnet-tui ros apply` writes it; ZENOH_ROUTER_CONFIG_URI must name it), "
                 "then restart rmw_zenohd there.",
                 f"On {who}: `getent hosts {_master(ev)}` must print the master's public IP "
                 "(the Linux step)."],
                check_ids=[c for c in ("ros2.router", "ros2.graph") if ev.is_fail(c)] + hops,
                evidence=[f"{c}: {ev.data(c).get('detail')}" for c in hops])]


@rule("security.zenoh_exposed", "router", ("router.port_open",),
      "the master's Zenoh port is reachable from the internet",
      "Anyone who reaches the master's router joins the ROS 2 graph: rmw_zenoh has no "
      "authentication by default.",
      "Restrict the forward to the members' addresses; consider Zenoh's user/password or TLS.",
      "router", "security")
def _exposed(ev: Evidence) -> list[Hit]:
    p = ev.data("router.port_open")
    if not _on(ev) or p.get("zenoh_port_open") is not True:
        return []
    if ev.data("ros2.router").get("security") == "mtls":   # only fleet certificates get in
        return []
    peers = [f"{x.name} {x.public_ip}" for x in ev.s.peers if x.public_ip]
    return [Hit(f"TCP {_port(ev)} of {ev.me} is open to the whole internet: whoever reaches it "
                "can list, publish to and subscribe from every node of this ROS 2 network "
                "(rmw_zenoh has no authentication unless you configure it).",
                ["Where the modem allows it, restrict the forward to the members' public "
                 f"addresses{' (' + join_and(peers) + ')' if peers else ''}.",
                 "For more: Zenoh's user/password authentication or TLS (mutual TLS) in the "
                 "routers' configs; forward the port only while the robot is in use."],
                evidence=[f"router.port_open: TCP {_port(ev)} open from outside"])]
