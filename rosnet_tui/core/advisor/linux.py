"""Step 3 (Linux): the rules that read the linux.* checks about reaching the peers (ping, SSH,
chat); the names and the hosts file have theirs in :mod:`.names`."""

from __future__ import annotations

from collections.abc import Mapping

from rosnet_tui.core.advisor.engine import Hit, rule
from rosnet_tui.core.advisor.evidence import (
    FORWARD_RANGE,
    Evidence,
    behind_relay,
    is_unreachable,
    linux_peers,
    peer_state,
)
from rosnet_tui.core.advisor.firewall import firewall_action
from rosnet_tui.core.advisor.ranking import (
    Cause,
    chat_causes,
    peer_causes,
    peer_check_ids,
    peer_tcp,
    ssh_refused_first,
)
from rosnet_tui.core.config.settings_model import PORT_MAX, PORT_MIN
from rosnet_tui.core.ssh.known_hosts import fingerprint_command


def _ssh_caused(ev: Evidence, name: str) -> list[str]:
    """The chat checks that failed for *name* only because SSH to it failed."""
    return [c for c in ("linux.chat_out", "linux.chat_in")
            if str(((ev.data(c).get("peers") or {}).get(name) or {}).get("failure")
                   or "").startswith("ssh:")]


@rule("linux.ping.icmp_filtered", "linux", ("linux.ping",),
      "ping fails, TCP to the peer works",
      "ICMP is dropped on the way (many modems and carriers do), but TCP gets through: not a "
      "problem, ROS uses TCP.",
      "Nothing to fix; go on.",
      None, "info")
def _icmp_filtered(ev: Evidence) -> list[Hit]:
    hits = []
    for name, st in (ev.data("linux.ping").get("peers") or {}).items():
        if isinstance(st, Mapping) and st.get("icmp") is False and st.get("tcp22") is True:
            hits.append(Hit(
                f"{name} does not answer ping, but a TCP connection to its port 22 works: ICMP "
                "is filtered on the way (common with modems and mobile carriers). Not a "
                "problem: ROS, SSH and the chat test all use TCP.",
                ["Nothing to fix; go on with the SSH and chat checks."],
                evidence=[f"linux.ping {name}: icmp no, tcp/22 yes"]))
    return hits


def _silent(ev: Evidence, name: str) -> bool:   # dropped, not refused
    return peer_tcp(ev, name) in ("timeout", "error", None)


def _peer_actions(ev: Evidence, name: str, causes: list[Cause], port: int) -> list[str]:
    """One action per cause, in the evidence's order."""
    local = ev.peer_local(name) or "its local IP"
    pub = ev.peer_public(name) or "?"
    ports = f"TCP {port} and {FORWARD_RANGE}" if port < PORT_MIN else f"TCP {FORWARD_RANGE}"
    words = {
        "forwarding": f"Check that {name}'s modem forwards {ports} to {local} (the Router step "
                      f"on {name}: its port test must say Open)"
                      + (f"; port {port} is outside {FORWARD_RANGE} and needs a rule of its own."
                         if port < PORT_MIN else ".")
                      + (" Check the modem's firewall too: one that drops incoming "
                         "connections looks the same from here."
                         if _silent(ev, name) and causes[0].key == "forwarding" else ""),
        "sshd": f"On {name}: sshd may listen on another port than {port}, or not run at all: "
                f"`sudo ss -tlnp | grep sshd` there shows its port; set ssh_port = N under the "
                f"[[peer]] named {name} in the settings, or start it (`sudo systemctl enable "
                "--now ssh`).",
        "offline": f"Check that {name} is switched on, online and running sshd (the ISP step "
                   f"on {name}).",
        "address": f"Check our hosts line for {name}: `getent hosts {name}` must print its "
                   f"current public IP ({pub} in the settings; the ISP step on {name} shows the "
                   f"address it has now). If it moved, `rosnet-tui sync` keeps it current"
                   + (f" once {name}'s sync key is pinned here (`rosnet-tui sync pin {name}`)."
                      if name in (ev.data("linux.resolve").get("unpinned") or ()) else "."),
        "firewall": firewall_action(ev, name),
    }
    return [words[c.key] for c in causes if c.key != "firewall" or c.score > 0]


