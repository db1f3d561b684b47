"""Competing causes, ranked by what the checks observed.

When a symptom has several possible causes (Table 1's closed port, a peer that cannot be
reached, a master that does not answer), the advisor lists every cause and puts first the one the
evidence supports most; ``g`` goes to the step of that first cause. The evidence, strongest
first:

1. how the connection was answered: **refused** (something at the address answered and rejected
   it: that machine is online, and the port is not forwarded or nothing listens on it),
   **unreachable** (an ICMP error: a router found no machine where it forwards to), **silent**
   (dropped), or **answered** by our listener's token or by another program;
2. whether the public IP answers ping;
3. the path probe's hops and UPnP's WAN address (carrier-grade NAT, a second router of your own,
   or a modem that holds the public address itself);
4. the local IP's history (a new DHCP lease leaves the forwarding on the old address);
5. the network profile (on a LAN nothing is forwarded);
6. the connection type, only to break a tie.

Each :class:`Cause` carries its score and the observations that moved it, in words; the findings
quote them. :data:`EVIDENCE` is the same list for docs/TROUBLESHOOTING.md.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from rosnet_tui.core.addresses import is_private, is_shared
from rosnet_tui.core.advisor.evidence import Evidence, does_not_resolve
from rosnet_tui.core.results import Status
from rosnet_tui.core.words import age

# (observation, what it makes more or less likely): the docs' table, strongest first.
EVIDENCE: tuple[tuple[str, str], ...] = (
    ("a process holds the test port (`router.port_free`)", "Table 1 (a) first"),
    ("carrier-grade NAT: a 100.64.0.0/10 address on the way out or as the modem's WAN address "
     "(`isp.cgnat`)", "the provider (ISP step) first"),
    ("the port test was **refused** at the public address (`router.port_open`, `linux.ssh`, "
     "`ros.master`)", "the modem is online and rejects the port: its forwarding (or, for a "
     "peer's SSH port, sshd listening elsewhere) first; the provider last"),
    ("the connection came back **unreachable**", "the modem forwards to a local address where "
     "no machine answers: the forwarding's target (a changed local IP) first"),
    ("another program answered instead of our listener", "forwarded to another machine, or the "
     "port used by a service on the modem"),
    ("this component's local IP differs from the settings, or changed since the last run "
     "(`router.local_ip` history)", "the forwarding points at the old address: forwarding first"),
    ("a private router right behind this component's own (`isp.cgnat`: double NAT)",
     "forward on the inner router to this component, or bridge mode, first; the outer one "
     "second"),
    ("other ports get through, the test port does not", "the forwarding rule is incomplete"),
    ("the connection was **silent** while the public IP answers ping", "the modem is online "
     "and drops it: forwarding (or the component is off) before the provider"),
    ("silent, and the public IP does not answer ping either", "the address may be wrong or "
     "offline: the hosts entry and the provider first"),
    ("how old the peer's address is (`linux.resolve`: when the settings holding it were saved, "
     "the peer's own sync record)", "confirmed within the hour: a stale address is unlikely, "
     "the modem's forwarding or firewall first; older than a day, undated, or a newer sync "
     "record with another address: the address first"),
    ("UPnP: the modem's WAN address is the public IP; the path probe's hops are public",
     "no carrier NAT: the provider moves down (not for a corporate firewall)"),
    ("the network profile is office or portable", "nothing is forwarded: no Table 1, no "
     "modem advice; firewalls and addresses on the LAN instead"),
    ("the connection type (corporate, telecom, home)", "only breaks a tie: corporate and "
     "telecom put the administrator or carrier first, home the modem"),
)


@dataclass
class Cause:
    """One possible cause: its key, the step that fixes it, its score and why."""

    key: str
    step: str | None
    score: float = 0.0
    seen_for: list[str] = field(default_factory=list)      # observations that point here
    seen_against: list[str] = field(default_factory=list)  # observations that point away

    def up(self, points: float, why: str) -> None:
        self.score += points
        self.seen_for.append(why)

    def down(self, points: float, why: str) -> None:
        self.score -= points
        self.seen_against.append(why)

    def sentence(self) -> str:
        """The observations, as a sentence to append to a finding's meaning."""
        parts = []
        if self.seen_for:
            parts.append("Seen: " + "; ".join(self.seen_for) + ".")
        if self.seen_against:
            parts.append("Less likely here: " + "; ".join(self.seen_against) + ".")
        return " ".join(parts)

    def evidence(self) -> list[str]:
        return [f"+ {w}" for w in self.seen_for] + [f"- {w}" for w in self.seen_against]


