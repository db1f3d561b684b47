"""Step 4 (ROS): the rules that read the ros.* checks (environment, master, node URIs, pub/sub)."""

from __future__ import annotations

from collections.abc import Mapping
from urllib.parse import urlsplit

from rosnet_tui.core.addresses import is_ip
from rosnet_tui.core.advisor.engine import Hit, rule
from rosnet_tui.core.advisor.evidence import (
    FORWARD_RANGE,
    Evidence,
    is_unreachable,
    join_and,
    linux_peers,
    uri_host,
)
from rosnet_tui.core.advisor.firewall import firewall_action
from rosnet_tui.core.advisor.ranking import master_causes
from rosnet_tui.core.results import Status


def _ros_trouble(ev: Evidence) -> bool:
    return any(ev.is_fail(c) for c in ("ros.node_uris", "ros.pubsub_out", "ros.pubsub_in"))


def _uri_rule(ev: Evidence, exp: str) -> str:
    """What ROS_MASTER_URI must be on this component, and why."""
    if ev.s.is_master:
        return (f"{ev.me} is the master: its ROS_MASTER_URI must use its own name or local IP "
                f"({exp}); roscore will not start on its public IP.")
    return (f"{ev.me} is a member: its ROS_MASTER_URI must use the master's name ({exp}), "
            "which its hosts file maps to the master's public IP.")


def _expected_uri(ev: Evidence) -> str:
    return ev.data("ros.env").get("expected_uri") \
        or f"http://{ev.s.master_name or 'MASTER'}:{ev.s.ros.port}"


@rule("ros.env.master_uri_unset", "ros", ("ros.env",),
      "ROS_MASTER_URI not set",
      "Neither this shell nor ~/.bashrc sets ROS_MASTER_URI: nodes started here do not know "
      "where the master is (they stop at once, or look for one on localhost).",
      "Set `export ROS_MASTER_URI=http://MASTER:11311` in ~/.bashrc (`rosnet-tui ros apply`), "
      "open a new shell, restart the nodes.",
      "ros", "fail")
def _master_uri_unset(ev: Evidence) -> list[Hit]:
    d = ev.data("ros.env")
    if not d or d.get("uri_ok") is not False or d.get("env_uri") or d.get("bashrc_uri"):
        return []
    exp = _expected_uri(ev)
    return [Hit(f"ROS_MASTER_URI is not set on {ev.me}, neither in this shell nor in "
                f"~/.bashrc: nodes started here do not know where the master is. Set it to "
                f"{exp}. {_uri_rule(ev, exp)}",
                [f"`rosnet-tui ros apply` on {ev.me} writes `export ROS_MASTER_URI={exp}` into "
                 "~/.bashrc (it shows the change first; `rosnet-tui undo` takes it back).",
                 f"Then open a new terminal (or run `export ROS_MASTER_URI={exp}` in this one) "
                 "and start the nodes from there."],
                severity=ev.sev("ros.env", "fail"),
                evidence=[f"ros.env: ROS_MASTER_URI set neither in the environment nor in "
                          f"~/.bashrc, expected {exp}"])]


@rule("ros.env.master_uri", "ros", ("ros.env",),
      "ROS_MASTER_URI wrong for the role",
      "Nodes started here look for the master at the wrong place (a member must use the "
      "master's name; the master its own name or local IP - roscore refuses its public IP).",
      "Set `export ROS_MASTER_URI=http://MASTER:11311` in ~/.bashrc (`rosnet-tui ros apply`), "
      "open a new shell, restart the nodes.",
      "ros", "fail")
def _master_uri(ev: Evidence) -> list[Hit]:
    d = ev.data("ros.env")
    env_uri, rc_uri = d.get("env_uri"), d.get("bashrc_uri")
    if not d or d.get("uri_ok") is not False or not (env_uri or rc_uri):
        return []                       # not set at all: ros.env.master_uri_unset
    exp = _expected_uri(ev)
    if env_uri and rc_uri and env_uri != rc_uri and rc_uri == exp:
        meaning = (f"~/.bashrc has the right ROS_MASTER_URI ({exp}), but this shell still has "
                   f"{env_uri}: it was opened before the change.")
    else:
        meaning = f"ROS_MASTER_URI is {env_uri or rc_uri} on {ev.me}. {_uri_rule(ev, exp)}"
    acts = [f"In ~/.bashrc on {ev.me}: `export ROS_MASTER_URI={exp}`, replacing any other "
            "ROS_MASTER_URI line (`rosnet-tui ros apply` writes it, with a preview).",
            f"In open terminals: `export ROS_MASTER_URI={exp}` (or open a new one), then "
            "restart the nodes started with the old value."]
    return [Hit(meaning, acts, severity=ev.sev("ros.env", "fail"),
                evidence=[f"ros.env: env {env_uri}, ~/.bashrc {rc_uri}, expected {exp}"])]


