"""What the rules read: the round's results and the settings, and the helpers rules share.

:class:`Evidence` is the one object a rule's predicate receives. The helpers below it are the
ones more than one step's rules use (the ISP rules and Table 1 both describe carrier NAT; the
ROS rules ask whether the Linux step found a peer unreachable).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from urllib.parse import urlsplit

from rosnet_tui.core.addresses import is_loopback
from rosnet_tui.core.checks.data import CheckData, view
from rosnet_tui.core.config.settings_model import PORT_MAX, PORT_MIN, Settings
from rosnet_tui.core.files.hosts import hosts_entries
from rosnet_tui.core.results import CheckResult, Status

FORWARD_RANGE = f"{PORT_MIN}-{PORT_MAX}"
__all__ = ["FORWARD_RANGE", "Evidence", "RuleOrderError", "cgnat_text", "chat_ok",
           "does_not_resolve", "is_unreachable", "join_and", "linux_peers", "offline_ids", "peer_state", "status_of",
           "uri_host"]


class RuleOrderError(Exception):
    """The rules' declared dependencies are wrong (a cycle, an unknown id, an undeclared read)."""


def status_of(r: CheckResult) -> Status:
    return r.status if isinstance(r.status, Status) else Status(str(r.status))


def join_and(items: Iterable[str]) -> str:
    """'a', 'a and b', 'a, b and c'."""
    items = [str(i) for i in items]
    if len(items) <= 1:
        return "".join(items)
    return ", ".join(items[:-1]) + " and " + items[-1]


def uri_host(uri: str) -> str:
    """The host part of a ROS URI (``http://sami:41234/`` -> ``sami``)."""
    try:
        return urlsplit(uri).hostname or ""
    except ValueError:
        return ""


class Evidence:
    """The results of one round by id, plus the settings, with helpers the predicates share."""

    def __init__(self, results: Mapping[str, CheckResult], settings: Settings) -> None:
        self.results = dict(results)
        self.s = settings
        self._fired: set[str] = set()           # rules that fired so far (the engine adds)
        # (rule id, its `after`) while the engine evaluates that rule
        self._reading: tuple[str, tuple[str, ...]] | None = None

    # results
    def get(self, cid: str) -> CheckResult | None:
        r = self.results.get(cid)
        if r is None or status_of(r) is Status.SKIP:
            return None
        return r

    def data(self, cid: str) -> CheckData:
        """*cid*'s data as declared in checks.data (empty when the check is absent or skipped).

        Reading a key the check does not declare raises UndeclaredKeyError, also on an empty
        view: a rule that reads a renamed key fails the tests instead of going quiet.
        """
        r = self.get(cid)
        return view(cid, r.data if r is not None and isinstance(r.data, dict) else None)

    def status(self, cid: str) -> Status | None:
        r = self.get(cid)
        return status_of(r) if r is not None else None

    def is_fail(self, cid: str) -> bool:
        return self.status(cid) is Status.FAIL

    def sev(self, cid: str, default: str = "warn") -> str:
        """'fail' when the check failed, else *default*."""
        return "fail" if self.is_fail(cid) else default

    # rules
    def fired_any(self, *rule_ids: str) -> bool:
        """True when one of *rule_ids* fired this round.

        Only for rules named in the asking rule's ``after``: the engine evaluates those first,
        so the answer is complete; asking about any other rule is an error, not a silent False.
        """
        if self._reading is not None:
            rid, after = self._reading
            missing = [r for r in rule_ids if r not in after]
            if missing:
                raise RuleOrderError(f"rule {rid} reads whether {', '.join(missing)} fired but "
                                     "does not name it in after=(...)")
        return any(r in self._fired for r in rule_ids)

    # settings
    @property
    def me(self) -> str:
        return self.s.this.name or "this component"

    @property
    def remote(self) -> bool:
        return self.s.this.profile == "remote"

    def expected_ip(self, name: str) -> str:
        for e in hosts_entries(self.s):
            if e.name == name:
                return e.ip
        return ""

    def peer_public(self, name: str) -> str:
        p = self.s.peer(name)
        return p.public_ip if p else ""

    def peer_local(self, name: str) -> str:
        p = self.s.peer(name)
        return p.local_ip if p else ""

    def ssh_user(self, name: str) -> str:
        p = self.s.peer(name)
        return (p.ssh_user if p and p.ssh_user else "USER")

    def my_local_ip(self) -> str:
        d = self.data("router.local_ip")
        return d.get("local_ip") or self.s.this.local_ip or "this component's local IP"

    def my_public_ip(self) -> str:
        return (self.data("isp.public_ip").get("public_ip") or self.s.this.public_ip
                or "this component's public IP")

    def component(self, host: str) -> tuple[str | None, str]:
        """Which component *host* (a name or an address) belongs to, and as what.

        The kind is "name", "local_ip", "public_ip", "office_ip", "portable_ip", "loopback" or
        "unknown".
        """
        if not host:
            return None, "unknown"
        if is_loopback(host):
            return None, "loopback"
        t = self.s.this
        comps: list[tuple[str, dict[str, str]]] = [
            (t.name, {"local_ip": t.local_ip, "public_ip": t.public_ip, "office_ip": t.office_ip,
                      "portable_ip": t.portable_ip})]
        for p in self.s.peers:
            comps.append((p.name, {"local_ip": p.local_ip, "public_ip": p.public_ip,
                                   "office_ip": p.office_ip, "portable_ip": p.portable_ip}))
        for name, _ in comps:
            if name and host.lower() == name.lower():
                return name, "name"
        if t.name:
            ld = self.data("router.local_ip").get("local_ip")
            if ld and host == ld:
                return t.name, "local_ip"
            pd = self.data("isp.public_ip").get("public_ip")
            if pd and host == pd:
                return t.name, "public_ip"
        for name, addrs in comps:
            for kind in ("local_ip", "public_ip", "office_ip", "portable_ip"):
                if name and addrs[kind] and host == addrs[kind]:
                    return name, kind
        return None, "unknown"