def rank(causes: list[Cause], tie: list[str]) -> list[Cause]:
    """*causes* most likely first: by score, then by *tie* (the connection type's order)."""
    pos = {k: i for i, k in enumerate(tie)}
    return sorted(causes, key=lambda c: (-c.score, pos.get(c.key, len(pos))))


def tie_order(ev: Evidence, keys: list[str]) -> list[str]:
    """The connection type's tie-break between "isp" and "forwarding" (and the rest after)."""
    c = ev.s.this.connection
    first = ["isp", "forwarding"] if c in ("corporate", "telecom") else ["forwarding", "isp"]
    return [k for k in first if k in keys] + [k for k in keys if k not in first]


# --------------------------------------------------------------------------- NAT on the way out
@dataclass(frozen=True)
class Nat:
    """What isp.cgnat saw: kind is "cgnat", "inner" (a private router right behind this
    component's own: a router of the user's, e.g. a travel router behind the provider's box),
    "far" (a private address further up: the provider's network) or "" (none seen)."""

    kind: str
    hop: str | None = None         # the address that showed it
    wan_ip: str | None = None      # UPnP: the WAN address of this component's router
    no_nat: str = ""               # words when the evidence says there is no NAT


def nat_seen(ev: Evidence) -> Nat:
    d = ev.data("isp.cgnat")
    if not d:
        return Nat("")
    wan, hop = d.get("wan_ip"), d.get("hop")
    if d.get("cgnat"):
        return Nat("cgnat", hop or wan, wan)
    if d.get("double_nat"):
        hops = list(d.get("hops") or [])
        if wan and is_private(wan):
            return Nat("inner", hop or wan, wan)
        if hop and hop in hops and hops.index(hop) == 1 and not is_shared(hop):
            return Nat("inner", hop, wan)
        return Nat("far", hop or wan, wan)
    if d.get("method") == "upnp" and wan:
        return Nat("", None, wan, f"UPnP: the modem's WAN address is the public IP {wan}, so "
                                  "nothing sits between it and the internet")
    if d.get("method") == "traceroute" and any(h for h in (d.get("hops") or [])[1:]):
        return Nat("", None, None, "the path probe's hops after the modem are public (no "
                                   "carrier NAT)")
    return Nat("")


# --------------------------------------------------------------------------- Table 1
def _t1_port(ev: Evidence) -> int:
    pd, ld = ev.data("router.port_open"), ev.data("router.listener")
    return int(pd.get("test_port") or ld.get("port") or ev.s.probe.port)


def port_rows(ev: Evidence) -> list[Mapping]:
    return [p for p in ev.data("router.port_open").get("ports") or [] if isinstance(p, Mapping)]


def _test_row(ev: Evidence) -> Mapping:
    tp = _t1_port(ev)
    return next((p for p in port_rows(ev) if p.get("port") == tp), {})


def _tester(row: Mapping) -> str:
    via = str(row.get("via") or "")
    return via[5:] if via.startswith("peer:") else "the port checker"