@rule("ros.env.bashrc", "ros", ("ros.env",),
      "ROS_MASTER_URI in this shell only, or in ~/.bashrc only",
      "The value is right where it is set, but only in one place: without the line in "
      "~/.bashrc new terminals (and nodes started over SSH or at boot) look for the master on "
      "localhost; with it only in ~/.bashrc, this shell was opened before it was written.",
      "Write it into ~/.bashrc with `rosnet-tui ros apply`, or open a new terminal "
      "(`source ~/.bashrc`).",
      "ros", "warn", superseded_by=("ros.env.master_uri",))
def _bashrc(ev: Evidence) -> list[Hit]:
    d = ev.data("ros.env")
    if not d or d.get("uri_ok") is False or ev.status("ros.env") is not Status.WARN:
        return []
    env_uri, rc_uri = d.get("env_uri"), d.get("bashrc_uri")
    exp = d.get("expected_uri") or env_uri or rc_uri
    if env_uri and not rc_uri:
        return [Hit(f"ROS_MASTER_URI={env_uri} is set in this shell on {ev.me}, but not in "
                    "~/.bashrc: new terminals, and nodes started over SSH or at boot, will not "
                    "have it and look for a master on localhost.",
                    [f"Write it into ~/.bashrc on {ev.me}: `rosnet-tui ros apply` (it shows the "
                     "change first, writes a marked block with a backup; `rosnet-tui undo` "
                     "takes it back).",
                     f"Or add the line `export ROS_MASTER_URI={exp}` to ~/.bashrc by hand."],
                    evidence=[f"ros.env: environment {env_uri}, ~/.bashrc none"])]
    if rc_uri and not env_uri:
        return [Hit(f"~/.bashrc on {ev.me} sets ROS_MASTER_URI={rc_uri}, but this shell does "
                    "not have it: it was opened before the line was written.",
                    ["Open a new terminal, or run `source ~/.bashrc` (or "
                     "`eval \"$(rosnet-tui ros export)\"`) in this one; then restart the "
                     "nodes started from it."],
                    evidence=[f"ros.env: environment none, ~/.bashrc {rc_uri}"])]
    return []


@rule("ros.env.ros_ip", "ros", ("ros.env",),
      "ROS_IP/ROS_HOSTNAME set on a remote network",
      "ROS_IP/ROS_HOSTNAME override the hosts-file names: nodes advertise a local address the "
      "peers behind other modems cannot reach, so topics work one way only or not at all.",
      "Unset ROS_IP/ROS_HOSTNAME on that component and remove the line from ~/.bashrc; restart "
      "its nodes.",
      "ros", "warn")
def _ros_ip(ev: Evidence) -> list[Hit]:
    d = ev.data("ros.env")
    vals = [(k, d.get(k.lower())) for k in ("ROS_IP", "ROS_HOSTNAME") if d.get(k.lower())]
    if not vals:
        return []
    if not ev.remote:
        hits = [Hit(f"{k}={v} is set on {ev.me}: fine on the {ev.s.this.profile} LAN, but "
                    "unset it before this component goes onto a remote network.",
                    [f"Before going remote: `unset {k}` and remove its line from ~/.bashrc on "
                     f"{ev.me}."], severity="info", evidence=[f"ros.env: {k}={v}"])
                for k, v in vals]
        return hits
    hits = []
    for k, v in vals:
        if k == "ROS_HOSTNAME" and v == ev.s.this.name:
            hits.append(Hit(f"ROS_HOSTNAME={v} is {ev.me}'s own network name: harmless, since "
                            "every peer resolves that name, but not needed.",
                            [f"Optional: `unset ROS_HOSTNAME` and remove its line from "
                             f"~/.bashrc on {ev.me}."], severity="info",
                            evidence=[f"ros.env: ROS_HOSTNAME={v}"]))
            continue
        what = "address" if k == "ROS_IP" else "host name"
        trouble = _ros_trouble(ev)
        meaning = (f"{k}={v} is set on {ev.me}: every node started here advertises the {what} "
                   f"{v} instead of the name {ev.me}. Peers behind other modems cannot reach "
                   f"{v}, so topics work in one direction only, or not at all.")
        if trouble:
            meaning += " That is what the failing ROS checks show."
        ids = ["ros.env"] + [c for c in ("ros.node_uris", "ros.pubsub_out", "ros.pubsub_in")
                             if trouble and ev.is_fail(c)]
        hits.append(Hit(
            meaning,
            [f"Unset {k} on {ev.me}: run `unset {k}` there and remove (or comment out) the "
             f"`export {k}=...` line in ~/.bashrc on {ev.me} (`rosnet-tui ros apply` comments "
             "it out after asking).",
             f"Restart the ROS nodes on {ev.me} so they advertise {ev.me} again."],
            check_ids=ids, severity="fail" if trouble else ev.sev("ros.env", "warn"),
            evidence=[f"ros.env: {k}={v}"]))
    return hits


