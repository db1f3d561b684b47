"""Step 1 (ISP): the rules that read the isp.* checks (internet, public IP, carrier NAT).

The link-down rule, which reads router.local_ip, lives with the router's rules; carrier NAT
as a cause of a closed port is Table 1's cause (b), also there.
"""

from __future__ import annotations

from collections.abc import Mapping

from rosnet_tui.core.addresses import is_ip
from rosnet_tui.core.advisor.engine import Hit, rule
from rosnet_tui.core.advisor.evidence import (
    Evidence,
    cgnat_text,
    join_and,
    offline_ids,
    uri_host,
)


def _url_host(url: str) -> str:
    return uri_host(url) or url or "the test address"


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
    gw = ev.data("router.local_ip").get("gateway")
    # A command is printed only as it can be run: with the gateway's address, or said in words.
    ping = (f"`ping {gw}`" if gw else
            "ping (its address is the one after \"default via\" in `ip route`)")
    look_up = f"`getent hosts {host}`" if d.get("url") else "`getent hosts` on a well-known name"
    return [Hit(
        f"{ev.me} cannot resolve names (looking up {host} failed): the DNS server it uses does "
        "not answer, or the link to the modem is down.",
        [f"Check the link: `ip route` must show a default route via {gw or 'the modem'}; a "
         "mobile hotspot may have lost its signal or its data allowance.",
         "See which DNS server is used: `resolvectl status` (systemd-resolved) or "
         "`cat /etc/resolv.conf`; it should be the modem or the provider's server.",
         f"Test by hand: {look_up}. If the modem answers {ping} but names still "
         "fail, set a DNS server explicitly in the network settings (NetworkManager: "
         "`nmcli connection modify CONNECTION ipv4.dns ADDRESS`).",
         "Then re-run the ISP step."],
        check_ids=offline_ids(ev), evidence=[f"isp.internet: DNS lookup of {host} failed"])]


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
                "connection does not carry traffic.", acts, check_ids=offline_ids(ev),
                evidence=["isp.internet: DNS ok, HTTP failed"])]


def _relay_says(ev: Evidence) -> str | None:
    """Under a relay (ROS 2), what this component's public address is still for (None: no
    relay); the peers' SSH, when it has no tunnel."""
    if not (ev.s.ros2 and ev.s.relayed):
        return None
    if ev.s.tunnelled:
        return (f"the peers reach {ev.me} through the relay {ev.s.relay.host} (ROS 2, and SSH "
                "through its tunnel): its public address does not matter")
    return (f"the ROS path goes through the relay {ev.s.relay.host} and does not use this "
            f"address; only the peers' SSH to {ev.me} does (no tunnel for it under "
            "[relay.tunnels])")


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
    urls = join_and(srcs) or "the configured sources"
    relay = _relay_says(ev)
    return [Hit(f"None of the what-is-my-IP sources ({urls}) told {ev.me} its public address.",
                ["Check that the internet works (ISP step, isp.internet).",
                 "Check public_ip_urls under [probe] in the settings: each URL must answer the "
                 "caller's address as plain text (e.g. https://ifconfig.co/ip).",
                 "Without a public IP no peer can be given this component's address."
                 if relay is None else f"Under the relay, {relay}."],
                evidence=errs or ["isp.public_ip: no address"])]


def _ip_answers(d: Mapping) -> dict[str, str]:
    return {u: v for u, v in (d.get("sources") or {}).items()
            if isinstance(v, str) and is_ip(v.strip())}


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
    return [Hit(f"The sources saw {ev.me} behind different public addresses ({join_and(distinct)}): "
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
    relay = _relay_says(ev)
    if not d.get("changed") or ev.s.tunnelled:
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
    if relay is not None:
        return [Hit(f"{ev.me}'s public IP changed from {prev} to {now} since the last run: "
                    f"{relay}; a peer that still uses {prev} for {ev.me} cannot SSH to "
                    "it.", acts, evidence=ev_lines)]
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
    relay = _relay_says(ev)
    if d.get("matches_settings") is not False or not d.get("public_ip") or ev.s.tunnelled:
        return []
    now, old = d["public_ip"], d.get("settings_ip") or ev.s.this.public_ip or "?"
    acts = [f"Set public_ip = \"{now}\" under [this] in the settings of {ev.me}."]
    for p in [p.name for p in ev.s.peers] or ["each peer"]:
        acts.append(f"On {p}: the hosts line for {ev.me} must read `{now} {ev.me}`, not "
                    f"`{old} {ev.me}`.")
    acts.append("Address sync does both for you whenever the address moves: `rosnet-tui sync`.")
    why = (f"peers configured from the settings look for {ev.me} at an address that is no "
           "longer its own" if relay is None else relay)
    return [Hit(f"{ev.me}'s public IP is {now}, but the settings say {old}: {why}.",
                acts, evidence=[f"isp.public_ip: seen {now}, settings {old}"])]


@rule("isp.cgnat", "isp", ("isp.cgnat",),
      "carrier-grade or double NAT on the way out",
      "The modem does not hold the public address: a NAT of the carrier (or a second router) "
      "sits in front of it, and forwarding on the modem cannot work.",
      "Ask the carrier for a public IP, or use another connection; with your own second router, "
      "forward on both or use bridge mode.",
      "isp", "warn", superseded_by=("table1.listener_up_closed.isp",))
def _cgnat(ev: Evidence) -> list[Hit]:
    d = ev.data("isp.cgnat")
    if not (d.get("cgnat") or d.get("double_nat")):
        return []
    if ev.s.ros2 and d.get("cgnat"):
        return []  # ROS 2: ros2.cgnat says what carrier NAT means for this role
    meaning, acts, evid = cgnat_text(ev)
    return [Hit(meaning, acts, severity=ev.sev("isp.cgnat", "warn"), evidence=evid)]