def local_ip_moved(ev: Evidence) -> tuple[str, str] | None:
    """(old, new) when this component's local IP is not the one the modem was set up for: the
    settings say another one, or the history saw another one before the current."""
    li = ev.data("router.local_ip")
    now = li.get("local_ip") or ""
    if not now:
        return None
    if li.get("differs") and li.get("expected_ip"):
        return str(li["expected_ip"]), now
    hist = [h.get("ip") for h in li.get("history") or [] if isinstance(h, Mapping)]
    if li.get("changed") and li.get("previous_ip"):
        return str(li["previous_ip"]), now
    if len(hist) >= 2 and hist[-1] == now and hist[-2] and hist[-2] != now:
        return str(hist[-2]), now
    return None


def table1_causes(ev: Evidence) -> list[Cause]:
    """Table 1's three causes for "listener up, checker says Closed", most likely first."""
    a = Cause("port_in_use", "router")
    b = Cause("isp", "isp")
    c = Cause("forwarding", "router")
    tp = _t1_port(ev)
    pd = ev.data("router.port_open")
    pub = pd.get("public_ip") or ev.my_public_ip()
    where = f"{pub}:{tp}"
    pf = ev.data("router.port_free")
    if pf.get("in_use"):
        a.up(100, f"port {pf.get('port') or tp} is held by {pf.get('process') or 'another process'}"
                  " on this machine")
    elif pf.get("in_use") is False:
        a.down(10, "nothing else listens on the port on this machine")
    row = _test_row(ev)
    answer, who = row.get("answer"), _tester(row)
    others = [p for p in port_rows(ev) if p.get("port") != tp and p.get("answer")]
    if answer == "refused":
        c.up(40, f"{who}'s connection to {where} was refused: something at that address "
                 "answers and rejects it, so the modem is online and most likely does not forward "
                 "the port")
        b.down(20, "a refusal usually comes from the modem itself; a carrier that blocks "
                   "usually drops")
    elif answer == "unreachable":
        c.up(50, f"{who}'s connection to {where} came back unreachable: the modem forwards it "
                 "to a local address where no machine answers")
    elif answer == "other":
        if others and all(p.get("answer") == "token" for p in others):
            a.up(60, f"{where} was answered by another program while the other ports reached "
                     "our listener: a service on the modem (or this port only) owns it")
        else:
            c.up(50, f"{where} was answered by another program, not our listener: the port is "
                     "forwarded to another machine")
    if answer in ("refused", "unreachable", "timeout"):
        a.down(10, "a service holding the port would have accepted the connection")
    if answer == "timeout":
        ping = pd.get("public_ip_ping")
        if ping is True:
            c.up(10, f"{who}'s connection to {where} got no answer while {pub} answers ping: "
                     "the modem is online and drops it")
        elif ping is False:
            b.up(10, f"{who}'s connection to {where} got no answer, and {pub} does not answer "
                     "ping either")
    nat = nat_seen(ev)
    if nat.kind == "cgnat":
        b.up(100, f"isp.cgnat: carrier-grade NAT ({nat.hop})")
    elif nat.kind == "inner":
        gw = ev.data("router.local_ip").get("gateway") or "this component's gateway"
        c.up(60, f"isp.cgnat: a private router ({nat.hop}) sits right behind {gw}: two routers "
                 "of your own, and the inner one must forward too")
        b.up(30, "if the outer router is the provider's, only the provider can open it")
    elif nat.kind == "far":
        b.up(60, f"isp.cgnat: a private address ({nat.hop}) further up the provider's network")
    elif nat.no_nat and ev.s.this.connection != "corporate":
        b.down(15, nat.no_nat)
    moved = local_ip_moved(ev)
    if moved:
        c.up(60, f"router.local_ip: the local IP is {moved[1]} now, the modem was set up for "
                 f"{moved[0]}")
    if any(p.get("reachable") for p in port_rows(ev) if p.get("port") != tp):
        c.up(40, "other ports get through, this one does not")
    return rank([a, b, c], tie_order(ev, ["forwarding", "isp", "port_in_use"]))


# --------------------------------------------------------------------------- a peer's address
def _ping_peer(ev: Evidence, name: str) -> Mapping:
    return (ev.data("linux.ping").get("peers") or {}).get(name) or {}