def _registration_failed(ev: Evidence) -> list[str]:
    return [c for c in ("ros.pubsub_out", "ros.pubsub_in")
            if ev.data(c).get("ok") is False and ev.data(c).get("failed_hop") == "registration"]


def _node_list_failed(ev: Evidence) -> list[str]:
    """ros.node_uris when it could not list the nodes (or not from the peer): no node named."""
    d = ev.data("ros.node_uris")
    st = ev.status("ros.node_uris")
    if st in (Status.FAIL, Status.WARN) and d and not d.get("unreachable"):
        return ["ros.node_uris"]
    return []


@rule("ros.master.unreachable", "ros", ("ros.master",),
      "the master does not answer",
      "No ROS master answers at ROS_MASTER_URI: roscore is not running there, port 11311 is not "
      "forwarded to it, or its name leads elsewhere.",
      "Start roscore on the master; forward 11311 on its modem; check its hosts line.",
      "ros", "fail")
def _master_down(ev: Evidence) -> list[Hit]:
    d = ev.data("ros.master")
    if not d or d.get("reachable") is not False:
        return []
    uri = d.get("uri") or f"http://{ev.s.master_name}:{ev.s.ros.port}"
    host = uri_host(uri)
    port = urlsplit(uri).port or ev.s.ros.port
    master = ev.s.master_name or host or "the master"
    ids = ["ros.master", *_node_list_failed(ev), *_registration_failed(ev)]
    evid = [f"ros.master: {uri} did not answer" + (f" ({d.get('tcp')})" if d.get("tcp") else "")]
    causes = master_causes(ev, master)
    said = causes[0].sentence()
    if ev.s.is_master:
        here = ev.data("router.local_ip").get("local_ip") or ev.my_local_ip()
        acts = {"roscore": f"Start it on {ev.me}: `roscore` (in its own terminal, or as a "
                           "service). If roscore runs, ROS_MASTER_URI here does not point at "
                           "it (see ros.env).",
                "address": f"Map {ev.me} to this machine's address: `getent hosts {ev.me}` must "
                           f"print {here} (`rosnet-tui hosts apply` after setting local_ip = "
                           f"\"{here}\" under [this]).",
                "forwarding": "", "peer": "", "firewall": ""}
        return [Hit(f"No ROS master answers at {uri} on {ev.me} (this component is the master): "
                    + ("roscore is not running here, or the name leads elsewhere. " + said).strip(),
                    [acts[c.key] for c in causes if acts[c.key]], check_ids=ids,
                    goto_step=causes[0].step, evidence=evid + causes[0].evidence())]
    local = ev.peer_local(master) or "its local IP"
    pub = ev.expected_ip(master) or ev.peer_public(master) or "?"
    acts = {"roscore": f"Is roscore running on {master}? Start `roscore` there; `rostopic list` "
                       f"on {master} itself must work.",
            "forwarding": f"Is TCP {port} forwarded on {master}'s modem to {local}? (The Router "
                          f"step on {master} tests {port} from outside when roscore listens.)",
            "address": f"Does {host or master} lead to the master here? `getent hosts "
                       f"{host or master}` must print {pub}.",
            "peer": f"Reach {master} first (the Linux step): the master follows.",
            "firewall": firewall_action(ev, master)}
    meaning = f"The master {master} does not answer at {uri} from {ev.me}."
    if master in linux_peers(ev) and is_unreachable(ev, master):
        meaning += (f" {master} itself cannot be reached from here (see the Linux step), so "
                    "fix that first: the master follows.")
    return [Hit((meaning + " " + said).strip(),
                [acts[c.key] for c in causes if c.key not in ("peer", "firewall")
                 or c.score > 0], check_ids=ids,
                goto_step=causes[0].step, evidence=evid + causes[0].evidence())]