_LEAD = {
    "forwarding": "most likely {name}'s modem does not forward port {port} to {name}",
    "forwarding_silent": "most likely {name}'s modem does not forward port {port} to {name} "
                         "(or its firewall drops it)",
    "sshd": "most likely sshd on {name} does not listen on port {port} (it may listen on "
            "another one: ssh_port in the settings)",
    "offline": "most likely {name} itself is off or off-line",
    "address": "most likely {ip} is not {name}'s address any more (a new public IP, or "
               "carrier-grade NAT on {name}'s side: its isp.cgnat check tells)",
    "firewall": "most likely {name}'s peers-only firewall does not know this machine's address "
                "yet and refuses it",
}



def _peer_hit(ev: Evidence, name: str, meaning: str) -> Hit:
    causes = peer_causes(ev, name)
    st = peer_state(ev, name)
    ssh = (ev.data("linux.ssh").get("peers") or {}).get(name) or {}
    port = int(ssh.get("port") or 22)
    ip = ssh.get("address") or ev.expected_ip(name) or "?"
    first = causes[0]
    lead = "forwarding_silent" if first.key == "forwarding" and _silent(ev, name) else first.key
    meaning += (" Causes, most likely first: "
                + _LEAD[lead].format(name=name, port=port, ip=ip) + ". " + first.sentence())
    return Hit(meaning.strip(), _peer_actions(ev, name, causes, port),
               check_ids=peer_check_ids(ev, name), goto_step=first.step,
               evidence=[f"{name} ({ip}): icmp={st['icmp']}, tcp={peer_tcp(ev, name)}, "
                         f"ssh={st['ssh_failure'] or st['ssh_ok']}", *first.evidence()])


@rule("linux.peer.unreachable", "linux", ("linux.ping", "linux.ssh"),
      "peer unreachable over TCP (ping may still answer)",
      "No TCP connection gets through to the peer's public address. If the address answers "
      "ping, its modem is online and does not forward to the peer (or the peer is off); if "
      "nothing answers, the address is probably wrong (stale hosts entry, changed IP, carrier "
      "NAT) or the modem is offline.",
      "Ping answers: fix the forwarding on the peer's modem. Nothing answers: check our hosts "
      "line for the peer and its current public IP, then that it is online. The first cause "
      "is the one the evidence supports most.",
      "router", "fail")
def _peer_unreachable(ev: Evidence) -> list[Hit]:
    hits = []
    for name in linux_peers(ev):
        if not is_unreachable(ev, name) or (ev.remote and ssh_refused_first(ev, name)) \
                or behind_relay(ev, name):
            continue
        st = peer_state(ev, name)
        ip = (ev.data("linux.resolve").get("names") or {}).get(name, {}).get("resolved") \
            or ev.expected_ip(name) or "?"
        if not ev.remote:
            exp = ev.expected_ip(name) or "?"
            hits.append(Hit(
                f"{name} ({ip}) does not accept TCP connections from {ev.me} on the "
                f"{ev.s.this.profile} LAN (port 22 and SSH fail).",
                [f"Check that {name} is on the same LAN as {ev.me}, switched on and running "
                 "sshd.",
                 f"Check our hosts line: `getent hosts {name}` must print {exp} (its address "
                 f"on the {ev.s.this.profile} LAN)."],
                check_ids=peer_check_ids(ev, name), goto_step="linux",
                evidence=[f"{name} ({ip}): icmp={st['icmp']}, tcp22={st['tcp22']}, "
                          f"ssh={st['ssh_failure'] or st['ssh_ok']}"]))
            continue
        pub = ev.peer_public(name) or "?"
        if st["icmp"] is True:
            meaning = (f"{ip} answers ping, so {name}'s modem is online, but no TCP connection "
                       f"gets through to {name} (port 22 and SSH fail).")
        else:
            meaning = (f"Nothing answers at {ip}, the address {ev.me} uses for {name}: neither "
                       "ping nor a TCP connection to port 22.")
            if ip != pub and pub != "?":
                meaning += f" The settings say {name} is at {pub}."
        hits.append(_peer_hit(ev, name, meaning))
    return hits


@rule("linux.ssh.refused", "linux", ("linux.ssh", "linux.ping"),
      "the peer's SSH port refuses the connection",
      "Something at the peer's address answers and rejects its SSH port: the address is right "
      "and online. Either sshd does not listen on that port (another port, or not running) or "
      "the peer's modem rejects the port instead of forwarding it.",
      "Find sshd's port on the peer (`sudo ss -tlnp | grep sshd`) and set ssh_port for it, or "
      "start sshd; else forward the port on the peer's modem. The first cause is the one the "
      "evidence supports most.",
      "linux", "fail")