def _ssh_peer(ev: Evidence, name: str) -> Mapping:
    return (ev.data("linux.ssh").get("peers") or {}).get(name) or {}


def peer_tcp(ev: Evidence, name: str) -> str | None:
    """How the TCP connection to *name*'s SSH port went (ssh first, then ping's fallback)."""
    return _ssh_peer(ev, name).get("tcp") or _ping_peer(ev, name).get("tcp")


def master_answer(ev: Evidence, name: str) -> str | None:
    """How *name*'s ROS master (ROS 2: its Zenoh router) answered us ("connected", "refused",
    ...), when *name* runs it."""
    if name != ev.s.master_name or ev.s.is_master:
        return None
    if ev.s.ros2:
        r = ev.data("ros2.router")
        if r.get("reachable") is True:
            return "connected"
        f = r.get("failure")
        return f if f in ("refused", "timeout", "unreachable") else None
    d = ev.data("ros.master")
    if d.get("reachable") is True:
        return "connected"
    return d.get("tcp")


def master_port_words(ev: Evidence) -> str:
    """The master's port, in words: "the ROS master's port 11311" (ROS 2: the Zenoh router's)."""
    if ev.s.ros2:
        return f"the Zenoh router's port {ev.s.ros.zenoh_port}"
    return f"the ROS master's port {ev.s.ros.port}"


# --------------------------------------------------------------------------- an address's age
FRESH_S = 3600.0       # confirmed within the hour: a stale address is the less likely cause
DAY_S = 86400.0        # within a day: still unlikely; older: public addresses do change

_DATED_BY = {"settings": "settings saved", "sync": "{name}'s own sync record"}


def address_dates(ev: Evidence, name: str, ip: str) -> tuple[Mapping | None, Mapping | None]:
    """(the newest confirmation of *ip* as *name*'s address, a newer source that gives another
    address), from linux.resolve's ``dated``; None where there is none."""
    rows = ((ev.data("linux.resolve").get("names") or {}).get(name) or {}).get("dated") or []
    rows = sorted((r for r in rows if isinstance(r, Mapping) and r.get("ip")
                   and isinstance(r.get("age_s"), (int, float))), key=lambda r: r["age_s"])
    same = next((r for r in rows if r["ip"] == ip), None)
    other = next((r for r in rows if r["ip"] != ip
                  and (same is None or r["age_s"] < same["age_s"])), None)
    return same, other


def dated_words(name: str, row: Mapping) -> str:
    """"203.0.113.2 was confirmed 3 min ago (settings saved)"."""
    by = _DATED_BY.get(str(row.get("by")), str(row.get("by"))).format(name=name)
    return f"{row['ip']} was confirmed {age(row['age_s'])} ago ({by})"


def _date_address(ev: Evidence, name: str, ip: str, addr: Cause, fwd: Cause) -> None:
    """Rank "the address is stale" against "the modem drops it" by the age of *ip*."""
    same, other = address_dates(ev, name, ip)
    if other is not None and other.get("by") == "sync":
        addr.up(50, f"{name}'s own sync record of {age(other['age_s'])} ago gives "
                    f"{other['ip']}, not {ip}")
        return
    if same is None:
        addr.up(0, f"nothing here says when {ip} was last confirmed (no sync record of {name}, "
                   "no time for the settings)")
        return
    said, age_s = dated_words(name, same), float(same["age_s"])
    if age_s < FRESH_S:
        addr.down(30, said)
        fwd.up(30, f"{said}, so the address is most likely right: {name}'s modem is there and "
                   "drops what comes in (no forwarding, or its firewall)")
    elif age_s < DAY_S:
        addr.down(10, said)
        fwd.up(15, f"{said}: a modem that drops what comes in looks the same")
    else:
        addr.up(10, f"{said.replace(' was confirmed ', ' was last confirmed ')}: public "
                    "addresses change when a modem restarts or reconnects")