@rule("ros.master.peer_cannot_register", "ros", ("ros.pubsub_out", "ros.pubsub_in"),
      "the master answers here, a peer cannot register with it",
      "The master works locally, but the peer's nodes cannot reach it: connections from outside "
      "do not get to the master's port 11311 (forwarding, firewall, or the peer's hosts entry "
      "for the master).",
      "Forward 11311 (with the range) to the master's local IP; check the peer's hosts line for "
      "the master.",
      "router", "fail")
def _peer_cannot_register(ev: Evidence) -> list[Hit]:
    failed = _registration_failed(ev)
    if not failed or not ev.s.is_master or ev.data("ros.master").get("reachable") is not True:
        return []
    peer = _pubsub_peer(ev)
    me, port = ev.me, ev.s.ros.port
    pub = ev.my_public_ip()
    acts = [f"On {me}'s modem: forward TCP {FORWARD_RANGE} (11311 included) to "
            f"{ev.my_local_ip()} (the Router step here: its port test must say Open).",
            f"On {me}: the firewall must let TCP {port} in (`sudo ufw status`).",
            f"On {peer}: `getent hosts {me}` must print {pub}, and ROS_MASTER_URI must be "
            f"http://{me}:{port}."]
    meaning = (f"The master answers on {me} itself, but {peer}'s nodes cannot register with "
               f"it: connections from outside do not reach {me}'s port {port}.")
    goto = "router"
    rows = [r for r in ev.data("router.port_open").get("ports") or []
            if isinstance(r, Mapping) and r.get("port") == port]
    if rows and rows[0].get("reachable") is True:      # the forwarding is not it
        meaning = (f"The master answers on {me} itself, and the port test reached port {port} "
                   f"from outside, yet {peer}'s nodes cannot register with it: {peer} looks for "
                   f"the master at the wrong address, or a firewall here lets only some in. "
                   f"Seen: router.port_open: {port} open from outside.")
        acts, goto = [acts[2], acts[1], acts[0]], "linux"
    elif ev.data("router.port_open").get("test_port_open") is False:
        meaning += " Seen: router.port_open: the test port is closed from outside (Table 1)."
    return [Hit(meaning, acts, check_ids=[*failed, *_node_list_failed(ev)], goto_step=goto,
                evidence=[f"{c}: {peer} failed at registration" for c in failed])]


def _uri_problems(ev: Evidence) -> list[dict]:
    """Unreachable advertised URIs, from ros.node_uris and from the pub/sub hops that failed."""
    out: list[dict] = []
    for u in ev.data("ros.node_uris").get("unreachable") or []:
        if isinstance(u, Mapping) and u.get("uri"):
            seat = u.get("from") or "here"
            out.append({"node": u.get("node") or "?", "uri": u["uri"],
                        "host": u.get("host") or uri_host(u["uri"]),
                        "reason": u.get("reason") or "", "check": "ros.node_uris",
                        "seat": ev.me if seat == "here" else seat})
    for cid in ("ros.pubsub_out", "ros.pubsub_in"):
        d = ev.data(cid)
        if d.get("ok") is False and d.get("failed_hop") in ("xmlrpc_callback", "tcpros") \
                and d.get("uri"):
            seat = ev.me if cid == "ros.pubsub_in" else (d.get("peer") or "the peer")
            out.append({"node": d.get("node") or "?", "uri": d["uri"],
                        "host": uri_host(d["uri"]), "reason": d.get("failed_hop"),
                        "check": cid, "seat": seat})
    return out


def _group_uris(ev: Evidence, kinds: tuple[str, ...]) -> dict[tuple, list[dict]]:
    groups: dict[tuple, list[dict]] = {}
    for u in _uri_problems(ev):
        comp, kind = ev.component(u["host"])
        if kind in kinds:
            groups.setdefault((comp, kind, u["host"]), []).append(u)
    return groups


_LOCAL_KINDS = ("local_ip", "office_ip", "portable_ip")


def _nodes(us: list[dict]) -> str:
    return join_and(dict.fromkeys(u["node"] for u in us))


