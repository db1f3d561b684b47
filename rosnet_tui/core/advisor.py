"""The troubleshooting advisor: rules over check results -> what it means, what to do, where to go.

Rules are data (:data:`RULES`): each has a stable id, the condition in words, a meaning, an action,
the step to go back to, a severity and the check ids it explains, plus a small predicate that reads
the checks' documented ``data`` keys (see the checks contract) and returns concrete hits, with the
names, addresses, ports and processes of this network filled in. Table 1 of the procedure is the
``table1.*`` rules. The same list feeds the TUI's Advisor pane, ``rosnet-tui check``/``report`` and
docs/TROUBLESHOOTING.md (:func:`render_rules_markdown`).
"""

from __future__ import annotations

import ipaddress
import sys
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from urllib.parse import urlsplit

from rosnet_tui.core.hosts import hosts_entries
from rosnet_tui.core.results import CheckResult, Status
from rosnet_tui.core.settings import PORT_MAX, PORT_MIN, Settings

SEVERITIES = ("fail", "warn", "security", "info")
STEP_ORDER = ("isp", "router", "linux", "ros")
_STEP_TITLES = {"isp": "ISP", "router": "Router/modem", "linux": "Linux", "ros": "ROS"}
FORWARD_RANGE = f"{PORT_MIN}-{PORT_MAX}"


@dataclass
class Finding:
    rule: str                  # stable rule id, e.g. "table1.listener_up_closed.forwarding"
    meaning: str               # what it means
    actions: list[str]         # what to do, concrete
    goto_step: str | None      # "isp" | "router" | "linux" | "ros" | None
    check_ids: list[str] = field(default_factory=list)  # the checks this finding explains
    severity: str = "fail"     # "fail" | "warn" | "info" | "security"
    order: int = 0             # rank among several possible causes (0 = most likely)
    condition: str = ""        # the rule's condition in words (the Table-1 "condition" column)
    evidence: list[str] = field(default_factory=list)  # the facts from the results that fired it

    def to_json(self) -> dict:
        return {"rule": self.rule, "meaning": self.meaning, "actions": list(self.actions),
                "goto_step": self.goto_step}

    def to_dict(self) -> dict:
        """Every field (the report's JSON form)."""
        return {"rule": self.rule, "severity": self.severity, "condition": self.condition,
                "meaning": self.meaning, "actions": list(self.actions),
                "goto_step": self.goto_step, "check_ids": list(self.check_ids),
                "order": self.order, "evidence": list(self.evidence)}


@dataclass
class Hit:
    """What a rule's predicate returns for one match; unset fields fall back to the rule's."""

    meaning: str
    actions: list[str]
    check_ids: list[str] | None = None
    severity: str | None = None
    goto_step: str | None = "-"        # "-" = the rule's goto_step
    order: int = 0
    evidence: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class Rule:
    id: str
    step: str                  # the step of the symptom (sort order: procedure order)
    check_ids: tuple[str, ...]  # the checks it reads and explains
    condition: str             # the condition in words
    meaning: str               # the generic meaning (docs / full table)
    action: str                # the generic action (docs / full table)
    goto_step: str | None
    severity: str
    evaluate: Callable[[Evidence], list[Hit]]
    group: str | None = None   # rules of one group (Table 1's causes) are ranked together
    superseded_by: tuple[str, ...] = ()  # drop this rule's hits when one of these fired

    def row(self) -> dict:
        """The rule as a table row (the TUI's full-table view, the docs)."""
        return {"id": self.id, "step": self.step, "condition": self.condition,
                "meaning": self.meaning, "action": self.action, "goto_step": self.goto_step,
                "severity": self.severity, "check_ids": list(self.check_ids)}


# --------------------------------------------------------------------------- evidence helpers
def _status(r: CheckResult) -> Status:
    return r.status if isinstance(r.status, Status) else Status(str(r.status))


def _and(items: Iterable[str]) -> str:
    items = [str(i) for i in items]
    if len(items) <= 1:
        return "".join(items)
    return ", ".join(items[:-1]) + " and " + items[-1]


def _is_loopback(host: str) -> bool:
    if host in ("localhost", "ip6-localhost"):
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _is_ip(host: str) -> bool:
    try:
        ipaddress.ip_address(host)
        return True
    except ValueError:
        return False


def uri_host(uri: str) -> str:
    """The host part of a ROS URI (``http://sami:41234/`` -> ``sami``)."""
    try:
        return urlsplit(uri).hostname or ""
    except ValueError:
        return ""


def step_title(step: str | None) -> str:
    """'Step 2 (Router/modem)' for 'router'."""
    if step not in _STEP_TITLES:
        return "-"
    return f"step {STEP_ORDER.index(step) + 1} ({_STEP_TITLES[step]})"


class Evidence:
    """The results of one round by id, plus the settings, with helpers the predicates share."""

    def __init__(self, results: Mapping[str, CheckResult], settings: Settings) -> None:
        self.results = dict(results)
        self.s = settings
        self.fired: set[str] = set()

    # results
    def get(self, cid: str) -> CheckResult | None:
        r = self.results.get(cid)
        if r is None or _status(r) is Status.SKIP:
            return None
        return r

    def data(self, cid: str) -> dict:
        r = self.get(cid)
        return r.data if r is not None and isinstance(r.data, dict) else {}

    def status(self, cid: str) -> Status | None:
        r = self.get(cid)
        return _status(r) if r is not None else None

    def is_fail(self, cid: str) -> bool:
        return self.status(cid) is Status.FAIL

    def sev(self, cid: str, default: str = "warn") -> str:
        """'fail' when the check failed, else *default*."""
        return "fail" if self.is_fail(cid) else default

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
        if _is_loopback(host):
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


# --------------------------------------------------------------------------- the rule list
RULES: list[Rule] = []


def rule(id: str, step: str, checks: tuple[str, ...], condition: str, meaning: str, action: str,
         goto: str | None, severity: str, group: str | None = None,
         superseded_by: tuple[str, ...] = ()) -> Callable[[Callable], Callable]:
    """Add a rule (in procedure order: the list order is the tie-break of the findings)."""
    if severity not in SEVERITIES:
        raise ValueError(severity)

    def deco(fn: Callable[[Evidence], list[Hit]]) -> Callable[[Evidence], list[Hit]]:
        RULES.append(Rule(id, step, checks, condition, meaning, action, goto, severity, fn,
                          group, superseded_by))
        return fn

    return deco


# ---- step 1: ISP ----------------------------------------------------------------------------
def _url_host(url: str) -> str:
    return uri_host(url) or url or "the test address"


def _offline_ids(ev: Evidence) -> list[str]:
    """isp.internet plus the checks that failed only because nothing gets out."""
    ids = ["isp.internet"]
    if ev.is_fail("isp.public_ip") and not ev.data("isp.public_ip").get("public_ip"):
        ids.append("isp.public_ip")
    if ev.is_fail("router.port_open") and ev.data("router.port_open").get("test_port_open") is None:
        ids.append("router.port_open")
    return ids


@rule("router.local_ip.no_link", "isp", ("router.local_ip",),
      "no local address or no default route",
      "This machine is not on its LAN: the link is down (cable, Wi-Fi), or DHCP gave it no "
      "address or no gateway. Nothing else can work until it is.",
      "Connect the cable or Wi-Fi, check `ip addr` / `ip route`, renew DHCP; then start again "
      "from step 1.",
      "router", "fail")
def _no_link(ev: Evidence) -> list[Hit]:
    d = ev.data("router.local_ip")
    if not d or not ev.is_fail("router.local_ip") or (d.get("local_ip") and d.get("gateway")):
        return []
    iface = d.get("interface") or ev.s.this.interface or "the network interface"
    if not d.get("local_ip"):
        meaning = (f"{ev.me} has no IPv4 address on {iface}: the link is down (cable unplugged, "
                   "Wi-Fi off or not joined) or the modem's DHCP did not answer.")
    else:
        meaning = (f"{ev.me} has the address {d['local_ip']} on {iface} but no default route: "
                   "it cannot reach the modem as its gateway (DHCP incomplete, or a static "
                   "address without a gateway).")
    ids = ["router.local_ip"] + (_offline_ids(ev) if ev.is_fail("isp.internet") else [])
    return [Hit(meaning,
                [f"Check the link: `ip addr show {iface}` must show an address and state UP; "
                 "reconnect the cable or the Wi-Fi (`nmcli device status`).",
                 f"Renew the address: `sudo nmcli device reapply {iface}` (NetworkManager) or "
                 f"`sudo dhclient -v {iface}`; `ip route` must then show a default route via "
                 "the modem.",
                 "Then run the checks again from step 1."],
                check_ids=ids,
                evidence=[f"router.local_ip: address {d.get('local_ip') or 'none'}, gateway "
                          f"{d.get('gateway') or 'none'} on {iface}"])]