def resolved_elsewhere(ev: Evidence, name: str) -> tuple[str, str] | None:
    """(resolved, expected) when *name* resolves here to another address than the settings'."""
    n = (ev.data("linux.resolve").get("names") or {}).get(name) or {}
    got, want = n.get("resolved"), n.get("expected")
    if got and want and got != want:
        return str(got), str(want)
    return None


def firewall_refusal(ev: Evidence, name: str, cause: Cause) -> None:
    """Score *cause* ("firewall": *name*'s peers-only table) for a connection to *name* that was
    refused. ROS 1's table answers every address it does not hold with a TCP reset
    (core/exposure/firewall.py), so a refusal is its doing when this machine's public IP is not
    the one *name* was given (the settings' [this] public_ip, which the peers' tables and sync
    records follow): then it comes first. When it is that one, the table lets this machine in:
    the firewall moves down; when nothing says, it carries no weight."""
    if ev.s.ros2 or ev.s.ros.security != "firewall" or not ev.remote:
        cause.down(100, "no peers-only firewall on ROS 1 here")
        return
    seen = ev.data("isp.public_ip").get("public_ip") or ""
    said = ev.s.this.public_ip
    if seen and said and seen != said:
        cause.up(70, f"this machine's public IP is {seen} now, not {said} as the settings say: "
                     f"{name}'s peers-only firewall lets in the addresses it was given and "
                     f"refuses {seen} (a TCP reset) until its set follows")
    elif seen and said:
        cause.down(10, f"this machine's public IP is still {said}, the address {name}'s "
                       "peers-only firewall was given: it lets this machine in")
    else:      # nothing says whether this machine's address moved: a note, no weight
        cause.up(0, f"{name}'s peers-only firewall refuses (resets) every address it does "
                    "not hold")


def peer_causes(ev: Evidence, name: str) -> list[Cause]:
    """Why *name* takes no TCP connection (SSH) from here: "sshd" (not on its ssh_port),
    "forwarding" (its modem), "offline" (it is off or off-line), "address" (the address we use
    for it is wrong), "firewall" (ROS 1: its peers-only table does not hold this machine's
    address), most likely first."""
    sshd, fwd = Cause("sshd", "linux"), Cause("forwarding", "router")
    off, addr = Cause("offline", "isp"), Cause("address", "linux")
    wall = Cause("firewall", "linux")
    kind = peer_tcp(ev, name)
    port = _ssh_peer(ev, name).get("port") or _ping_peer(ev, name).get("port") or 22
    ip = _ssh_peer(ev, name).get("address") or ev.expected_ip(name) or "its address"
    icmp = _ping_peer(ev, name).get("icmp")
    m = master_answer(ev, name)
    if kind == "refused":
        sshd.up(30, f"{ip} refused port {port}: something there is online and rejects it")
        fwd.up(25, f"a modem that does not forward port {port} can refuse it too")
        off.down(30, f"{ip} answered (it refused), so it is online")
        addr.down(20, f"{ip} answered (it refused)")
        if m == "connected":
            sshd.up(40, f"{name}'s {'Zenoh router' if ev.s.ros2 else 'ROS master'} answers at "
                        "the same address, so its modem forwards and the machine is up")
            wall.down(100, f"{name}'s master lets this machine in at the same address, so its "
                           "firewall knows this machine")
        elif m == "refused":
            fwd.up(35, f"{ip} refuses {master_port_words(ev)} as well: the modem (or its "
                       "provider) seems to reject everything")
        if m != "connected":
            firewall_refusal(ev, name, wall)
    elif kind == "unreachable":
        fwd.up(40, f"the connection to {ip}:{port} came back unreachable: {name}'s modem "
                   "forwards to a local address where no machine answers (its local IP changed?)")
        off.up(30, f"or {name} itself is off (the same answer)")
    elif kind in ("timeout", "error") or kind is None:
        if m == "connected":
            fwd.up(45, f"{name}'s {'Zenoh router' if ev.s.ros2 else 'ROS master'} answers at "
                       f"{ip}, but port {port} is dropped: most likely {port} is not forwarded"
                       + ("" if ev.s.ros2 else " (it is outside the forwarded range)"))
        elif icmp is True:
            fwd.up(20, f"{ip} answers ping, so {name}'s modem is online, but drops port {port}")
            off.up(15, f"{name} itself may be off (its modem would still answer ping)")
        elif icmp is False:
            addr.up(25, f"nothing answers at {ip}, not even ping")
            off.up(20, f"{name}'s modem may be off-line")
        if m == "refused":
            fwd.up(30, f"{ip} refuses {master_port_words(ev)} while port {port} gets no answer: "
                       "something at that address answers, and lets nothing in")
            addr.down(20, f"{ip} answers (it refused {master_port_words(ev)})")
            off.down(20, f"{ip} answers, so it is online")
        if m != "connected":
            _date_address(ev, name, ip, addr, fwd)
    moved = resolved_elsewhere(ev, name)
    if moved:
        addr.up(50, f"{name} resolves to {moved[0]} here, not to {moved[1]} as the settings say")
    if kind != "refused":
        wall.down(100, "a peers-only firewall refuses at once; this was no refusal")
    return rank([sshd, fwd, off, addr, wall],
                ["forwarding", "sshd", "offline", "address", "firewall"])