# --------------------------------------------------------------------------- shared by steps
def offline_ids(ev: Evidence) -> list[str]:
    """isp.internet plus the checks that failed only because nothing gets out."""
    ids = ["isp.internet"]
    if ev.is_fail("isp.public_ip") and not ev.data("isp.public_ip").get("public_ip"):
        ids.append("isp.public_ip")
    if ev.is_fail("router.port_open") and ev.data("router.port_open").get("test_port_open") is None:
        ids.append("router.port_open")
    return ids


def cgnat_text(ev: Evidence) -> tuple[str, list[str], list[str]]:
    d = ev.data("isp.cgnat")
    wan, hop = d.get("wan_ip"), d.get("hop")
    pub = ev.data("isp.public_ip").get("public_ip") or "the public address"
    if d.get("cgnat"):
        seen = (f"the modem's WAN address is {wan}" if wan else
                "the modem itself reports no public address of its own" if wan == "" else
                f"the route out passes a carrier NAT address ({hop})" if hop else
                "the route out passes a carrier NAT")
        meaning = (f"Carrier-grade NAT: {seen}, not the public address {pub}. The carrier shares "
                   f"{pub} among many customers, so a connection from outside ends at the "
                   "carrier's NAT and never reaches this modem: forwarding on the modem cannot "
                   "work on this connection, however it is set.")
        acts = ["Ask the carrier (its networking department, not first-line support) for a "
                "public IP on this line: often an option, an APN or a business plan.",
                "Or use another connection for this component: a home or office line, or "
                "another carrier that gives public addresses.",
                "Until then, this component can only connect out: it cannot be the side the "
                "others connect to (not the ROS master, not reachable by SSH from outside)."]
        if not ev.s.ros2:
            meaning += (" Under ROS 1 no forwarding anywhere gets around it: ROS 1 nodes connect "
                        "to each other directly, in both directions (XML-RPC and TCPROS), so "
                        "every component must be reachable from every other.")
            acts[2:] = ["Or move the fleet to ROS 2 over rmw_zenoh with a relay you own (a small "
                        "public server every component dials out to: [relay] in the settings, "
                        "docs/SETTINGS.md); only the relay takes connections.",
                        "Or join the components with a VPN (Tailscale, Husarnet, ZeroTier) and "
                        "give the ROS names its addresses (the office profile's addresses, or "
                        "the hosts entries)."]
    else:
        seen = (f"the modem's WAN address is {wan}" if wan else
                f"a private address ({hop}) sits on the route out beyond the modem" if hop else
                "there is a second NAT on the route out")
        meaning = (f"Double NAT: {seen}, so a second router (the provider's or one of your own) "
                   "sits between this modem and the internet, and connections from outside stop "
                   "at it.")
        acts = ["If the first router is yours (e.g. a provider box in front of your own router): "
                "forward the same ports on it to your router's WAN address, or put your router "
                "in its DMZ, or switch the provider box to bridge mode.",
                "If it belongs to the provider, ask them for a public IP on this line (the same "
                "question as carrier-grade NAT)."]
    return meaning, acts, [f"isp.cgnat: cgnat={bool(d.get('cgnat'))}, "
                           f"double_nat={bool(d.get('double_nat'))}, wan_ip={wan}, hop={hop}"]