@rule("isp.no_internet.dns", "isp", ("isp.internet",),
      "internet check fails at name resolution (DNS)",
      "Names do not resolve: the DNS server this machine uses does not answer, or there is no "
      "link to the modem at all.",
      "Check the link and default route (`ip route`), the nameserver in /etc/resolv.conf "
      "(`resolvectl status`), and try `getent hosts` on a well-known name.",
      "isp", "fail", superseded_by=("router.local_ip.no_link",))
def _no_dns(ev: Evidence) -> list[Hit]:
    d = ev.data("isp.internet")
    if d.get("failed_part") != "dns" and d.get("dns_ok") is not False:
        return []
    host = _url_host(d.get("url", ""))
    gw = ev.data("router.local_ip").get("gateway") or "the modem"
    return [Hit(
        f"{ev.me} cannot resolve names (looking up {host} failed): the DNS server it uses does "
        "not answer, or the link to the modem is down.",
        [f"Check the link: `ip route` must show a default route via {gw}; a mobile hotspot may "
         "have lost its signal or its data allowance.",
         "See which DNS server is used: `resolvectl status` (systemd-resolved) or "
         "`cat /etc/resolv.conf`; it should be the modem or the provider's server.",
         f"Test by hand: `getent hosts {host}`. If the modem answers `ping {gw}` but names still "
         "fail, set a DNS server explicitly in the network settings (NetworkManager: "
         "`nmcli connection modify CONNECTION ipv4.dns ADDRESS`).",
         "Then re-run the ISP step."],
        check_ids=_offline_ids(ev), evidence=[f"isp.internet: DNS lookup of {host} failed"])]


@rule("isp.no_internet.http", "isp", ("isp.internet",),
      "names resolve, the web request fails",
      "Name resolution works but no web request gets through: the connection is down further "
      "up, held by a captive portal or an exhausted data plan, or filtered by a proxy/firewall.",
      "Open the test URL in a browser (login or top-up page?), look at the modem's status page, "
      "ask about a proxy on corporate networks, then call the provider.",
      "isp", "fail", superseded_by=("router.local_ip.no_link",))
def _no_http(ev: Evidence) -> list[Hit]:
    d = ev.data("isp.internet")
    if d.get("failed_part") != "http":
        return []
    url = d.get("url") or "the test URL"
    acts = [f"Open {url} in a browser on {ev.me}: a login, terms or top-up page means a captive "
            "portal or a used-up data plan; accept or top up, then test again.",
            "Look at the modem's status page: WAN connected? mobile signal? data limit reached?"]
    if ev.s.this.connection == "corporate":
        acts.append("On a corporate network, ask the administrator whether web access needs a "
                    "proxy, and whether this machine is allowed out at all.")
    acts.append("If the modem says it is connected and it still fails, call the provider.")
    return [Hit(f"{ev.me} resolves names but the request to {url} got no answer: the internet "
                "connection does not carry traffic.", acts, check_ids=_offline_ids(ev),
                evidence=["isp.internet: DNS ok, HTTP failed"])]


@rule("isp.public_ip.unknown", "isp", ("isp.public_ip",),
      "no source tells the public IP",
      "None of the what-is-my-IP sources answered, so the public address is unknown.",
      "Fix the internet connection first; check the public_ip_urls in the settings.",
      "isp", "fail", superseded_by=("isp.no_internet.dns", "isp.no_internet.http"))
def _public_unknown(ev: Evidence) -> list[Hit]:
    r = ev.get("isp.public_ip")
    d = ev.data("isp.public_ip")
    if r is None or not d or d.get("public_ip") or not ev.is_fail("isp.public_ip"):
        return []
    srcs = d.get("sources") or {}
    errs = [f"{u}: {v}" for u, v in srcs.items()]
    urls = _and(srcs) or "the configured sources"
    return [Hit(f"None of the what-is-my-IP sources ({urls}) told {ev.me} its public address.",
                ["Check that the internet works (ISP step, isp.internet).",
                 "Check public_ip_urls under [probe] in the settings: each URL must answer the "
                 "caller's address as plain text (e.g. https://ifconfig.co/ip).",
                 "Without a public IP no peer can be given this component's address."],
                evidence=errs or ["isp.public_ip: no address"])]


def _ip_answers(d: dict) -> dict[str, str]:
    return {u: v for u, v in (d.get("sources") or {}).items()
            if isinstance(v, str) and _is_ip(v.strip())}


@rule("isp.public_ip.disagree", "isp", ("isp.public_ip",),
      "public IP sources disagree",
      "The what-is-my-IP sources saw different addresses: traffic leaves by more than one route "
      "(VPN, proxy, two WAN links, load balancing), so peers cannot count on one address.",
      "Switch off VPNs/proxies for this component, pin it to one WAN link, then test again.",
      "isp", "warn")
def _public_disagree(ev: Evidence) -> list[Hit]:
    d = ev.data("isp.public_ip")
    answers = _ip_answers(d)
    distinct = sorted({v.strip() for v in answers.values()})
    if len(distinct) < 2:
        return []
    seen = [f"{u} -> {v}" for u, v in answers.items()]
    return [Hit(f"The sources saw {ev.me} behind different public addresses ({_and(distinct)}): "
                "its traffic leaves by more than one route, so a peer cannot know which address "
                "to use.",
                ["Look for a VPN or proxy on this machine (`ip route`, `ip rule`, "
                 "`env | grep -i proxy`) and switch it off for this component.",
                 "If the modem balances or fails over between two WAN links (DSL + mobile), pin "
                 "this component to one of them.",
                 "A source behind a proxy of its own can also answer oddly: drop it from "
                 "public_ip_urls under [probe] if the others agree.",
                 "Re-run the ISP step: every source must report the same address."],
                evidence=seen)]


@rule("isp.public_ip.changed", "isp", ("isp.public_ip",),
      "public IP changed since the last run",
      "The provider gave a new public address: the connection has no fixed IP, and every peer's "
      "hosts entry for this component is now stale.",
      "Run address sync (`rosnet-tui sync`) on every component, or update the peers' hosts "
      "entries by hand; for a lasting fix ask for a fixed IP or use a dynamic DNS name.",
      "isp", "warn")
def _public_changed(ev: Evidence) -> list[Hit]:
    d = ev.data("isp.public_ip")
    if not d.get("changed"):
        return []
    now, prev = d.get("public_ip") or "?", d.get("previous_ip") or "?"
    peers = [p.name for p in ev.s.peers]
    acts = ["Keep the peers in step automatically: run address sync on every component "
            "(`rosnet-tui sync`; `rosnet-tui sync install-service --user` keeps it running).",
            ]
    for p in peers or ["each peer"]:
        acts.append(f"Until sync runs, on {p}: change the hosts line for {ev.me} from "
                    f"`{prev} {ev.me}` to `{now} {ev.me}` (`rosnet-tui hosts apply` there after "
                    "updating its settings).")
    if d.get("matches_settings") is False:
        acts.append(f"Set public_ip = \"{now}\" under [this] in the settings of {ev.me}.")
    acts.append("For a lasting fix ask the provider for a fixed public IP, or give this "
                "component a dynamic DNS name.")
    n = len(d.get("history") or [])
    ev_lines = [f"isp.public_ip: was {prev}, now {now}"]
    if n:
        ev_lines.append(f"{n} different addresses seen so far")
    return [Hit(f"{ev.me}'s public IP changed from {prev} to {now} since the last run: this "
                "connection has no fixed address, and every peer that still uses "
                f"{prev} for {ev.me} can no longer reach it.", acts, evidence=ev_lines)]


@rule("isp.public_ip.differs", "isp", ("isp.public_ip",),
      "public IP differs from the settings",
      "The public address seen now is not the one in the settings, which is probably also the "
      "one the peers have in their hosts files.",
      "Update public_ip in the settings and the peers' hosts entries (or run `rosnet-tui sync`).",
      "isp", "warn", superseded_by=("isp.public_ip.changed",))
def _public_differs(ev: Evidence) -> list[Hit]:
    d = ev.data("isp.public_ip")
    if d.get("matches_settings") is not False or not d.get("public_ip"):
        return []
    now, old = d["public_ip"], d.get("settings_ip") or ev.s.this.public_ip or "?"
    acts = [f"Set public_ip = \"{now}\" under [this] in the settings of {ev.me}."]
    for p in [p.name for p in ev.s.peers] or ["each peer"]:
        acts.append(f"On {p}: the hosts line for {ev.me} must read `{now} {ev.me}`, not "
                    f"`{old} {ev.me}`.")
    acts.append("Address sync does both for you whenever the address moves: `rosnet-tui sync`.")
    return [Hit(f"{ev.me}'s public IP is {now}, but the settings say {old}: peers configured "
                f"from the settings look for {ev.me} at an address that is no longer its own.",
                acts, evidence=[f"isp.public_ip: seen {now}, settings {old}"])]