def peer_check_ids(ev: Evidence, name: str) -> list[str]:
    """The Linux checks that failed for *name* (plus ros.node_uris when it could not check from
    the peer for the same reason): what a finding about reaching *name* explains."""
    ids = [c for c in ("linux.ping", "linux.ssh", "linux.chat_out", "linux.chat_in")
           if (ev.data(c).get("peers") or {}).get(name) is not None and ev.is_fail(c)]
    nd = ev.data("ros.node_uris")
    if _ssh_peer(ev, name).get("failure") == "network" \
            and ev.status("ros.node_uris") is Status.WARN and nd and not nd.get("unreachable"):
        ids.append("ros.node_uris")      # could not check from the peer: same cause
    return ids or ["linux.ping", "linux.ssh"]


def ssh_refused_first(ev: Evidence, name: str) -> bool:
    """*name*'s SSH port refused us: the linux.ssh.refused finding explains it (not
    linux.peer.unreachable)."""
    return peer_tcp(ev, name) == "refused" and _ssh_peer(ev, name).get("ok") is not True


# --------------------------------------------------------------------------- the chats
def chat_causes(ev: Evidence, name: str, inbound: bool) -> list[Cause]:
    """Why a chat failed in one direction although the other works: "forwarding" (the modem of
    the side that listened), "firewall" (on that side), "hosts" (the connecting side's entry for
    the listener), most likely first. *inbound*: *name* could not connect to us."""
    fwd, fw, hosts = Cause("forwarding", "router"), Cause("firewall", "linux"), \
        Cause("hosts", "linux")
    cid = "linux.chat_in" if inbound else "linux.chat_out"
    kind = ((ev.data(cid).get("peers") or {}).get(name) or {}).get("tcp")
    target = ev.me if inbound else name
    if not ev.remote:
        fwd.down(100, f"on the {ev.s.this.profile} LAN nothing is forwarded")
    if inbound:
        po = ev.data("router.port_open").get("test_port_open")
        if po is True:
            fwd.down(40, "router.port_open: the test port is open from outside")
            hosts.up(30, f"{name} reached the port from outside in the port test, yet not "
                         f"by the name {ev.me}")
        elif po is False:
            fwd.up(40, "router.port_open: the test port is closed from outside (Table 1)")
    else:
        moved = resolved_elsewhere(ev, name)
        if moved:
            hosts.up(50, f"{name} resolves to {moved[0]} here, not to {moved[1]}")
    if kind == "refused":
        fwd.up(15, f"the connection to {target} was refused: the modem rejects the port, or a "
                   "firewall there does")
        fw.up(15, f"a firewall on {target} that rejects would refuse it too")
        if not inbound:
            firewall_refusal(ev, name, fw)
    elif kind in ("timeout", "unreachable"):
        fwd.up(15, f"the connection to {target} got no answer (dropped)")
    return rank([fwd, fw, hosts], ["forwarding", "firewall", "hosts"])


