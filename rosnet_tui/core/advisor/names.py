"""Step 3 (Linux): the rules about names (linux.resolve) and the hosts file's lines for them
(linux.hosts).

A name that does not resolve is a cause, not one symptom among others: nothing here can reach
that component by name, so its finding also names the checks that failed for that reason alone
(ping, SSH, the chats, the master's router), instead of leaving them unexplained.
"""

from __future__ import annotations

from collections.abc import Mapping

from rosnet_tui.core.advisor.engine import Hit, rule
from rosnet_tui.core.advisor.evidence import Evidence, does_not_resolve, join_and
from rosnet_tui.core.results import Status

# (check, the key of its per-peer data, the values that mean "the name did not resolve here")
_NAME_FAILURES = (("linux.ping", "tcp", ("resolve",)),
                  ("linux.ssh", "failure", ("resolve",)),
                  ("linux.chat_out", "failure", ("resolve", "ssh:resolve")),
                  ("linux.chat_in", "failure", ("ssh:resolve",)))


def _name_role(ev: Evidence, name: str) -> str:
    if name == ev.s.this.name:
        return "its own local IP"
    if ev.remote:
        return f"{name}'s public IP"
    return f"{name}'s address on the {ev.s.this.profile} LAN"


def _missing(ev: Evidence, name: str) -> bool:
    """The hosts file has no line for *name*."""
    return name in (ev.data("linux.hosts").get("missing") or [])


def _hosts_id(ev: Evidence, name: str) -> list[str]:
    """linux.hosts when it found *name*'s line missing or wrong."""
    wrong = [w.get("name") for w in ev.data("linux.hosts").get("wrong") or []
             if isinstance(w, Mapping)]
    return ["linux.hosts"] if _missing(ev, name) or name in wrong else []


def failed_by_name(ev: Evidence, name: str) -> list[str]:
    """The checks that failed only because *name* does not resolve here."""
    ids = []
    for cid, key, values in _NAME_FAILURES:
        peer = (ev.data(cid).get("peers") or {}).get(name)
        if ev.is_fail(cid) and isinstance(peer, Mapping) and peer.get(key) in values:
            ids.append(cid)
    if ev.s.ros2 and name == ev.s.master_name and ev.is_fail("ros2.router") \
            and ev.data("ros2.router").get("failure") == "resolve":
        ids.append("ros2.router")
    # The security checks look from a peer over SSH: they could not run there (a warning, or a
    # failure), and a member's own probe dials the master by name.
    for cid in ("security.ssh_auth", "security.outsider"):
        if ev.status(cid) in (Status.FAIL, Status.WARN) and (
                (ev.data(cid).get("ssh_failures") or {}).get(name) == "resolve"
                or cid == "security.outsider" and _probe_by_name(ev, name)):
            ids.append(cid)
    return ids


def _probe_by_name(ev: Evidence, name: str) -> bool:
    """A ROS 2 member's outsider probe found nothing at the master, whose name is *name*."""
    d = ev.data("security.outsider")
    return ev.s.ros2 and not ev.s.is_master and name == ev.s.master_name \
        and d.get("from") == "here" and d.get("cause") == "unreachable"


def _sev(ev: Evidence, ids: list[str]) -> str:
    return "fail" if any(ev.is_fail(c) for c in ids) else "warn"


@rule("linux.name.loopback", "linux", ("linux.hosts", "linux.resolve"),
      "a name maps to loopback (127.0.1.1)",
      "A network name points at this machine's loopback (the 127.0.1.1 line installers write): "
      "anything that derives an address from it talks to itself, and ROS nodes can end up "
      "advertising an address no peer can use.",
      "Remove the name from the 127.0.1.1 line of /etc/hosts and add the right address line.",
      "linux", "fail")