def does_not_resolve(ev: Evidence, name: str) -> bool:
    """linux.resolve found no address at all for *name* here."""
    rd = ev.data("linux.resolve")
    info = (rd.get("names") or {}).get(name)
    return name in (rd.get("wrong") or []) and isinstance(info, Mapping) \
        and not info.get("resolved")


def peer_state(ev: Evidence, name: str) -> dict[str, object]:
    ping = (ev.data("linux.ping").get("peers") or {}).get(name) or {}
    ssh = (ev.data("linux.ssh").get("peers") or {}).get(name) or {}
    co = (ev.data("linux.chat_out").get("peers") or {}).get(name) or {}
    ci = (ev.data("linux.chat_in").get("peers") or {}).get(name) or {}
    return {"icmp": ping.get("icmp"), "tcp22": ping.get("tcp22"), "ssh_ok": ssh.get("ok"),
            "ssh_failure": ssh.get("failure"), "fingerprint": ssh.get("fingerprint"),
            "out": chat_ok(co), "in": chat_ok(ci), "out_failure": co.get("failure"),
            "in_failure": ci.get("failure")}


def chat_ok(d: Mapping) -> bool | None:
    """A chat's verdict, or None when the chat itself did not happen (no SSH to run the peer's
    side: failure "no_user" or "ssh:...")."""
    f = str(d.get("failure") or "")
    if f == "no_user" or f.startswith("ssh:"):
        return None
    return d.get("ok")


def linux_peers(ev: Evidence) -> list[str]:
    names: dict[str, None] = {}
    for cid in ("linux.ping", "linux.ssh", "linux.chat_out", "linux.chat_in"):
        for n in ev.data(cid).get("peers") or {}:
            names[n] = None
    return list(names)


def behind_relay(ev: Evidence, name: str) -> bool:
    """*name* is reached through the relay (a tunnel under [relay.tunnels]), not at its own
    address: the direct path's advice (forwards, the peer's modem) does not apply to it."""
    return bool(ev.s.relay.host) and name != ev.s.this.name and name in ev.s.relay.tunnels


def is_unreachable(ev: Evidence, name: str) -> bool:
    st = peer_state(ev, name)
    if st["ssh_ok"] is True or st["out"] is True:
        return False
    if st["ssh_failure"] == "network":
        return True
    return st["tcp22"] is False and st["ssh_failure"] in (None, "timeout", "no_user")