# --------------------------------------------------------------------------- the ROS master
def master_causes(ev: Evidence, master: str) -> list[Cause]:
    """Why the master does not answer at ROS_MASTER_URI: "roscore" (not running there),
    "forwarding" (its port is not forwarded to it), "address" (the name leads elsewhere),
    "peer" (the master's machine cannot be reached at all), "firewall" (its peers-only table
    does not hold this machine's address), most likely first."""
    core, fwd = Cause("roscore", "ros"), Cause("forwarding", "router")
    addr, peer = Cause("address", "linux"), Cause("peer", "linux")
    wall = Cause("firewall", "linux")
    d = ev.data("ros.master")
    kind, port = d.get("tcp"), ev.s.ros.port
    if ev.s.is_master:
        fwd.down(100, "the master is this machine: nothing is forwarded on the way")
        peer.down(100, "the master is this machine")
        own = (ev.data("linux.resolve").get("names") or {}).get(ev.me) or {}
        here = ev.data("router.local_ip").get("local_ip")
        if own.get("resolved") and here and own["resolved"] != here:
            addr.up(60, f"{ev.me} resolves to {own['resolved']}, but this machine's address "
                        f"is {here} now")
        if does_not_resolve(ev, ev.me):
            addr.up(80, f"{ev.me} does not resolve here (linux.resolve): ROS_MASTER_URI "
                        "names nothing")
        if kind == "refused":
            core.up(40, f"port {port} was refused on this machine: nothing listens there")
        wall.down(100, "the master is this machine (loopback gets in)")
        return rank([core, addr, fwd, peer, wall],
                    ["roscore", "address", "forwarding", "peer", "firewall"])
    ssh = _ssh_peer(ev, master)
    reached = ssh.get("ok") is True or ssh.get("tcp") == "connected"
    ip = ssh.get("address") or ev.expected_ip(master) or "its address"
    if kind == "refused":
        firewall_refusal(ev, master, wall)
        if reached:
            core.up(50, f"{master} answers SSH at {ip} but refuses port {port}: most likely "
                        "nothing listens there")
            wall.down(100, f"{master}'s firewall lets this machine in on SSH, so it knows "
                           "this machine's address")
        elif peer_tcp(ev, master) == "refused":
            fwd.up(40, f"{ip} refuses port {port} and its SSH port alike: the modem (or its "
                       "provider) seems to reject everything")
        else:
            core.up(20, f"port {port} was refused at {ip}: nothing listens there, or the modem "
                        "rejects it")
            fwd.up(10, f"a modem that does not forward {port} can refuse it too")
    elif kind in ("timeout", "unreachable"):
        if reached:
            fwd.up(40, f"{master} answers SSH at {ip}, but port {port} is dropped: the forwarded "
                       f"range (or a firewall on {master}) does not let {port} through")
        elif ssh.get("failure") in ("network", "timeout"):
            peer.up(40, f"{master} itself cannot be reached from here (see the Linux step)")
            fwd.up(10, f"port {port} got no answer either")
    moved = resolved_elsewhere(ev, master)
    if moved:
        addr.up(60, f"{master} resolves to {moved[0]} here, not to {moved[1]}")
    if does_not_resolve(ev, master):
        addr.up(80, f"{master} does not resolve here (linux.resolve): no connection to it can "
                    "even start")
    if kind != "refused":
        wall.down(100, "a peers-only firewall refuses at once; this was no refusal")
    return rank([core, fwd, addr, peer, wall],
                ["roscore", "forwarding", "peer", "address", "firewall"])