def _uri_ids(us: list[dict]) -> list[str]:
    return list(dict.fromkeys(u["check"] for u in us))


@rule("ros.node_uri.local_ip", "ros", ("ros.node_uris", "ros.pubsub_out", "ros.pubsub_in"),
      "a node advertises a component's local IP",
      "The node's component has ROS_IP set to its local address; peers behind other modems "
      "cannot reach it (the classic 'rostopic list works but no data').",
      "Unset ROS_IP on the component whose address it is; remove it from ~/.bashrc; restart "
      "the node.",
      "ros", "fail")
def _uri_local(ev: Evidence) -> list[Hit]:
    hits = []
    if not ev.remote:
        return []
    for (comp, _kind, host), us in _group_uris(ev, _LOCAL_KINDS).items():
        hits.append(Hit(
            f"{_nodes(us)} on {comp} advertise{'s' if len(us) == 1 else ''} {comp}'s local "
            f"address {host} ({us[0]['uri']}), which nobody behind another modem can reach: "
            f"ROS_IP is set on {comp} (or ROS_HOSTNAME to that address).",
            [f"Unset ROS_IP on {comp}: run `unset ROS_IP` (and `unset ROS_HOSTNAME`) there and "
             f"remove the `export ROS_IP=...` line from ~/.bashrc on {comp} "
             "(`rosnet-tui ros apply` on it comments the line out).",
             f"Restart {_nodes(us)} on {comp}: it must advertise http://{comp}:PORT/."],
            check_ids=_uri_ids(us),
            evidence=[f"{u['check']}: {u['node']} at {u['uri']} ({u['reason']})" for u in us]))
    return hits


@rule("ros.node_uri.loopback", "ros", ("ros.node_uris", "ros.pubsub_out", "ros.pubsub_in"),
      "a node advertises a loopback address",
      "The node's machine gives itself a loopback address (ROS_IP/ROS_HOSTNAME localhost or "
      "127.x, or its host name maps to 127.0.1.1): only that machine can reach the node.",
      "On that machine: unset ROS_IP/ROS_HOSTNAME, fix the 127.0.1.1 hosts line, restart the "
      "node.",
      "ros", "fail")
def _uri_loopback(ev: Evidence) -> list[Hit]:
    hits = []
    for (_, _, host), us in _group_uris(ev, ("loopback",)).items():
        hits.append(Hit(
            f"{_nodes(us)} advertise{'s' if len(us) == 1 else ''} the loopback address {host} "
            f"({us[0]['uri']}): only its own machine can reach it.",
            [f"On the machine running {_nodes(us)}: `unset ROS_IP ROS_HOSTNAME` and remove "
             "those lines from ~/.bashrc.",
             "There, take the machine's name off the `127.0.1.1` line of /etc/hosts and map it "
             "to its local IP; then restart the node."],
            check_ids=_uri_ids(us),
            evidence=[f"{u['check']}: {u['node']} at {u['uri']}" for u in us]))
    return hits


@rule("ros.node_uri.unknown_host", "ros", ("ros.node_uris", "ros.pubsub_out", "ros.pubsub_in"),
      "a node advertises a name or address no component has",
      "The node advertises a host that is not one of the network names in the settings: its "
      "machine's hostname differs from its network name, or ROS_HOSTNAME/ROS_IP points "
      "elsewhere.",
      "Give that machine its network name as hostname (`hostnamectl set-hostname`), unset "
      "ROS_HOSTNAME/ROS_IP, restart the node.",
      "ros", "fail")
def _uri_unknown(ev: Evidence) -> list[Hit]:
    hits = []
    names = join_and([ev.s.this.name, *[p.name for p in ev.s.peers]])
    for (_, _, host), us in _group_uris(ev, ("unknown",)).items():
        if is_ip(host):
            meaning = (f"{_nodes(us)} advertise{'s' if len(us) == 1 else ''} {host} "
                       f"({us[0]['uri']}), an address of none of the components ({names}): "
                       "ROS_IP is set to it on the node's machine, and it cannot be reached "
                       "from here.")
            acts = [f"On the machine running {_nodes(us)}: `unset ROS_IP` and remove it from "
                    "~/.bashrc, then restart the node."]
        else:
            meaning = (f"{_nodes(us)} advertise{'s' if len(us) == 1 else ''} the host name "
                       f"{host} ({us[0]['uri']}), which is not one of the network names "
                       f"({names}): the machine's hostname is not its network name, or "
                       "ROS_HOSTNAME says so.")
            acts = [f"On the machine running {_nodes(us)}: make its hostname its network name "
                    "(`sudo hostnamectl set-hostname NAME`) or `unset ROS_HOSTNAME` and remove "
                    "it from ~/.bashrc; then restart the node.",
                    f"Or, if {host} must stay, add `ADDRESS {host}` to every component's "
                    "hosts file (every peer must resolve it)."]
        hits.append(Hit(meaning, acts, check_ids=_uri_ids(us),
                        evidence=[f"{u['check']}: {u['node']} at {u['uri']}" for u in us]))
    return hits