def _ssh_refused(ev: Evidence) -> list[Hit]:
    hits = []
    for name in linux_peers(ev):
        if not ssh_refused_first(ev, name) or behind_relay(ev, name):
            continue
        ssh = (ev.data("linux.ssh").get("peers") or {}).get(name) or {}
        port = int(ssh.get("port") or 22)
        ip = ssh.get("address") or ev.expected_ip(name) or "?"
        icmp = peer_state(ev, name)["icmp"]
        meaning = (f"{ip} refused {ev.me}'s connection to {name}'s SSH port {port}: something "
                   f"there is online and rejects the port"
                   + (" (and the address answers ping)." if icmp else "."))
        if not ev.remote:
            hits.append(Hit(meaning + f" On the {ev.s.this.profile} LAN nothing is forwarded: "
                                      f"sshd on {name} does not listen on {port}.",
                            _peer_actions(ev, name, [Cause("sshd", "linux")], port),
                            check_ids=peer_check_ids(ev, name), goto_step="linux",
                            evidence=[f"{name} ({ip}): port {port} refused"]))
            continue
        hits.append(_peer_hit(ev, name, meaning))
    return hits


def _fp_command(ev: Evidence, name: str, st: Mapping) -> str:
    """The command printing *name*'s own sshd key fingerprint there, of the type it showed."""
    p = ev.s.peer(name)
    return fingerprint_command(p.ssh_port if p else 22, str(st.get("host_key") or "").split(" ")[0])


@rule("linux.ssh.host_key_changed", "linux", ("linux.ssh",),
      "SSH host key changed",
      "The peer shows a different host key than the one recorded: a reinstall or new keys, or "
      "someone in the middle. We refuse to connect.",
      "Verify the new fingerprint out of band; only then `ssh-keygen -R NAME` and accept it.",
      "linux", "fail")
def _ssh_key_changed(ev: Evidence) -> list[Hit]:
    hits = []
    for name, st in (ev.data("linux.ssh").get("peers") or {}).items():
        if not isinstance(st, Mapping) or st.get("failure") != "host_key_changed":
            continue
        fp = st.get("fingerprint") or "(see the evidence)"
        user = ev.ssh_user(name)
        hits.append(Hit(
            f"{name} presented a host key ({fp}) that differs from the one in "
            f"~/.ssh/known_hosts: either {name} was reinstalled or its keys regenerated, or "
            "someone is intercepting the connection. We refuse to connect until you verify.",
            [f"Verify out of band (at {name}'s console, or by someone you trust there): "
             f"`{_fp_command(ev, name, st)}` on {name} must list {fp}.",
             f"If it matches: `ssh-keygen -R {name}` here (and `ssh-keygen -R ADDRESS` for its "
             f"IP), then `ssh {user}@{name}` once and accept the verified key.",
             "If it does not match: do not connect; treat it as an attack and tell whoever runs "
             "the network."],
            evidence=[f"linux.ssh {name}: host key changed, now {fp}"],
            check_ids=["linux.ssh", *_ssh_caused(ev, name)]))
    return hits


@rule("linux.ssh.host_key_unknown", "linux", ("linux.ssh",),
      "SSH host key not known yet",
      "First contact: the peer's host key is not in known_hosts, and we never accept one "
      "silently.",
      "Compare the fingerprint with the peer's own key, then connect once and accept it.",
      "linux", "warn")
def _ssh_key_unknown(ev: Evidence) -> list[Hit]:
    hits = []
    for name, st in (ev.data("linux.ssh").get("peers") or {}).items():
        if not isinstance(st, Mapping) or st.get("failure") != "host_key_unknown":
            continue
        fp = st.get("fingerprint") or "(see the evidence)"
        hits.append(Hit(
            f"{name}'s host key ({fp}) is not in ~/.ssh/known_hosts yet; it is never accepted "
            "silently.",
            [f"On {name} (console or a trusted channel) run `{_fp_command(ev, name, st)}` and "
             f"compare with {fp}.",
             f"If they match: `ssh {ev.ssh_user(name)}@{name}` once and answer yes, then re-run "
             "the Linux step."],
            severity=ev.sev("linux.ssh", "warn"),
            evidence=[f"linux.ssh {name}: unknown host key {fp}"],
            check_ids=["linux.ssh", *_ssh_caused(ev, name)]))
    return hits