def _name_loopback(ev: Evidence) -> list[Hit]:
    hd, rd = ev.data("linux.hosts"), ev.data("linux.resolve")
    names = list(dict.fromkeys([*(hd.get("loopback") or []), *(rd.get("loopback") or [])]))
    hits = []
    for name in names:
        exp = (rd.get("names") or {}).get(name, {}).get("expected") or ev.expected_ip(name) or "?"
        found = (rd.get("names") or {}).get(name, {}).get("resolved") or "127.0.1.1"
        ids = [c for c in ("linux.hosts", "linux.resolve")
               if name in (ev.data(c).get("loopback") or [])]
        ids += [c for c in _hosts_id(ev, name) if c not in ids]
        hits.append(Hit(
            f"{name} resolves to the loopback address {found} on {ev.me}, not to "
            f"{exp} ({_name_role(ev, name)}): programs here that look the name up talk to "
            "themselves, and ROS nodes can bind or advertise an address no peer reaches.",
            [f"In /etc/hosts on {ev.me}, take {name} off the `{found} ...` line (delete the line "
             f"if {name} is all it holds; keep `127.0.0.1 localhost`).",
             f"Make sure the line `{exp} {name}` is there (`rosnet-tui hosts apply` writes "
             "the right entries).",
             f"Check with `getent hosts {name}`: it must print {exp}."],
            check_ids=ids, severity=_sev(ev, ids), evidence=[f"{name} -> {found}"]))
    return hits


@rule("linux.name.unresolved", "linux", ("linux.resolve", "linux.hosts"),
      "a name does not resolve",
      "A component's name has no address here (no hosts line, and no DNS record): nothing on "
      "this machine can reach that component by name, so every check that connects to it fails "
      "for that reason alone.",
      "Add the hosts line for that name (`rosnet-tui hosts apply` writes every line, with a "
      "preview and a backup).",
      "linux", "fail")
def _name_unresolved(ev: Evidence) -> list[Hit]:
    rd = ev.data("linux.resolve")
    hits = []
    for name in rd.get("wrong") or []:
        if not does_not_resolve(ev, name):
            continue
        exp = ((rd.get("names") or {}).get(name) or {}).get("expected") \
            or ev.expected_ip(name) or "?"
        ids = ["linux.resolve", *_hosts_id(ev, name), *failed_by_name(ev, name)]
        if _missing(ev, name):
            meaning = (f"{name} does not resolve on {ev.me}: /etc/hosts has no line for it (and "
                       f"no DNS server knows it). It should be {exp} ({_name_role(ev, name)}).")
            acts = [f"Add `{exp} {name}` to /etc/hosts on {ev.me}: `rosnet-tui hosts apply` "
                    "writes every component's line, with a preview and a backup."]
        else:
            meaning = (f"{name} does not resolve on {ev.me}, although /etc/hosts has a line for "
                       f"it: the system resolver does not read the hosts file. It should be "
                       f"{exp} ({_name_role(ev, name)}).")
            acts = [f"Check that /etc/nsswitch.conf has `files` on its `hosts:` line (before "
                    f"`dns`), and that the line for {name} in /etc/hosts is not commented out."]
        others = [c for c in ids if c not in ("linux.resolve", "linux.hosts")]
        if others:
            meaning += f" Until it does, nothing here reaches {name} by name, which is " \
                       f"why {join_and(others)} failed."
        acts.append(f"Check with `getent hosts {name}`: it must print {exp}.")
        hits.append(Hit(meaning, acts, check_ids=ids, severity=_sev(ev, ids),
                        evidence=[f"{name} -> nothing, expected {exp}"
                                  + ("; no line in /etc/hosts" if _missing(ev, name) else "")]))
    return hits


@rule("linux.name.wrong", "linux", ("linux.hosts", "linux.resolve"),
      "a name resolves to the wrong address",
      "A network name leads to an address that is not the component's (stale public IP, typo, "
      "another line or a DNS record winning).",
      "Correct the hosts line for that name (or find what else answers: nsswitch order, a "
      "second line, DNS).",
      "linux", "fail")