@rule("ros.node_uri.unreachable", "ros", ("ros.node_uris", "ros.pubsub_out", "ros.pubsub_in"),
      "a node's URI (a component's name or public IP) is unreachable",
      "The node advertises its component correctly, but the port it picked does not get "
      "through: that component's modem does not forward the range, a firewall blocks it, or "
      "our hosts entry for it is wrong.",
      f"On the node's component: forward {FORWARD_RANGE}, check its firewall; here: check its "
      "hosts line.",
      "router", "fail")
def _uri_unreach(ev: Evidence) -> list[Hit]:
    hits = []
    kinds = ("name", "public_ip") + (() if ev.remote else _LOCAL_KINDS)
    for (comp, kind, _host), us in _group_uris(ev, kinds).items():
        port = urlsplit(us[0]["uri"]).port or "its port"
        local = (ev.s.this.local_ip if comp == ev.s.this.name else ev.peer_local(comp or "")) \
            or "its local IP"
        acts = [f"On {comp}'s modem: forward TCP {FORWARD_RANGE} to {local} (nodes use random "
                f"ports; {port} did not get through).",
                f"On {comp}: check the firewall lets {FORWARD_RANGE} in (`sudo ufw status`)."]
        if kind == "name" and comp != ev.s.this.name:
            acts.append(f"Here: `getent hosts {comp}` must print {ev.expected_ip(comp) or '?'}.")
        hits.append(Hit(
            f"{_nodes(us)} on {comp} advertise{'s' if len(us) == 1 else ''} {us[0]['uri']}, "
            f"but {join_and(dict.fromkeys(u['seat'] for u in us))} cannot connect to it "
            f"({us[0]['reason'] or 'no answer'}).",
            acts, check_ids=_uri_ids(us),
            evidence=[f"{u['check']}: {u['node']} at {u['uri']} ({u['reason']})" for u in us]))
    return hits


_HOP_WORDS = {
    "registration": "registering with the master",
    "xmlrpc_callback": "the XML-RPC call to a node's advertised URI",
    "tcpros": "the TCPROS data connection",
    "no_message": "the message delivery (connected, but nothing arrived in time)",
}


def _pubsub_peer(ev: Evidence) -> str:
    for cid in ("ros.pubsub_out", "ros.pubsub_in"):
        if ev.data(cid).get("peer"):
            return ev.data(cid)["peer"]
    return ev.s.peers[0].name if ev.s.peers else "the peer"


def _hop_actions(ev: Evidence, cid: str, sender: str, receiver: str) -> list[str]:
    d = ev.data(cid)
    hop, uri = d.get("failed_hop"), d.get("uri")
    if hop == "registration":
        return [f"A node could not register with the master: check ROS_MASTER_URI on {sender} "
                f"and {receiver} and that the master answers (ros.env, ros.master)."]
    if hop in ("xmlrpc_callback", "tcpros") and uri:
        comp, kind = ev.component(uri_host(uri))
        if kind in ("local_ip", "office_ip", "portable_ip") and comp:
            return [f"Unset ROS_IP on {comp}: the node there advertises its local address "
                    f"({uri}); remove the line from ~/.bashrc on {comp} and restart its nodes."]
        if comp:
            return [f"{uri} on {comp} is not reachable from the other side: forward "
                    f"{FORWARD_RANGE} on {comp}'s modem and check its firewall."]
        return [f"{uri} is not an address of any component: unset ROS_IP/ROS_HOSTNAME on the "
                "node's machine and make its hostname its network name."]
    if hop == "no_message":
        return ["Connections were made but no message arrived in time: the link may be slow or "
                "lossy; re-run, and compare with `rostopic hz` on the real topic."]
    return [f"The node advertised by {sender} is probably not reachable from {receiver}: check "
            f"ROS_IP/ROS_HOSTNAME on {sender} (unset them on a remote network) and {sender}'s "
            f"forwarding of {FORWARD_RANGE}."]