@rule("linux.ssh.auth", "linux", ("linux.ssh",),
      "SSH: sshd answers, login refused",
      "The network and sshd are fine; the login is refused: wrong user name or no key "
      "installed for it.",
      "Check ssh_user; install the key with `ssh-copy-id USER@NAME` (easier on a LAN first).",
      "linux", "fail")
def _ssh_auth(ev: Evidence) -> list[Hit]:
    hits = []
    for name, st in (ev.data("linux.ssh").get("peers") or {}).items():
        if not isinstance(st, Mapping) or st.get("failure") != "auth":
            continue
        user = ev.ssh_user(name)
        hits.append(Hit(
            f"{name}'s SSH server answered but refused {user}'s login: the network and sshd "
            "work; the user name or the key is the problem.",
            [f"Check that ssh_user = \"{user}\" under the [[peer]] {name} is an account on "
             f"{name}.",
             f"Install your public key there: `ssh-copy-id {user}@{name}` (or append "
             f"~/.ssh/id_ed25519.pub to ~{user}/.ssh/authorized_keys on {name}; that file "
             "mode 600, the folder 700).",
             "Problems that are not network problems are easier to fix on a LAN first."],
            evidence=[f"linux.ssh {name}: authentication failed"],
            check_ids=["linux.ssh", *_ssh_caused(ev, name)]))
    return hits


@rule("linux.ssh.sshd", "linux", ("linux.ssh",),
      "SSH: peer reachable, no SSH server answers",
      "The peer is reachable but nothing speaking SSH answers on its SSH port: sshd is not "
      "installed/running, or the port is not forwarded.",
      "Install and start openssh-server on the peer; forward its SSH port on the peer's modem.",
      "linux", "fail")
def _ssh_sshd(ev: Evidence) -> list[Hit]:
    hits = []
    for name, st in (ev.data("linux.ssh").get("peers") or {}).items():
        if not isinstance(st, Mapping) or st.get("failure") != "sshd":
            continue
        p = ev.s.peer(name)
        port = p.ssh_port if p else 22
        hits.append(Hit(
            f"{name} is reachable, but no SSH server answered on port {port}.",
            [f"On {name}: `sudo apt install openssh-server`, then "
             "`sudo systemctl enable --now ssh`.",
             f"On {name}'s modem: forward TCP {port} to {ev.peer_local(name) or 'its local IP'}"
             + (f" ({port} is outside {FORWARD_RANGE}, so it needs its own rule)."
                if port < PORT_MIN else "."),
             f"Try `ssh {ev.ssh_user(name)}@{name}` on {name}'s own LAN first."],
            evidence=[f"linux.ssh {name}: no SSH server"],
            check_ids=["linux.ssh", *_ssh_caused(ev, name)]))
    return hits


@rule("linux.ssh.resolve", "linux", ("linux.ssh",),
      "SSH: the peer's name does not resolve",
      "The peer's name has no address here, so nothing can connect to it by name.",
      "Add the peer's hosts line (`rosnet-tui hosts apply`).",
      "linux", "fail", superseded_by=("linux.name.unresolved", "linux.name.wrong",
                                      "linux.hosts.missing"))
def _ssh_resolve(ev: Evidence) -> list[Hit]:
    hits = []
    for name, st in (ev.data("linux.ssh").get("peers") or {}).items():
        if isinstance(st, Mapping) and st.get("failure") == "resolve":
            exp = ev.expected_ip(name) or "?"
            hits.append(Hit(f"{name} does not resolve on {ev.me}, so SSH cannot find it.",
                            [f"Add `{exp} {name}` to /etc/hosts on {ev.me} "
                             "(`rosnet-tui hosts apply`)."],
                            evidence=[f"linux.ssh {name}: name does not resolve"]))
    return hits


@rule("linux.ssh.no_user", "linux", ("linux.ssh",),
      "no SSH user set for a peer",
      "Without an SSH user the checks from the peer's side (chat in, pub/sub in, port test from "
      "the peer) cannot run.",
      "Set ssh_user under that [[peer]] in the settings.",
      "linux", "info")
def _ssh_no_user(ev: Evidence) -> list[Hit]:
    hits = []
    for name, st in (ev.data("linux.ssh").get("peers") or {}).items():
        if isinstance(st, Mapping) and st.get("failure") == "no_user":
            hits.append(Hit(f"No SSH user is set for {name}, so the checks that run on "
                            f"{name}'s side are skipped.",
                            [f"Set ssh_user = \"...\" under the [[peer]] named {name} in the "
                             "settings (an account on it that accepts your key)."],
                            evidence=[f"linux.ssh {name}: no ssh_user"]))
    return hits