def _cgnat_text(ev: Evidence) -> tuple[str, list[str], list[str]]:
    d = ev.data("isp.cgnat")
    wan, hop = d.get("wan_ip"), d.get("hop")
    pub = ev.data("isp.public_ip").get("public_ip") or "the public address"
    if d.get("cgnat"):
        seen = (f"the modem's WAN address is {wan}" if wan else
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


# ---- step 2: Router/modem: Table 1 ----------------------------------------------------------
T1 = "table1.listener_up_closed"


def _t1(ev: Evidence) -> tuple[dict, dict] | None:
    """(listener data, port_open data) when both checks have a verdict."""
    ld, pd = ev.data("router.listener"), ev.data("router.port_open")
    if "listening" not in ld or "test_port_open" not in pd:
        return None
    return ld, pd


def _t1_port(ev: Evidence) -> int:
    pd, ld = ev.data("router.port_open"), ev.data("router.listener")
    return int(pd.get("test_port") or ld.get("port") or ev.s.probe.port)


def _t1_where(ev: Evidence) -> str:
    pd = ev.data("router.port_open")
    return f"{pd.get('public_ip') or ev.my_public_ip()}:{_t1_port(ev)}"


def _other_open_ports(ev: Evidence) -> list[int]:
    pd = ev.data("router.port_open")
    tp = _t1_port(ev)
    return [p["port"] for p in pd.get("ports") or []
            if isinstance(p, dict) and p.get("reachable") and p.get("port") != tp]


def _cgnat_passed(ev: Evidence) -> bool:
    d = ev.data("isp.cgnat")
    return (bool(d) and d.get("cgnat") is False and d.get("double_nat") is False
            and d.get("method") not in (None, "none"))


def _table1_ranking(ev: Evidence) -> dict[str, tuple[int, list[str]]]:
    """Rank Table 1's three causes by the evidence: {cause: (score, reasons)}, lower first.

    The procedure's order (port in use, ISP, modem forwarding) is the default; evidence moves a
    cause up (carrier NAT -> ISP; a changed local IP or other ports open -> forwarding; a
    process on the port -> port in use) or down (port free; the modem holds the public IP).
    """
    score = {"port_in_use": 10, "isp": 20, "forwarding": 30}
    why: dict[str, list[str]] = {k: [] for k in score}
    pf = ev.data("router.port_free")
    if pf.get("in_use"):
        score["port_in_use"] = 5
        why["port_in_use"].append(f"router.port_free: port {pf.get('port')} is held by "
                                  f"{pf.get('process') or 'another process'}")
    elif pf.get("in_use") is False:
        score["port_in_use"] = 40
        why["port_in_use"].append("router.port_free found the port free on this machine")
    cg = ev.data("isp.cgnat")
    if cg.get("cgnat"):
        score["isp"] = 1
        why["isp"].append("isp.cgnat: carrier-grade NAT")
    elif cg.get("double_nat"):
        score["isp"] = 3
        why["isp"].append("isp.cgnat: double NAT")
    elif _cgnat_passed(ev) and ev.s.this.connection != "corporate":
        score["isp"] = 35
        why["isp"].append("isp.cgnat: the modem holds the public address (no carrier NAT)")
    li = ev.data("router.local_ip")
    if li.get("differs"):
        score["forwarding"] = 2
        why["forwarding"].append(f"router.local_ip: local IP is {li.get('local_ip')}, "
                                 f"forwarded IP is {li.get('expected_ip')}")
    elif _other_open_ports(ev):
        score["forwarding"] = 4
        why["forwarding"].append("router.port_open: other ports are reachable, this one is not")
    return {k: (score[k], why[k]) for k in score}


def _t1_order(ev: Evidence, cause: str) -> int:
    ranking = _table1_ranking(ev)
    ranked = sorted(ranking, key=lambda k: (ranking[k][0], ("port_in_use", "isp",
                                                            "forwarding").index(k)))
    return ranked.index(cause)


def _listener_up_closed(ev: Evidence) -> bool:
    t = _t1(ev)
    return bool(t and t[0]["listening"] is True and t[1]["test_port_open"] is False)


_T1_CHECKS = ("router.listener", "router.port_open")


@rule("table1.open", "router", _T1_CHECKS,
      "listener up, checker says Open",
      "Port forwarding works: a connection from the internet reached the listener on this "
      "component.",
      "Go on to step 3 (Linux).",
      "linux", "info")
def _t1_open(ev: Evidence) -> list[Hit]:
    t = _t1(ev)
    if not t or t[0]["listening"] is not True or t[1]["test_port_open"] is not True:
        return []
    return [Hit(f"Port forwarding works: a connection from outside reached the listener on "
                f"{_t1_where(ev)}.", ["Go on to step 3 (Linux)."],
                evidence=["router.listener: listening", "router.port_open: Open"])]


@rule("table1.no_listener", "router", _T1_CHECKS,
      "listener down, checker says Closed",
      "Nothing listened on the test port, so Closed says nothing about the forwarding yet.",
      "Start the listener (`nc -l PORT`, or re-run the Router step, whose listener check starts "
      "one) and test the port again.",
      "router", "fail")
def _t1_no_listener(ev: Evidence) -> list[Hit]:
    t = _t1(ev)
    if not t or t[0]["listening"] is not False or t[1]["test_port_open"] is not False:
        return []
    port = _t1_port(ev)
    acts = [f"Start a listener on port {port} (`nc -l {port}`, or re-run the Router step: its "
            "listener check starts one for the test) and test the port again."]
    ids = list(_T1_CHECKS)
    pf = ev.data("router.port_free")
    if pf.get("in_use"):
        proc = pf.get("process") or "another program"
        pid = f" (pid {pf['pid']})" if pf.get("pid") else ""
        acts.insert(0, f"Port {port} is taken by {proc}{pid}, so our listener could not start: "
                       f"choose another test port between 1024 and {PORT_MAX} (port = N under "
                       f"[probe] in the settings), or stop {proc} if it should not run.")
        ids.append("router.port_free")
    return [Hit(f"Nothing was listening on port {port} when the checker tried {_t1_where(ev)}, "
                "so its Closed says nothing about the forwarding yet.", acts, check_ids=ids,
                evidence=["router.listener: not listening", "router.port_open: Closed"])]


@rule("table1.no_listener_open", "router", _T1_CHECKS,
      "listener down, checker says Open",
      "Our listener is not up, yet the port answered from outside: another program owns the "
      "port, and the forwarding works for it.",
      "Pick a free test port and test again; make sure the program on the port should be "
      "reachable from the internet.",
      "router", "warn")
def _t1_no_listener_open(ev: Evidence) -> list[Hit]:
    t = _t1(ev)
    if not t or t[0]["listening"] is not False or t[1]["test_port_open"] is not True:
        return []
    port = _t1_port(ev)
    proc = ev.data("router.port_free").get("process")
    owner = proc or "another program"
    return [Hit(f"Our listener is not up, yet {_t1_where(ev)} answered from outside: {owner} "
                f"owns port {port}, and the forwarding delivers to it.",
                [f"Choose a free test port (port = N under [probe], between 1024 and "
                 f"{PORT_MAX}) and re-run the Router step.",
                 f"Check that {proc or 'the program on that port'} is meant to be reachable "
                 "from the whole internet."],
                check_ids=[*_T1_CHECKS, "router.port_free"],
                evidence=["router.listener: not listening", "router.port_open: Open"])]


@rule(f"{T1}.port_in_use", "router", _T1_CHECKS,
      "listener up, checker says Closed - cause (a)",
      "Cause (a): the port may be used by another service (here or on the modem itself), so the "
      "test never reaches our listener.",
      f"Try another port between 1024 and {PORT_MAX} (port = N under [probe]); stop the program "
      "holding the port if it should not run.",
      "router", "fail", group=T1)
def _t1_cause_port(ev: Evidence) -> list[Hit]:
    if not _listener_up_closed(ev):
        return []
    port = _t1_port(ev)
    pf = ev.data("router.port_free")
    why = _table1_ranking(ev)["port_in_use"][1]
    ids = list(_T1_CHECKS)
    if pf.get("in_use"):
        proc = pf.get("process") or "another program"
        pid = f" (pid {pf['pid']})" if pf.get("pid") else ""
        meaning = (f"Port {port} is also held by {proc}{pid}, so the checker's connection may "
                   "not reach our listener.")
        acts = [f"Try another port between 1024 and {PORT_MAX}: set port = N under [probe] and "
                "re-run the Router step.",
                f"Or stop {proc}{pid} if it should not be running."]
        ids.append("router.port_free")
    else:
        meaning = (f"Port {port} may be used by another service, on this machine or on the "
                   "modem itself (its web page, VPN or remote-management port), so the test "
                   "does not reach our listener.")
        if pf.get("in_use") is False:
            meaning += " Least likely here: nothing else listens on it on this machine."
        acts = [f"Try another port between 1024 and {PORT_MAX}: set port = N under [probe] "
                "and re-run the Router step; try two or three ports."]
    return [Hit(meaning, acts, check_ids=ids, order=_t1_order(ev, "port_in_use"),
                evidence=["router.listener: listening", "router.port_open: Closed", *why])]


@rule(f"{T1}.isp", "router", _T1_CHECKS,
      "listener up, checker says Closed - cause (b)",
      "Cause (b): the provider or the network administrator blocks incoming connections before "
      "they reach the modem (carrier-grade NAT is the hard form of it).",
      "Back to the ISP step: ask the provider (networking department) or the administrator to "
      "allow port forwarding, and for a public IP.",
      "isp", "fail", group=T1)
def _t1_cause_isp(ev: Evidence) -> list[Hit]:
    if not _listener_up_closed(ev):
        return []
    cg = ev.data("isp.cgnat")
    why = _table1_ranking(ev)["isp"][1]
    ids = list(_T1_CHECKS)
    if cg.get("cgnat") or cg.get("double_nat"):
        meaning, acts, more = _cgnat_text(ev)
        why = why + more
        ids.append("isp.cgnat")
    else:
        c = ev.s.this.connection
        who = {"corporate": "the network administrator", "telecom": "the carrier",
               "home": "the provider"}.get(c, "the provider")
        meaning = (f"{who[0].upper() + who[1:]} may block incoming connections before they reach "
                   "the modem, whatever the modem is set to.")
        if _cgnat_passed(ev):
            meaning += " Less likely here: the modem holds the public address itself."
        if c == "corporate":
            acts = [f"Ask the network administrator to allow incoming TCP (and UDP) "
                    f"{FORWARD_RANGE} to {ev.my_local_ip()} on their firewall, or to set it as "
                    "the DMZ host; they usually configure the router as well."]
        elif c == "telecom":
            acts = ["Call the carrier and ask for the networking department (first-line support "
                    "rarely knows port forwarding): is forwarding allowed on this plan and "
                    "modem, and is the public IP really yours?"]
        else:
            acts = ["Ask the provider whether incoming connections are blocked on this line, "
                    "and how to lift it (some need a setting in the customer portal)."]
        acts.append("Back to step 1 (ISP) once they answer.")
    return [Hit(meaning, acts, check_ids=ids, order=_t1_order(ev, "isp"),
                evidence=["router.listener: listening", "router.port_open: Closed", *why])]


@rule(f"{T1}.forwarding", "router", _T1_CHECKS,
      "listener up, checker says Closed - cause (c)",
      "Cause (c): the modem's port forwarding is missing or points at the wrong local address.",
      f"Back to the Router step: forward TCP {FORWARD_RANGE} (or DMZ) to this component's local "
      "IP, and reserve that IP by DHCP.",
      "router", "fail", group=T1)
def _t1_cause_forwarding(ev: Evidence) -> list[Hit]:
    if not _listener_up_closed(ev):
        return []
    li = ev.data("router.local_ip")
    local = ev.my_local_ip()
    why = _table1_ranking(ev)["forwarding"][1]
    ids = list(_T1_CHECKS)
    if li.get("differs"):
        old = li.get("expected_ip") or "the old address"
        meaning = (f"The modem forwards to {old}, but {ev.me}'s local IP is now {local} "
                   f"(on {li.get('interface') or 'its interface'}): the forwarding points at the "
                   "old address, so connections from outside go nowhere.")
        acts = [f"In the modem's web page, change the forwarding (or DMZ host) from {old} to "
                f"{local}.",
                f"Reserve {local} for {ev.me} by DHCP (a reservation for its MAC address) so "
                "it does not move again.",
                f"Set local_ip = \"{local}\" under [this] in the settings, then re-run the "
                "Router step."]
        ids.append("router.local_ip")
    else:
        meaning = (f"The modem does not forward port {_t1_port(ev)} to {ev.me} ({local}): the "
                   "forwarding is missing, covers other ports, or points at another address.")
        others = _other_open_ports(ev)
        if others:
            meaning += (f" Ports {_and(map(str, others))} do get through, so the path to the "
                        "modem works: the forwarding rule itself is incomplete.")
        acts = [f"In the modem's web page (firewall / NAT / port forwarding), forward TCP (and "
                f"UDP if needed) {FORWARD_RANGE} to {local}, or set the DMZ host to {local}.",
                f"Reserve {local} for {ev.me} by DHCP so the forwarding keeps pointing at it.",
                "Save, restart the modem if it asks, and re-run the Router step."]
    return [Hit(meaning, acts, check_ids=ids, order=_t1_order(ev, "forwarding"),
                evidence=["router.listener: listening", "router.port_open: Closed", *why])]


# ---- step 1 (continued): carrier NAT on its own ------------------------------------------
@rule("isp.cgnat", "isp", ("isp.cgnat",),
      "carrier-grade or double NAT on the way out",
      "The modem does not hold the public address: a NAT of the carrier (or a second router) "
      "sits in front of it, and forwarding on the modem cannot work.",
      "Ask the carrier for a public IP, or use another connection; with your own second router, "
      "forward on both or use bridge mode.",
      "isp", "warn", superseded_by=(f"{T1}.isp",))
def _cgnat(ev: Evidence) -> list[Hit]:
    d = ev.data("isp.cgnat")
    if not (d.get("cgnat") or d.get("double_nat")):
        return []
    meaning, acts, evid = _cgnat_text(ev)
    return [Hit(meaning, acts, severity=ev.sev("isp.cgnat", "warn"), evidence=evid)]


# ---- step 2 (continued) ----------------------------------------------------------------------
@rule("router.local_ip.differs", "router", ("router.local_ip",),
      "local IP differs from the forwarded one",
      "The DHCP server gave this component a new local address; forwarding or DMZ set for the "
      "old one now goes nowhere.",
      "Point the forwarding at the new local IP, reserve it by DHCP, update local_ip in the "
      "settings.",
      "router", "warn", superseded_by=(f"{T1}.forwarding",))
def _local_differs(ev: Evidence) -> list[Hit]:
    d = ev.data("router.local_ip")
    if not d.get("differs"):
        return []
    now, old = d.get("local_ip") or "?", d.get("expected_ip") or "?"
    return [Hit(f"{ev.me}'s local IP is now {now} (on {d.get('interface') or '?'}, gateway "
                f"{d.get('gateway') or '?'}), not {old} as in the settings: a forwarding or DMZ "
                f"entry for {old} no longer reaches it.",
                [f"In the modem's web page, change the forwarding (or DMZ host) from {old} to "
                 f"{now}.",
                 f"Reserve {now} for {ev.me} by DHCP (a reservation for its MAC address).",
                 f"Set local_ip = \"{now}\" under [this] in the settings and apply the hosts "
                 "entries again (`rosnet-tui hosts apply`): its own name must map to "
                 f"{now}."],
                severity=ev.sev("router.local_ip", "warn"),
                evidence=[f"router.local_ip: {now}, settings {old}"])]


@rule("router.port_in_use", "router", ("router.port_free",),
      "test port used by another program",
      "Another program holds the test port, so our listener cannot use it.",
      "Choose another test port (port under [probe]) or stop that program.",
      "router", "warn", superseded_by=(f"{T1}.port_in_use", "table1.no_listener",
                                       "table1.no_listener_open"))
def _port_in_use(ev: Evidence) -> list[Hit]:
    d = ev.data("router.port_free")
    if not d.get("in_use"):
        return []
    port, proc = d.get("port") or ev.s.probe.port, d.get("process") or "another program"
    pid = f" (pid {d['pid']})" if d.get("pid") else ""
    return [Hit(f"Port {port} is in use by {proc}{pid}, so the test listener cannot use it.",
                [f"Choose another test port between 1024 and {PORT_MAX}: port = N under [probe] "
                 "in the settings.",
                 f"Or stop {proc}{pid} if it should not run."],
                severity=ev.sev("router.port_free", "warn"),
                evidence=[f"router.port_free: {port} held by {proc}{pid}"])]


@rule("router.port_open.partial", "router", ("router.port_open",),
      "test port Open, other listened ports Closed",
      "The forwarding covers only part of what ROS needs: some ports with a listener get "
      "through, others do not.",
      f"Forward the whole range {FORWARD_RANGE} (plus 22 for SSH), or use DMZ.",
      "router", "fail")
def _port_partial(ev: Evidence) -> list[Hit]:
    d = ev.data("router.port_open")
    if d.get("test_port_open") is not True:
        return []
    closed = [p["port"] for p in d.get("ports") or []
              if isinstance(p, dict) and p.get("listener") and p.get("reachable") is False]
    if not closed:
        return []
    local = ev.my_local_ip()
    acts = []
    if 22 in closed:
        acts.append(f"SSH (22) is outside {FORWARD_RANGE}: forward TCP 22 to {local} as well "
                    "(or set the DMZ host).")
    if any(p != 22 for p in closed):
        acts.append(f"Forward the whole range TCP {FORWARD_RANGE} to {local}: ROS picks random "
                    "ports for its nodes, so a partial range breaks some topics and not others.")
    return [Hit(f"Port {d.get('test_port')} is Open, but {_and(map(str, closed))} "
                f"{'is' if len(closed) == 1 else 'are'} Closed although something listens "
                "there: the forwarding covers only part of what is needed.", acts,
                severity=ev.sev("router.port_open", "warn"),
                evidence=[f"router.port_open: closed with a listener: {_and(map(str, closed))}"])]


@rule("router.port_open.no_verdict", "router", ("router.port_open",),
      "the port checker gave no verdict",
      "The outside test could not be made (port checker unreachable or refusing), so Table 1 "
      "cannot be read.",
      "Fix the internet connection, check port_check_url, or give a peer an ssh_user so it "
      "tests from its side.",
      "router", "warn", superseded_by=("isp.no_internet.dns", "isp.no_internet.http"))
def _port_no_verdict(ev: Evidence) -> list[Hit]:
    d = ev.data("router.port_open")
    if not d or "test_port_open" not in d or d.get("test_port_open") is not None:
        return []
    return [Hit("No outside test of the port was possible: neither the port checker "
                f"({ev.s.probe.port_check_url}) nor a peer gave a verdict.",
                ["Check that the internet works (ISP step).",
                 "Check port_check_url under [probe]: it must speak the echoip protocol "
                 "(GET /port/N); `rosnet-tui probe-server` runs one you can host.",
                 "Or set ssh_user for a peer: the port is then tested from the peer itself."],
                severity=ev.sev("router.port_open", "warn"),
                evidence=["router.port_open: no verdict"])]


# ---- step 3: Linux -------------------------------------------------------------------------
def _name_role(ev: Evidence, name: str) -> str:
    if name == ev.s.this.name:
        return "its own local IP"
    if ev.remote:
        return f"{name}'s public IP"
    return f"{name}'s address on the {ev.s.this.profile} LAN"


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
        hits.append(Hit(
            f"{name} resolves to the loopback address {found} on {ev.me}, not to "
            f"{exp} ({_name_role(ev, name)}): programs here that look the name up talk to "
            "themselves, and ROS nodes can bind or advertise an address no peer reaches.",
            [f"In /etc/hosts on {ev.me}, take {name} off the `{found} ...` line (delete the line "
             f"if {name} is all it holds; keep `127.0.0.1 localhost`).",
             f"Make sure the line `{exp} {name}` is there (`rosnet-tui hosts apply` writes "
             "the right entries).",
             f"Check with `getent hosts {name}`: it must print {exp}."],
            check_ids=ids, severity="fail" if any(ev.is_fail(c) for c in ids) else "warn",
            evidence=[f"{name} -> {found}"]))
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
    hosts_wrong = {w["name"]: w for w in hd.get("wrong") or [] if isinstance(w, dict)}
    names = [n for n in dict.fromkeys([*(rd.get("wrong") or []), *hosts_wrong]) if n not in loop]
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
        if name in hosts_wrong:
            old = hw.get("found") or found or "?"
            acts = [f"In /etc/hosts on {ev.me}, change `{old} {name}` to `{exp} {name}` "
                    "(`rosnet-tui hosts apply` writes the computed entries, with a preview)."]
        elif found:
            acts = [f"The hosts file of {ev.me} looks right, yet the system resolver answers "
                    f"{found}: run `getent hosts {name}`, check that /etc/nsswitch.conf lists "
                    "`files` before `dns` for hosts, and look for a DNS record or a second "
                    f"hosts line for {name}."]
        else:
            acts = [f"{name} does not resolve on {ev.me}: add `{exp} {name}` to /etc/hosts "
                    "(`rosnet-tui hosts apply`)."]
        if name != ev.s.this.name and ev.remote:
            acts.append(f"If {exp} is itself out of date, {name}'s public IP has moved: update "
                        f"the settings (or let address sync do it: `rosnet-tui sync`).")
        acts.append(f"Check with `getent hosts {name}`: it must print {exp}.")
        if found:
            meaning = (f"{name} resolves to {found} on {ev.me}, but it should be {exp} "
                       f"({_name_role(ev, name)}): everything that uses the name goes to the "
                       "wrong place.")
        else:
            meaning = (f"{name} does not resolve on {ev.me}; it should be {exp} "
                       f"({_name_role(ev, name)}).")
        hits.append(Hit(meaning, acts, check_ids=ids,
                        severity="fail" if any(ev.is_fail(c) for c in ids) else "warn",
                        evidence=[f"{name} -> {found or 'nothing'}, expected {exp}"]))
    return hits


@rule("linux.hosts.missing", "linux", ("linux.hosts",),
      "a name is missing from the hosts file",
      "The hosts file has no line for a component, so its name depends on DNS (if it resolves "
      "at all).",
      "Add the missing line(s) (`rosnet-tui hosts apply`).",
      "linux", "warn")
def _hosts_missing(ev: Evidence) -> list[Hit]:
    hd, rd = ev.data("linux.hosts"), ev.data("linux.resolve")
    missing = [n for n in hd.get("missing") or []
               if n not in (rd.get("wrong") or []) and n not in (rd.get("loopback") or [])]
    if not missing:
        return []
    lines = [f"`{ev.expected_ip(n) or '?'} {n}`" for n in missing]
    return [Hit(f"/etc/hosts on {ev.me} has no line for {_and(missing)}.",
                [f"Add {_and(lines)} to /etc/hosts on {ev.me} (`rosnet-tui hosts apply` "
                 "writes them, with a preview and a backup)."],
                severity=ev.sev("linux.hosts", "warn"),
                evidence=[f"linux.hosts: missing {_and(missing)}"])]


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
    return [Hit(f"{_and(dupes)} appear{'s' if len(dupes) == 1 else ''} on several lines of "
                f"/etc/hosts on {ev.me} with different addresses: the resolver may pick any of "
                "them (glibc even prefers 127.0.1.1).",
                [f"Keep only {_and(keep)} and delete the other lines for "
                 f"{'that name' if len(dupes) == 1 else 'those names'}."],
                severity=ev.sev("linux.hosts", "warn"),
                evidence=[f"linux.hosts: duplicates {_and(dupes)}"])]


def _peer_state(ev: Evidence, name: str) -> dict[str, object]:
    ping = (ev.data("linux.ping").get("peers") or {}).get(name) or {}
    ssh = (ev.data("linux.ssh").get("peers") or {}).get(name) or {}
    co = (ev.data("linux.chat_out").get("peers") or {}).get(name) or {}
    ci = (ev.data("linux.chat_in").get("peers") or {}).get(name) or {}
    return {"icmp": ping.get("icmp"), "tcp22": ping.get("tcp22"), "ssh_ok": ssh.get("ok"),
            "ssh_failure": ssh.get("failure"), "fingerprint": ssh.get("fingerprint"),
            "out": _chat_ok(co), "in": _chat_ok(ci), "out_failure": co.get("failure"),
            "in_failure": ci.get("failure")}


def _chat_ok(d: dict) -> bool | None:
    """A chat's verdict, or None when the chat itself did not happen (no SSH to run the peer's
    side: failure "no_user" or "ssh:...")."""
    f = str(d.get("failure") or "")
    if f == "no_user" or f.startswith("ssh:"):
        return None
    return d.get("ok")


def _ssh_caused(ev: Evidence, name: str) -> list[str]:
    """The chat checks that failed for *name* only because SSH to it failed."""
    return [c for c in ("linux.chat_out", "linux.chat_in")
            if str(((ev.data(c).get("peers") or {}).get(name) or {}).get("failure")
                   or "").startswith("ssh:")]


def _linux_peers(ev: Evidence) -> list[str]:
    names: dict[str, None] = {}
    for cid in ("linux.ping", "linux.ssh", "linux.chat_out", "linux.chat_in"):
        for n in ev.data(cid).get("peers") or {}:
            names[n] = None
    return list(names)


def _unreachable(ev: Evidence, name: str) -> bool:
    st = _peer_state(ev, name)
    if st["ssh_ok"] is True or st["out"] is True:
        return False
    if st["ssh_failure"] == "network":
        return True
    return st["tcp22"] is False and st["ssh_failure"] in (None, "timeout", "no_user")


@rule("linux.ping.icmp_filtered", "linux", ("linux.ping",),
      "ping fails, TCP to the peer works",
      "ICMP is dropped on the way (many modems and carriers do), but TCP gets through: not a "
      "problem, ROS uses TCP.",
      "Nothing to fix; go on.",
      None, "info")
def _icmp_filtered(ev: Evidence) -> list[Hit]:
    hits = []
    for name, st in (ev.data("linux.ping").get("peers") or {}).items():
        if isinstance(st, dict) and st.get("icmp") is False and st.get("tcp22") is True:
            hits.append(Hit(
                f"{name} does not answer ping, but a TCP connection to its port 22 works: ICMP "
                "is filtered on the way (common with modems and mobile carriers). Not a "
                "problem: ROS, SSH and the chat test all use TCP.",
                ["Nothing to fix; go on with the SSH and chat checks."],
                evidence=[f"linux.ping {name}: icmp no, tcp/22 yes"]))
    return hits


@rule("linux.peer.unreachable", "linux", ("linux.ping", "linux.ssh"),
      "peer unreachable over TCP (ping may still answer)",
      "No TCP connection gets through to the peer's public address. If the address answers "
      "ping, its modem is online and does not forward to the peer (or the peer is off); if "
      "nothing answers, the address is probably wrong (stale hosts entry, changed IP, carrier "
      "NAT) or the modem is offline.",
      "Ping answers: fix the forwarding on the peer's modem. Nothing answers: check our hosts "
      "line for the peer and its current public IP, then that it is online.",
      "router", "fail")
def _peer_unreachable(ev: Evidence) -> list[Hit]:
    hits = []
    for name in _linux_peers(ev):
        if not _unreachable(ev, name):
            continue
        st = _peer_state(ev, name)
        ip = (ev.data("linux.resolve").get("names") or {}).get(name, {}).get("resolved") \
            or ev.expected_ip(name) or "?"
        ids = [c for c in ("linux.ping", "linux.ssh", "linux.chat_out", "linux.chat_in")
               if (ev.data(c).get("peers") or {}).get(name) is not None and ev.is_fail(c)]
        local = ev.peer_local(name) or "its local IP"
        pub = ev.peer_public(name) or "?"
        forward = (f"Check that {name}'s modem forwards TCP 22 and {FORWARD_RANGE} to {local} "
                   f"(the Router step on {name}: its port test must say Open).")
        online = (f"Check that {name} is switched on, online and running sshd (the ISP step on "
                  f"{name}).")
        hosts = (f"Check our hosts line for {name}: `getent hosts {name}` must print its current "
                 f"public IP ({pub} in the settings; the ISP step on {name} shows the address it "
                 f"has now). If it moved, `rosnet-tui sync` keeps it current.")
        if not ev.remote:
            exp = ev.expected_ip(name) or "?"
            meaning = (f"{name} ({ip}) does not accept TCP connections from {ev.me} on the "
                       f"{ev.s.this.profile} LAN (port 22 and SSH fail).")
            acts = [f"Check that {name} is on the same LAN as {ev.me}, switched on and running "
                    "sshd.",
                    f"Check our hosts line: `getent hosts {name}` must print {exp} (its address "
                    f"on the {ev.s.this.profile} LAN)."]
        elif st["icmp"] is True:
            meaning = (f"{ip} answers ping, so {name}'s modem is online, but no TCP connection "
                       f"gets through to {name} (port 22 and SSH fail): the modem does not "
                       f"forward to {name}, or {name} itself is off.")
            acts = [forward, online]
        else:
            meaning = (f"Nothing answers at {ip}, the address {ev.me} uses for {name}: neither "
                       "ping nor a TCP connection to port 22. The address may be out of date "
                       f"(a new public IP, or {name} behind carrier-grade NAT - its isp.cgnat "
                       "check tells), or the modem is offline.")
            acts = [hosts, online, forward]
            if ip != pub and pub != "?":
                meaning += f" The settings say {name} is at {pub}."
        nd = ev.data("ros.node_uris")
        if st["ssh_failure"] == "network" and ev.status("ros.node_uris") is Status.WARN \
                and nd and not nd.get("unreachable"):
            ids.append("ros.node_uris")      # could not check from the peer: same cause
        hits.append(Hit(meaning, acts, check_ids=ids or ["linux.ping", "linux.ssh"],
                        goto_step="router",
                        evidence=[f"{name} ({ip}): icmp={st['icmp']}, tcp22={st['tcp22']}, "
                                  f"ssh={st['ssh_failure'] or st['ssh_ok']}"]))
    return hits


@rule("linux.ssh.host_key_changed", "linux", ("linux.ssh",),
      "SSH host key changed",
      "The peer shows a different host key than the one recorded: a reinstall or new keys, or "
      "someone in the middle. We refuse to connect.",
      "Verify the new fingerprint out of band; only then `ssh-keygen -R NAME` and accept it.",
      "linux", "fail")
def _ssh_key_changed(ev: Evidence) -> list[Hit]:
    hits = []
    for name, st in (ev.data("linux.ssh").get("peers") or {}).items():
        if not isinstance(st, dict) or st.get("failure") != "host_key_changed":
            continue
        fp = st.get("fingerprint") or "(see the evidence)"
        user = ev.ssh_user(name)
        hits.append(Hit(
            f"{name} presented a host key ({fp}) that differs from the one in "
            f"~/.ssh/known_hosts: either {name} was reinstalled or its keys regenerated, or "
            "someone is intercepting the connection. We refuse to connect until you verify.",
            [f"Verify out of band (at {name}'s console, or by someone you trust there): "
             f"`ssh-keygen -lf /etc/ssh/ssh_host_ed25519_key.pub` on {name} must print {fp}.",
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
        if not isinstance(st, dict) or st.get("failure") != "host_key_unknown":
            continue
        fp = st.get("fingerprint") or "(see the evidence)"
        hits.append(Hit(
            f"{name}'s host key ({fp}) is not in ~/.ssh/known_hosts yet; it is never accepted "
            "silently.",
            [f"On {name} (console or a trusted channel) run "
             f"`ssh-keygen -lf /etc/ssh/ssh_host_ed25519_key.pub` and compare with {fp}.",
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
        if not isinstance(st, dict) or st.get("failure") != "auth":
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
        if not isinstance(st, dict) or st.get("failure") != "sshd":
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
      "linux", "fail", superseded_by=("linux.name.wrong", "linux.hosts.missing"))
def _ssh_resolve(ev: Evidence) -> list[Hit]:
    hits = []
    for name, st in (ev.data("linux.ssh").get("peers") or {}).items():
        if isinstance(st, dict) and st.get("failure") == "resolve":
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
        if isinstance(st, dict) and st.get("failure") == "no_user":
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
    for name in _linux_peers(ev):
        st = _peer_state(ev, name)
        if not (st["out"] is True and st["in"] is False) or _unreachable(ev, name):
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
            meaning = (f"{me} reached {name}'s listener, but {name} could not connect back to "
                       f"{me}: connections into {me} are blocked (our modem's forwarding, or a "
                       f"firewall here), or {name} uses an old address for {me}.")
            acts = fix_fw + fix_name
        hits.append(Hit(meaning, acts, check_ids=_chat_ids(ev, name),
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
    for name in _linux_peers(ev):
        st = _peer_state(ev, name)
        if not (st["in"] is True and st["out"] is False) or _unreachable(ev, name):
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
            meaning = (f"{name} reached {me}, but {me} could not connect to {name}'s listener: "
                       f"connections into {name} are blocked ({name}'s modem forwarding, or its "
                       "firewall), or our hosts line sends us to an old address.")
            acts = [f"On {name}'s modem: forward TCP {FORWARD_RANGE} to {local} (Router step on "
                    f"{name}).",
                    f"On {name}: check its firewall (`sudo ufw status`).",
                    f"Here: `getent hosts {name}` must print {exp}."]
        hits.append(Hit(meaning, acts, check_ids=_chat_ids(ev, name),
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
    for name in _linux_peers(ev):
        st = _peer_state(ev, name)
        if st["in"] is False and st["out"] is False and not _unreachable(ev, name):
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


# ---- step 4: ROS ---------------------------------------------------------------------------
def _ros_trouble(ev: Evidence) -> bool:
    return any(ev.is_fail(c) for c in ("ros.node_uris", "ros.pubsub_out", "ros.pubsub_in"))


@rule("ros.env.master_uri", "ros", ("ros.env",),
      "ROS_MASTER_URI wrong for the role",
      "Nodes started here look for the master at the wrong place (a member must use the "
      "master's name; the master its own name or local IP - roscore refuses its public IP).",
      "Set `export ROS_MASTER_URI=http://MASTER:11311` in ~/.bashrc (`rosnet-tui ros apply`), "
      "open a new shell, restart the nodes.",
      "ros", "fail")
def _master_uri(ev: Evidence) -> list[Hit]:
    d = ev.data("ros.env")
    if not d or d.get("uri_ok") is not False:
        return []
    exp = d.get("expected_uri") or f"http://{ev.s.master_name or 'MASTER'}:{ev.s.ros.port}"
    env_uri, rc_uri = d.get("env_uri"), d.get("bashrc_uri")
    shown = env_uri or rc_uri
    if ev.s.is_master:
        why = (f"{ev.me} is the master: its ROS_MASTER_URI must use its own name or local IP "
               f"({exp}); roscore will not start on its public IP.")
    else:
        why = (f"{ev.me} is a member: its ROS_MASTER_URI must use the master's name ({exp}), "
               "which its hosts file maps to the master's public IP.")
    if not shown:
        meaning = f"ROS_MASTER_URI is not set on {ev.me}. {why}"
    elif env_uri and rc_uri and env_uri != rc_uri and rc_uri == exp:
        meaning = (f"~/.bashrc has the right ROS_MASTER_URI ({exp}), but this shell still has "
                   f"{env_uri}: it was opened before the change.")
    else:
        meaning = f"ROS_MASTER_URI is {shown} on {ev.me}. {why}"
    acts = [f"In ~/.bashrc on {ev.me}: `export ROS_MASTER_URI={exp}`, replacing any other "
            "ROS_MASTER_URI line (`rosnet-tui ros apply` writes it, with a preview).",
            f"In open terminals: `export ROS_MASTER_URI={exp}` (or open a new one), then "
            "restart the nodes started with the old value."]
    return [Hit(meaning, acts, severity=ev.sev("ros.env", "fail"),
                evidence=[f"ros.env: env {env_uri}, ~/.bashrc {rc_uri}, expected {exp}"])]


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
    evid = [f"ros.master: {uri} did not answer"]
    if ev.s.is_master:
        return [Hit(f"No ROS master answers at {uri}: roscore is not running on {ev.me} (this "
                    "component is the master).",
                    [f"Start it on {ev.me}: `roscore` (in its own terminal, or as a service).",
                     "If roscore runs, ROS_MASTER_URI here does not point at it (see ros.env)."],
                    check_ids=ids, evidence=evid)]
    local = ev.peer_local(master) or "its local IP"
    pub = ev.expected_ip(master) or ev.peer_public(master) or "?"
    acts = [f"Is roscore running on {master}? Start `roscore` there; `rostopic list` on "
            f"{master} itself must work.",
            f"Is TCP {port} forwarded on {master}'s modem to {local}? (The Router step on "
            f"{master} tests {port} from outside when roscore listens.)",
            f"Does {host or master} lead to the master here? `getent hosts "
            f"{host or master}` must print {pub}."]
    meaning = f"The master {master} does not answer at {uri} from {ev.me}."
    if master in _linux_peers(ev) and _unreachable(ev, master):
        meaning += (f" {master} itself cannot be reached from here (see the Linux step), so "
                    "fix that first: the master follows.")
        acts = acts[2:] + acts[:2]
    return [Hit(meaning, acts, check_ids=ids, evidence=evid)]


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
    return [Hit(f"The master answers on {me} itself, but {peer}'s nodes cannot register with it: "
                f"connections from outside do not reach {me}'s port {port}.",
                [f"On {me}'s modem: forward TCP {FORWARD_RANGE} (11311 included) to "
                 f"{ev.my_local_ip()} (the Router step here: its port test must say Open).",
                 f"On {me}: the firewall must let TCP {port} in (`sudo ufw status`).",
                 f"On {peer}: `getent hosts {me}` must print {pub}, and ROS_MASTER_URI must be "
                 f"http://{me}:{port}."],
                check_ids=[*failed, *_node_list_failed(ev)],
                evidence=[f"{c}: {peer} failed at registration" for c in failed])]


def _uri_problems(ev: Evidence) -> list[dict]:
    """Unreachable advertised URIs, from ros.node_uris and from the pub/sub hops that failed."""
    out: list[dict] = []
    for u in ev.data("ros.node_uris").get("unreachable") or []:
        if isinstance(u, dict) and u.get("uri"):
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
    return _and(dict.fromkeys(u["node"] for u in us))


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
    names = _and([ev.s.this.name, *[p.name for p in ev.s.peers]])
    for (_, _, host), us in _group_uris(ev, ("unknown",)).items():
        if _is_ip(host):
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
            f"but {_and(dict.fromkeys(u['seat'] for u in us))} cannot connect to it "
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


_MASTER_RULES = {"ros.master.unreachable", "ros.master.peer_cannot_register"}


@rule("ros.pubsub.out_fails", "ros", ("ros.pubsub_out", "ros.pubsub_in"),
      "pub/sub works in, fails out",
      "Messages from the peer reach us, but ours do not reach the peer: one of the two nodes "
      "advertises an address the other side cannot reach (usually ours).",
      "Follow the failed hop: unset ROS_IP/ROS_HOSTNAME where set, forward the range on the "
      "side whose node is unreachable.",
      "ros", "fail")
def _pubsub_out(ev: Evidence) -> list[Hit]:
    o, i = ev.data("ros.pubsub_out"), ev.data("ros.pubsub_in")
    if o.get("failed_hop") == "registration" and ev.fired & _MASTER_RULES:
        return []
    if o.get("ok") is not False or i.get("ok") is not True:
        return []
    peer = _pubsub_peer(ev)
    hop = _HOP_WORDS.get(o.get("failed_hop") or "", "an unknown hop")
    return [Hit(f"Messages published on {peer} reach {ev.me}, but messages published on {ev.me} "
                f"do not reach {peer}; the failing hop is {hop}"
                + (f" ({o.get('node')} at {o.get('uri')})." if o.get("uri") else "."),
                _hop_actions(ev, "ros.pubsub_out", ev.me, peer),
                check_ids=["ros.pubsub_out", "ros.pubsub_in"],
                evidence=[f"ros.pubsub_out: failed at {o.get('failed_hop')}",
                          "ros.pubsub_in: ok"])]


@rule("ros.pubsub.in_fails", "ros", ("ros.pubsub_out", "ros.pubsub_in"),
      "pub/sub works out, fails in",
      "Our messages reach the peer, but the peer's do not reach us: one of the two nodes "
      "advertises an address the other side cannot reach (usually the peer's).",
      "Follow the failed hop: unset ROS_IP/ROS_HOSTNAME where set, forward the range on the "
      "side whose node is unreachable.",
      "ros", "fail")
def _pubsub_in(ev: Evidence) -> list[Hit]:
    o, i = ev.data("ros.pubsub_out"), ev.data("ros.pubsub_in")
    if i.get("failed_hop") == "registration" and ev.fired & _MASTER_RULES:
        return []
    if i.get("ok") is not False or o.get("ok") is not True:
        return []
    peer = _pubsub_peer(ev)
    hop = _HOP_WORDS.get(i.get("failed_hop") or "", "an unknown hop")
    return [Hit(f"Messages published on {ev.me} reach {peer}, but messages published on {peer} "
                f"do not reach {ev.me}; the failing hop is {hop}"
                + (f" ({i.get('node')} at {i.get('uri')})." if i.get("uri") else "."),
                _hop_actions(ev, "ros.pubsub_in", peer, ev.me),
                check_ids=["ros.pubsub_out", "ros.pubsub_in"],
                evidence=["ros.pubsub_out: ok",
                          f"ros.pubsub_in: failed at {i.get('failed_hop')}"])]


@rule("ros.pubsub.both_fail", "ros", ("ros.pubsub_out", "ros.pubsub_in"),
      "pub/sub fails both ways",
      "No message gets through in either direction while the master answers: node ports are "
      "blocked on both sides, or both sides advertise unreachable addresses.",
      "Check ROS_IP/ROS_HOSTNAME on both sides and the forwarded range on both modems.",
      "ros", "fail", superseded_by=("ros.master.unreachable", "ros.master.peer_cannot_register"))
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


# ---- security ------------------------------------------------------------------------------
@rule("security.exposed", "router", ("router.port_open",),
      "ports reachable from the internet (forwarding or DMZ in use)",
      "Forwarding exposes this component to the whole internet: SSH to password guessing, and "
      "the ROS master to anyone - ROS 1 has no authentication at all.",
      "SSH keys only (`PasswordAuthentication no`), restrict source addresses on the modem to "
      "the peers, forward only while needed.",
      "router", "security")
def _exposed(ev: Evidence) -> list[Hit]:
    d = ev.data("router.port_open")
    reach = [p["port"] for p in d.get("ports") or [] if isinstance(p, dict) and p.get("reachable")]
    if d.get("test_port_open") is True and d.get("test_port") and d["test_port"] not in reach:
        reach.append(d["test_port"])
    if not reach:
        return []
    me = ev.me
    parts = [f"Ports of {me} are reachable from the whole internet ({_and(map(str, reach))}), "
             "not only from the peers."]
    acts = []
    if 22 in reach:
        parts.append("SSH (22) is open to everyone: password-guessing bots find it within hours.")
    else:
        parts.append("With the whole range (or DMZ) forwarded, SSH and every other service here "
                     "are as exposed as the test port.")
    if ev.s.ros.port in reach or ev.s.is_master:
        parts.append(f"The ROS master ({ev.s.ros.port}) is reachable too (or will be once it "
                     "runs): ROS 1 has no authentication, so anyone who reaches it can list, "
                     "publish to and command the robot.")
    acts.append(f"On {me}: accept SSH keys only - in /etc/ssh/sshd_config set "
                "`PasswordAuthentication no` and `KbdInteractiveAuthentication no`, then "
                "`sudo systemctl reload ssh` (install your keys first: `ssh-copy-id`).")
    peers = [f"{p.name} {p.public_ip}" for p in ev.s.peers if p.public_ip]
    acts.append("Where the modem allows it, restrict the forwarding to the peers' public "
                f"addresses{' (' + _and(peers) + ')' if peers else ''}.")
    acts.append("Forward only while the robot is in use, and switch DMZ/forward-all off "
                "afterwards; for the ROS master, restricting who can connect (or a VPN) is the "
                "only protection there is.")
    return [Hit(" ".join(parts), acts,
                evidence=[f"router.port_open: reachable from outside: {_and(map(str, reach))}"])]


# ---- catch-alls (evaluated after the others) ------------------------------------------------
CATCH_ALL_IDS = ("check.no_verdict", "check.unexplained")
_CATCH_ALL = [
    Rule("check.no_verdict", "-", (), "a check ran out of time or crashed",
         "The check gave no verdict (it timed out or stopped on an error), so no rule can read it.",
         "Re-run the step; on a slow link raise timeout_s under [checks].", None, "fail",
         lambda ev: []),
    Rule("check.unexplained", "-", (), "a check failed or warned and no rule explains it",
         "No rule recognises this case; the check's own summary and evidence say what was seen.",
         "Read the check's evidence and re-run its step.", None, "fail", lambda ev: []),
]


def _catch_all(ev: Evidence, explained: set[str]) -> list[Finding]:
    out: list[Finding] = []
    for cid, r in ev.results.items():
        st = _status(r)
        if st not in (Status.FAIL, Status.WARN) or cid in explained:
            continue
        sev = "fail" if st is Status.FAIL else "warn"
        step = r.step if r.step in STEP_ORDER else None
        if not r.data and ("timed out" in r.summary or "unexpectedly" in r.summary):
            rl = _CATCH_ALL[0]
            meaning = f"{cid} did not finish: {r.summary}."
            acts = [f"Re-run {step_title(step)}." if step else "Re-run the check.",
                    f"On a slow or lossy link, raise timeout_s under [checks] (now "
                    f"{r.timeout_s:g} s for this check)."]
        else:
            rl = _CATCH_ALL[1]
            meaning = f"{cid}: {r.summary}"
            acts = [f"Read the evidence of {cid}; fix what it shows, then re-run "
                    f"{step_title(step)}." if step else f"Read the evidence of {cid}."]
        out.append(Finding(rl.id, meaning, acts, step, [cid], sev, 0, rl.condition,
                           list(r.evidence[:3])))
    return out


# --------------------------------------------------------------------------- advise
_SEV_RANK = {s: i for i, s in enumerate(SEVERITIES)}


def _sort_key(f: Finding, pos: dict[str, int], steps: dict[str, str]) -> tuple:
    step = steps.get(f.rule) or f.goto_step or ""
    return (_SEV_RANK.get(f.severity, 9),
            STEP_ORDER.index(step) if step in STEP_ORDER else len(STEP_ORDER),
            pos.get(f.rule, len(pos)), f.order)


def advise(results: Mapping[str, CheckResult] | Iterable[CheckResult], settings: Settings,
           *, strict: bool = False) -> list[Finding]:
    """All findings that apply to *results*, most important first.

    Order: failures, then warnings, security findings, information; within each, the
    procedure's step order (ISP before Router before Linux before ROS), the rule list's order,
    and for competing causes (Table 1) the order the evidence gives. A rule that trips over
    malformed data is skipped (``strict=True`` raises instead, for tests).
    """
    if not isinstance(results, Mapping):
        results = {r.id: r for r in results}
    ev = Evidence(results, settings)
    by_rule: dict[str, list[Finding]] = {}
    for rl in RULES:
        try:
            hits = rl.evaluate(ev) or []
        except Exception:
            if strict:
                raise
            continue
        if hits:
            ev.fired.add(rl.id)
            by_rule[rl.id] = [
                Finding(rl.id, h.meaning, list(h.actions),
                        rl.goto_step if h.goto_step == "-" else h.goto_step,
                        list(h.check_ids if h.check_ids is not None else rl.check_ids),
                        h.severity or rl.severity, h.order, rl.condition, list(h.evidence))
                for h in hits]
    findings: list[Finding] = []
    for rl in RULES:
        if rl.id in by_rule and not any(s in by_rule for s in rl.superseded_by):
            findings.extend(by_rule[rl.id])
    explained = {c for f in findings for c in f.check_ids}
    findings.extend(_catch_all(ev, explained))
    pos: dict[str, int] = {}
    first_of: dict[str, int] = {}
    for i, rl in enumerate(RULES):
        pos[rl.id] = first_of.setdefault(rl.group or rl.id, i)
    steps = {rl.id: rl.step for rl in RULES}
    findings.sort(key=lambda f: _sort_key(f, pos, steps))
    return findings


def advice_by_check(findings: Iterable[Finding]) -> dict[str, list[Finding]]:
    """The findings each check id should carry (``check --json``'s "advice")."""
    out: dict[str, list[Finding]] = {}
    for f in findings:
        for cid in f.check_ids:
            out.setdefault(cid, []).append(f)
    return out


def first_failure(findings: Iterable[Finding]) -> Finding | None:
    return next((f for f in findings if f.severity == "fail"), None)


def all_rules() -> list[Rule]:
    """Every rule, in procedure order, catch-alls last (the TUI's full-table view)."""
    return [*RULES, *_CATCH_ALL]


def rule_by_id(rule_id: str) -> Rule | None:
    return next((r for r in all_rules() if r.id == rule_id), None)


# --------------------------------------------------------------------------- docs
def _cell(text: str | None) -> str:
    return (text or "-").replace("|", "\\|").replace("\n", " ")


def render_rules_markdown() -> str:
    """docs/TROUBLESHOOTING.md, generated from :data:`RULES` (regenerate, never edit by hand)."""
    lines = [
        "# Troubleshooting reference",
        "",
        "<!-- Generated by `python -m rosnet_tui.core.advisor --markdown > "
        "docs/TROUBLESHOOTING.md`; do not edit by hand. -->",
        "",
        "Every rule the advisor applies to the check results, in the order of the procedure. "
        "`rosnet-tui check` attaches the rules that match to the checks they explain, the "
        "wizard's Advisor pane highlights them, and `rosnet-tui report` writes them out with "
        "this network's names, addresses and ports filled in. The tables below give the "
        "general form.",
        "",
        "Severity: **fail** = a cause of a failed check; **warn** = will bite later or needs a "
        "look; **security** = shown whenever it applies, even when everything works; "
        "**info** = no action needed. Findings are listed failures first, in step order.",
        "",
        "## Table 1: the port test (step 2)",
        "",
        "`router.listener` (our listener on the test port) and `router.port_open` (the "
        "checker's verdict from outside), read together:",
        "",
        "| Listener | Checker says | Rule | Meaning | Action | Back to |",
        "|---|---|---|---|---|---|",
    ]
    t1 = [r for r in RULES if r.id.startswith("table1.")]
    for r in t1:
        lis = "up" if "listener up" in r.condition else "down"
        chk = "Open" if "Open" in r.condition else "Closed"
        lines.append(f"| {lis} | {chk} | `{r.id}` | {_cell(r.meaning)} | {_cell(r.action)} | "
                     f"{_cell(step_title(r.goto_step))} |")
    lines += [
        "",
        "When the listener is up and the checker says Closed, the three causes are listed in "
        "the procedure's order - (a) port in use, (b) ISP or administrator, (c) modem "
        "forwarding - unless the evidence says otherwise: carrier-grade or double NAT "
        "(`isp.cgnat`) puts the ISP first, a local IP that differs from the forwarded one "
        "(`router.local_ip`) or other ports that do get through put the forwarding first, a "
        "process on the port puts (a) first; a free port, or a modem that holds the public "
        "address itself, moves (a) or (b) down.",
        "",
    ]
    for step in STEP_ORDER:
        rows = [r for r in RULES if r.step == step and not r.id.startswith("table1.")]
        if not rows:
            continue
        lines += [f"## Step {STEP_ORDER.index(step) + 1}: {_STEP_TITLES[step]}", "",
                  "| Condition | Rule | Severity | Meaning | Action | Back to | Checks |",
                  "|---|---|---|---|---|---|---|"]
        for r in rows:
            lines.append(f"| {_cell(r.condition)} | `{r.id}` | {r.severity} | {_cell(r.meaning)} "
                         f"| {_cell(r.action)} | {_cell(step_title(r.goto_step))} | "
                         f"{', '.join(f'`{c}`' for c in r.check_ids)} |")
        lines.append("")
    lines += ["## Any check", "",
              "| Condition | Rule | Severity | Meaning | Action |", "|---|---|---|---|---|"]
    for r in _CATCH_ALL:
        lines.append(f"| {_cell(r.condition)} | `{r.id}` | fail or warn, as the check | "
                     f"{_cell(r.meaning)} | {_cell(r.action)} |")
    lines.append("")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    import argparse

    p = argparse.ArgumentParser(prog="python -m rosnet_tui.core.advisor",
                                description="Print the advisor's rules.")
    p.add_argument("--markdown", action="store_true",
                   help="print docs/TROUBLESHOOTING.md (the default)")
    p.add_argument("--ids", action="store_true", help="print the rule ids, one a line")
    args = p.parse_args(argv)
    if args.ids:
        sys.stdout.write("".join(f"{r.id}\n" for r in all_rules()))
    else:
        sys.stdout.write(render_rules_markdown())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