def _name_wrong(ev: Evidence) -> list[Hit]:
    hd, rd = ev.data("linux.hosts"), ev.data("linux.resolve")
    loop = set(hd.get("loopback") or []) | set(rd.get("loopback") or [])
    hosts_wrong = {w["name"]: w for w in hd.get("wrong") or [] if isinstance(w, Mapping)}
    names = [n for n in dict.fromkeys([*(rd.get("wrong") or []), *hosts_wrong])
             if n not in loop and not does_not_resolve(ev, n)]
    hits = []
    for name in names:
        info = (rd.get("names") or {}).get(name, {})
        hw = hosts_wrong.get(name, {})
        exp = info.get("expected") or hw.get("expected") or ev.expected_ip(name) or "?"
        found = info.get("resolved") or hw.get("found")
        ids = []
        if name in hosts_wrong:
            ids.append("linux.hosts")
        if name in (rd.get("wrong") or []):
            ids.append("linux.resolve")
        ids += [c for c in _hosts_id(ev, name) if c not in ids]
        if name in hosts_wrong:
            old = hw.get("found") or found or "?"
            acts = [f"In /etc/hosts on {ev.me}, change `{old} {name}` to `{exp} {name}` "
                    "(`rosnet-tui hosts apply` writes the computed entries, with a preview)."]
        elif _missing(ev, name):
            acts = [f"/etc/hosts on {ev.me} has no line for {name}, so DNS answers {found}: add "
                    f"`{exp} {name}` (`rosnet-tui hosts apply`)."]
        else:
            acts = [f"The hosts file of {ev.me} looks right, yet the system resolver answers "
                    f"{found}: run `getent hosts {name}`, check that /etc/nsswitch.conf lists "
                    "`files` before `dns` for hosts, and look for a DNS record or a second "
                    f"hosts line for {name}."]
        if name != ev.s.this.name and ev.remote:
            acts.append(f"If {exp} is itself out of date, {name}'s public IP has moved: update "
                        f"the settings (or let address sync do it: `rosnet-tui sync`).")
        acts.append(f"Check with `getent hosts {name}`: it must print {exp}.")
        hits.append(Hit(f"{name} resolves to {found} on {ev.me}, but it should be {exp} "
                        f"({_name_role(ev, name)}): everything that uses the name goes to the "
                        "wrong place.", acts, check_ids=ids, severity=_sev(ev, ids),
                        evidence=[f"{name} -> {found}, expected {exp}"]))
    return hits


@rule("linux.hosts.missing", "linux", ("linux.hosts",),
      "a name is missing from the hosts file",
      "The hosts file has no line for a component, so its name depends on DNS (if it resolves "
      "at all).",
      "Add the missing line(s) (`rosnet-tui hosts apply`).",
      "linux", "warn")
def _hosts_missing(ev: Evidence) -> list[Hit]:
    # The names that do not resolve, or resolve wrong, have their own finding (which names
    # linux.hosts): here the ones DNS happens to answer right.
    hd, rd = ev.data("linux.hosts"), ev.data("linux.resolve")
    missing = [n for n in hd.get("missing") or []
               if n not in (rd.get("wrong") or []) and n not in (rd.get("loopback") or [])]
    if not missing:
        return []
    lines = [f"`{ev.expected_ip(n) or '?'} {n}`" for n in missing]
    return [Hit(f"/etc/hosts on {ev.me} has no line for {join_and(missing)}.",
                [f"Add {join_and(lines)} to /etc/hosts on {ev.me} (`rosnet-tui hosts apply` "
                 "writes them, with a preview and a backup)."],
                severity=ev.sev("linux.hosts", "warn"),
                evidence=[f"linux.hosts: missing {join_and(missing)}"])]


@rule("linux.hosts.duplicates", "linux", ("linux.hosts",),
      "a name appears on several hosts lines",
      "The name has several addresses in the hosts file; which one a program gets is not "
      "guaranteed.",
      "Keep one line per name.",
      "linux", "warn")
def _hosts_dupes(ev: Evidence) -> list[Hit]:
    dupes = ev.data("linux.hosts").get("duplicates") or []
    if not dupes:
        return []
    keep = [f"`{ev.expected_ip(n) or '?'} {n}`" for n in dupes]
    return [Hit(f"{join_and(dupes)} appear{'s' if len(dupes) == 1 else ''} on several lines of "
                f"/etc/hosts on {ev.me} with different addresses: the resolver may pick any of "
                "them (glibc even prefers 127.0.1.1).",
                [f"Keep only {join_and(keep)} and delete the other lines for "
                 f"{'that name' if len(dupes) == 1 else 'those names'}."],
                severity=ev.sev("linux.hosts", "warn"),
                evidence=[f"linux.hosts: duplicates {join_and(dupes)}"])]