def _chat_ids(ev: Evidence, name: str) -> list[str]:
    return [c for c in ("linux.chat_out", "linux.chat_in")
            if (ev.data(c).get("peers") or {}).get(name) is not None]


@rule("linux.chat.in_fails", "linux", ("linux.chat_out", "linux.chat_in"),
      "chat works out, fails in",
      "We reach the peer, but the peer cannot reach us: incoming connections to this component "
      "are blocked (our modem's forwarding, our firewall), or the peer's hosts entry for us is "
      "wrong.",
      "Fix this component's forwarding (Router step here) and local firewall; check the peer's "
      "hosts line for us.",
      "router", "fail")
def _chat_in_fails(ev: Evidence) -> list[Hit]:
    hits = []
    me, pub = ev.me, ev.my_public_ip()
    for name in linux_peers(ev):
        st = peer_state(ev, name)
        if not (st["out"] is True and st["in"] is False) or is_unreachable(ev, name):
            continue
        why = st["in_failure"]
        fix_fw = [f"On {me}'s modem: forward TCP {FORWARD_RANGE} to {ev.my_local_ip()} (Router "
                  f"step on {me}: its port test must say Open).",
                  f"On {me}: check that the local firewall lets those ports in "
                  "(`sudo ufw status`, `sudo iptables -S INPUT`)."]
        fix_name = [f"On {name}: `getent hosts {me}` must print {me}'s public IP ({pub}); fix "
                    f"the line `{pub} {me}` in /etc/hosts there."]
        if why == "peer_resolve":
            meaning = (f"{me} reached {name}, but {name} cannot even resolve the name {me}: its "
                       f"hosts file has no line for {me}.")
            acts = [f"On {name}: add `{pub} {me}` to /etc/hosts (`rosnet-tui hosts apply` "
                    f"there)."]
        elif why == "wrong_peer":
            meaning = (f"{me} reached {name}, but when {name} connects to {me} another machine "
                       f"answers: {name}'s hosts entry for {me} is stale, or {me}'s modem "
                       "forwards the port to another local address.")
            acts = fix_name + [f"On {me}'s modem: the forwarding (or DMZ host) must point at "
                               f"{ev.my_local_ip()}."]
        elif why == "local_listen":
            meaning = (f"{me} could not listen on its test port for {name} to connect: another "
                       "program holds it.")
            acts = [f"Choose another test port (port = N under [probe], 1024-{PORT_MAX}) or "
                    "stop the program holding it (see router.port_free)."]
        else:
            causes = chat_causes(ev, name, inbound=True)
            meaning = (f"{me} reached {name}'s listener, but {name} could not connect back to "
                       f"{me}: connections into {me} are blocked (our modem's forwarding, or a "
                       f"firewall here), or {name} uses an old address for {me}. "
                       + causes[0].sentence())
            fixes = {"forwarding": fix_fw[0], "firewall": fix_fw[1], "hosts": fix_name[0]}
            acts = [fixes[c.key] for c in causes if c.score > -50]
            hits.append(Hit(meaning.strip(), acts, check_ids=_chat_ids(ev, name),
                            goto_step=causes[0].step, evidence=[
                                f"chat to {name} ok; from {name}: {why or 'failed'}",
                                *causes[0].evidence()]))
            continue
        goto = {"local_listen": "router"}.get(why or "", "linux")
        hits.append(Hit(meaning, acts, check_ids=_chat_ids(ev, name), goto_step=goto,
                        evidence=[f"chat to {name} ok; from {name}: {why or 'failed'}"]))
    return hits


@rule("linux.chat.out_fails", "linux", ("linux.chat_out", "linux.chat_in"),
      "chat works in, fails out",
      "The peer reaches us, but we cannot reach the peer's listener: the peer's modem does not "
      "forward the port, its firewall blocks it, or our hosts entry for it is wrong.",
      "Fix the peer's forwarding (Router step on the peer) and its firewall; check our hosts "
      "line for it.",
      "router", "fail")