# A registration failure is the master rules' to explain when one of them fired.
_MASTER_RULES = ("ros.master.unreachable", "ros.master.peer_cannot_register")


@rule("ros.pubsub.out_fails", "ros", ("ros.pubsub_out", "ros.pubsub_in"),
      "pub/sub works in, fails out",
      "Messages from the peer reach us, but ours do not reach the peer: one of the two nodes "
      "advertises an address the other side cannot reach (usually ours).",
      "Follow the failed hop: unset ROS_IP/ROS_HOSTNAME where set, forward the range on the "
      "side whose node is unreachable.",
      "ros", "fail", after=_MASTER_RULES)
def _pubsub_out(ev: Evidence) -> list[Hit]:
    return _one_way(ev, "ros.pubsub_out")


@rule("ros.pubsub.in_fails", "ros", ("ros.pubsub_out", "ros.pubsub_in"),
      "pub/sub works out, fails in",
      "Our messages reach the peer, but the peer's do not reach us: one of the two nodes "
      "advertises an address the other side cannot reach (usually the peer's).",
      "Follow the failed hop: unset ROS_IP/ROS_HOSTNAME where set, forward the range on the "
      "side whose node is unreachable.",
      "ros", "fail", after=_MASTER_RULES)
def _pubsub_in(ev: Evidence) -> list[Hit]:
    return _one_way(ev, "ros.pubsub_in")


def _one_way(ev: Evidence, failed: str) -> list[Hit]:
    """pub/sub fails the way *failed* checks (ros.pubsub_out: from us) and works the other."""
    works = "ros.pubsub_in" if failed == "ros.pubsub_out" else "ros.pubsub_out"
    f, w = ev.data(failed), ev.data(works)
    if f.get("failed_hop") == "registration" and ev.fired_any(*_MASTER_RULES):
        return []
    if f.get("ok") is not False or w.get("ok") is not True:
        return []
    peer = _pubsub_peer(ev)
    src, dst = (ev.me, peer) if failed == "ros.pubsub_out" else (peer, ev.me)
    hop = _HOP_WORDS.get(f.get("failed_hop") or "", "an unknown hop")
    said = {failed: f"{failed}: failed at {f.get('failed_hop')}", works: f"{works}: ok"}
    return [Hit(f"Messages published on {dst} reach {src}, but messages published on {src} "
                f"do not reach {dst}; the failing hop is {hop}"
                + (f" ({f.get('node')} at {f.get('uri')})." if f.get("uri") else "."),
                _hop_actions(ev, failed, src, dst),
                check_ids=["ros.pubsub_out", "ros.pubsub_in"],
                evidence=[said["ros.pubsub_out"], said["ros.pubsub_in"]])]


@rule("ros.pubsub.both_fail", "ros", ("ros.pubsub_out", "ros.pubsub_in"),
      "pub/sub fails both ways",
      "No message gets through in either direction while the master answers: node ports are "
      "blocked on both sides, or both sides advertise unreachable addresses.",
      "Check ROS_IP/ROS_HOSTNAME on both sides and the forwarded range on both modems.",
      "ros", "fail", superseded_by=_MASTER_RULES)
def _pubsub_both(ev: Evidence) -> list[Hit]:
    o, i = ev.data("ros.pubsub_out"), ev.data("ros.pubsub_in")
    if o.get("ok") is not False or i.get("ok") is not False:
        return []
    peer = _pubsub_peer(ev)
    acts = _hop_actions(ev, "ros.pubsub_out", ev.me, peer)
    for a in _hop_actions(ev, "ros.pubsub_in", peer, ev.me):
        if a not in acts:
            acts.append(a)
    return [Hit(f"No message gets through between {ev.me} and {peer}, in either direction "
                f"(out: {_HOP_WORDS.get(o.get('failed_hop') or '', '?')}; in: "
                f"{_HOP_WORDS.get(i.get('failed_hop') or '', '?')}).", acts,
                check_ids=["ros.pubsub_out", "ros.pubsub_in"],
                evidence=[f"ros.pubsub_out: {o.get('failed_hop')}",
                          f"ros.pubsub_in: {i.get('failed_hop')}"])]