def _chat_out_fails(ev: Evidence) -> list[Hit]:
    hits = []
    me = ev.me
    for name in linux_peers(ev):
        st = peer_state(ev, name)
        if not (st["in"] is True and st["out"] is False) or is_unreachable(ev, name):
            continue
        why = st["out_failure"]
        exp = ev.expected_ip(name) or ev.peer_public(name) or "?"
        local = ev.peer_local(name) or "its local IP"
        if why == "resolve":
            meaning = f"{name} reached {me}, but {me} cannot resolve the name {name}."
            acts = [f"On {me}: add `{exp} {name}` to /etc/hosts (`rosnet-tui hosts apply`)."]
        elif why == "wrong_peer":
            meaning = (f"{name} reached {me}, but when {me} connects to {name} another machine "
                       f"answers: our hosts entry for {name} is stale, or {name}'s modem "
                       "forwards the port to the wrong local address.")
            acts = [f"Here: `getent hosts {name}` must print {exp}.",
                    f"On {name}'s modem: the forwarding (or DMZ host) must point at {local}."]
        elif why == "peer_listen":
            meaning = f"{name} could not start a listener on the test port for {me} to connect."
            acts = [f"On {name}: another program may hold the test port "
                    f"({ev.s.probe.port}); choose another test port in the settings."]
        else:
            causes = chat_causes(ev, name, inbound=False)
            meaning = (f"{name} reached {me}, but {me} could not connect to {name}'s listener: "
                       f"connections into {name} are blocked ({name}'s modem forwarding, or its "
                       "firewall), or our hosts line sends us to an old address. "
                       + causes[0].sentence())
            fixes = {"forwarding": f"On {name}'s modem: forward TCP {FORWARD_RANGE} to {local} "
                                   f"(Router step on {name}).",
                     "firewall": (firewall_action(ev, name) if causes[0].key == "firewall"
                                  and not ev.s.ros2 and ev.s.ros.security == "firewall" else
                                  f"On {name}: check its firewall (`sudo ufw status`)."),
                     "hosts": f"Here: `getent hosts {name}` must print {exp}."}
            hits.append(Hit(meaning.strip(), [fixes[c.key] for c in causes if c.score > -50],
                            check_ids=_chat_ids(ev, name), goto_step=causes[0].step,
                            evidence=[f"chat from {name} ok; to {name}: {why or 'failed'}",
                                      *causes[0].evidence()]))
            continue
        hits.append(Hit(meaning, acts, check_ids=_chat_ids(ev, name),
                        goto_step="router" if why == "peer_listen" else "linux",
                        evidence=[f"chat from {name} ok; to {name}: {why or 'failed'}"]))
    return hits


@rule("linux.chat.both_fail", "linux", ("linux.chat_out", "linux.chat_in"),
      "SSH works, chat fails both ways",
      "Port 22 gets through but the high ports do not, in either direction: the forwarded range "
      "is missing on both modems, or firewalls allow SSH only.",
      f"Forward {FORWARD_RANGE} on both modems; check both firewalls.",
      "router", "fail")
def _chat_both(ev: Evidence) -> list[Hit]:
    hits = []
    for name in linux_peers(ev):
        st = peer_state(ev, name)
        if st["in"] is False and st["out"] is False and not is_unreachable(ev, name) \
                and not ev.remote:
            hits.append(Hit(
                f"The chat between {ev.me} and {name} fails in both directions on the "
                f"{ev.s.this.profile} LAN, while {name} itself is reachable: firewalls on both "
                "sides let SSH in and block the high ports (nothing is forwarded on a LAN).",
                [f"Check both firewalls (`sudo ufw status` on {ev.me} and on {name}): TCP "
                 f"{FORWARD_RANGE} must be allowed in, not only SSH."],
                check_ids=_chat_ids(ev, name), goto_step="linux",
                evidence=[f"chat with {name}: out {st['out_failure']}, in {st['in_failure']}"]))
        elif st["in"] is False and st["out"] is False and not is_unreachable(ev, name):
            hits.append(Hit(
                f"The chat between {ev.me} and {name} fails in both directions, while {name} "
                "itself is reachable: the high ports are blocked on both sides.",
                [f"Forward TCP {FORWARD_RANGE} on both modems ({ev.me} -> "
                 f"{ev.my_local_ip()}, {name} -> {ev.peer_local(name) or 'its local IP'}).",
                 "Check both firewalls (`sudo ufw status`): SSH alone being allowed is not "
                 "enough for ROS."],
                check_ids=_chat_ids(ev, name),
                evidence=[f"chat with {name}: out {st['out_failure']}, in {st['in_failure']}"]))
    return hits
