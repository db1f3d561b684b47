"""Step 1, ISP: is there internet, what is our public IP (and does it change), is there carrier NAT.

Traffic goes only to the endpoints the settings name (``probe.public_ip_urls``,
``probe.port_check_url``), plus, for ``isp.cgnat``, a question to the modem on the LAN (UPnP IGD,
NAT-PMP or PCP, :mod:`rosnet_tui.core.upnp`) when ``ctx.upnp`` allows it. HTTP ignores proxy variables: a proxy would answer with its own address.
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
import struct
import time
from dataclasses import dataclass
from typing import Any
from urllib.parse import urlsplit

import psutil

from rosnet_tui.core.addresses import (
    KIND_WORDS,
    address_kind,
    is_ip,
    is_loopback_ip,
    is_private,
    is_public_v4,
    is_shared,
)
from rosnet_tui.core.checks import CheckContext, check
from rosnet_tui.core.checks.probes.budget import budget
from rosnet_tui.core.checks.probes.public_ip import fetch_public_ip
from rosnet_tui.core.config.settings_model import Settings
from rosnet_tui.core.exposure.public_ip import find_public_ip
from rosnet_tui.core.net.blocking import run_blocking
from rosnet_tui.core.net.http import http_get
from rosnet_tui.core.net.netinfo import is_overlay
from rosnet_tui.core.results import Outcome, Status
from rosnet_tui.core.ssh.connection import resolve_ipv4
from rosnet_tui.core.upnp.modem import find_modem


# --------------------------------------------------------------------------- isp.internet
def _endpoints(ctx: CheckContext) -> list[str]:
    urls = list(ctx.settings.probe.public_ip_urls)
    if ctx.settings.probe.port_check_url:
        urls.append(ctx.settings.probe.port_check_url)
    return list(dict.fromkeys(urls))


@check("isp.internet", "isp", "Internet: DNS and HTTP work", 1.0)
async def check_internet(ctx: CheckContext) -> Outcome:
    urls = _endpoints(ctx)
    if not urls:
        return Outcome(Status.SKIP, "no endpoints in the settings (probe.public_ip_urls is empty)",
                       data={"dns_ok": None, "http_ok": None, "failed_part": None, "url": ""})
    total = budget(ctx, "isp.internet") * 0.9
    start = time.monotonic()

    async def probe(url: str) -> dict:
        host = urlsplit(url).hostname or ""
        ev: list[str] = []
        dns_ok: bool | None = None
        if host and not is_ip(host):
            addrs, err = await resolve_ipv4(host, total * 0.45)
            dns_ok = bool(addrs)
            ev.append(f"resolve {host} -> {', '.join(addrs)}" if addrs else f"resolve {host}: {err}")
            if not addrs:
                return {"url": url, "dns_ok": False, "http_ok": None, "evidence": ev}
        ans = await http_get(url, max(total - (time.monotonic() - start), 0.2))
        ev.append(ans.describe())
        return {"url": url, "dns_ok": dns_ok, "http_ok": ans.ok, "evidence": ev}

    probes = await asyncio.gather(*(probe(u) for u in urls))
    evidence = [line for p in probes for line in p["evidence"]]
    good = [p for p in probes if p["http_ok"]]
    bad = [p for p in probes if not p["http_ok"]]

    def part(p: dict) -> str:
        return "dns" if p["dns_ok"] is False else "http"

    shown = bad[0] if bad and good else probes[0]
    data = {"dns_ok": shown["dns_ok"], "http_ok": shown["http_ok"],
            "failed_part": None if shown["http_ok"] else part(shown), "url": shown["url"],
            "endpoints": {p["url"]: {"dns_ok": p["dns_ok"], "http_ok": p["http_ok"]} for p in probes}}
    if not bad:
        n = len(probes)
        return Outcome(Status.PASS, f"DNS and HTTP work ({n} endpoint{'s' if n > 1 else ''} answered)",
                       evidence, data)
    if good:
        names = ", ".join(p["url"] for p in bad)
        return Outcome(Status.WARN, f"the internet works, but {names} failed "
                                    f"({'name resolution' if part(bad[0]) == 'dns' else 'HTTP'})",
                       evidence, data)
    if all(part(p) == "dns" for p in bad):
        data["failed_part"] = "dns"
        return Outcome(Status.FAIL, "no internet: names do not resolve (DNS fails)", evidence, data)
    data["failed_part"] = "http"
    if any(p["dns_ok"] for p in bad):
        return Outcome(Status.FAIL, "no internet: names resolve but no HTTP request gets an answer",
                       evidence, data)
    return Outcome(Status.FAIL, "no internet: no HTTP request gets an answer", evidence, data)


# --------------------------------------------------------------------------- isp.public_ip
def relay_words(s: Settings) -> str | None:
    """Under a relay (ROS 2), what this component's public address is still used for, in
    words (None: no relay, the address is the peers' way here)."""
    if not (s.ros2 and s.relayed):
        return None
    via = f"the relay {s.relay.host}"
    if s.tunnelled:
        return (f"the address does not matter here: the peers reach this component through "
                f"{via} (ROS 2, and SSH through its tunnel), never at this address")
    return (f"the ROS path goes through {via} and does not use it; only the peers' SSH to this "
            "component does (it has no tunnel under [relay.tunnels]), from their hosts files")


@check("isp.public_ip", "isp", "Public IP: what the internet sees, and whether it changes", 1.0)
async def check_public_ip(ctx: CheckContext) -> Outcome:
    s = ctx.settings
    settings_ip = s.this.public_ip
    base: dict[str, Any] = {"public_ip": None, "sources": {}, "agree": False,
                            "settings_ip": settings_ip, "matches_settings": None,
                            "previous_ip": None, "changed": False, "history": []}
    found = await find_public_ip(s.probe.public_ip_urls, ctx.paths.state_dir,
                                 budget(ctx, "isp.public_ip"))
    problem = found.problem()
    if not found.asked:
        return Outcome(Status.SKIP, problem or "", data=base)
    evidence = list(found.evidence)
    data = dict(base, sources=found.sources)
    if problem is not None:
        return Outcome(Status.FAIL, problem, evidence, data)
    public_ip, rec, ips = found.ip, found.record, found.ips
    assert public_ip is not None and rec is not None
    errors = len(ips) < found.asked
    if found.record_error:
        evidence.append(found.record_error)
    matches = None if not settings_ip else settings_ip == public_ip
    data.update(public_ip=public_ip, agree=not errors, matches_settings=matches,
                previous_ip=rec.previous_ip, changed=rec.changed, history=rec.history)
    if len(rec.history) > 1:
        evidence.append("addresses seen: " + ", ".join(
            f"{h['ip']} ({h['first_seen']} .. {h['last_seen']})" for h in rec.history[-5:]))
    else:
        evidence.append(f"first recorded {rec.history[0]['first_seen']}")
    notes: list[str] = []
    status = Status.PASS
    if not is_public_v4(public_ip):
        status = Status.WARN
        notes.append(f"{public_ip} is not a public address (is the service on your own network?)")
    if errors:
        status = Status.WARN
        notes.append(f"{found.asked - len(ips)} of {found.asked} services did not answer")
    relay = relay_words(s)
    if relay is not None and (rec.changed or matches is False):
        moved = ([f"it changed since the last run (was {rec.previous_ip})"] if rec.changed
                 else []) + ([f"the settings say {settings_ip}"] if matches is False else [])
        status = status if s.tunnelled else Status.WARN
        notes.append(f"{'; '.join(moved)}: {relay}")
    else:
        if rec.changed:
            status = Status.WARN
            notes.append(f"it changed since the last run (was {rec.previous_ip}): this "
                         "connection's address is not fixed; peers' hosts entries go stale")
        if matches is False:
            status = Status.WARN
            notes.append(f"the settings say {settings_ip}: update them and the peers' hosts "
                         "files")
    if status is Status.PASS and notes:      # moved, and under a relay nothing uses it
        return Outcome(Status.PASS, f"public IP {public_ip}; " + "; ".join(notes), evidence, data)
    if status is Status.PASS:
        kept = rec.history[-1]["first_seen"]
        how = f"unchanged since {kept}" if len(rec.history) > 1 or rec.previous_ip else "recorded"
        agree = f"{len(ips)} sources agree" if len(ips) > 1 else "from 1 source"
        return Outcome(Status.PASS, f"public IP {public_ip} ({how}; {agree})",
                       evidence, data)
    return Outcome(status, f"public IP {public_ip}; " + "; ".join(notes), evidence, data)


# --------------------------------------------------------------------------- isp.cgnat
IP_RECVERR = getattr(socket, "IP_RECVERR", 11)
SO_EE_ORIGIN_ICMP = 2
_EE = struct.Struct("=IBBBBII")
TRACE_BASE_PORT = 33434
MAX_HOPS = 6


@dataclass
class Hop:
    ttl: int
    ip: str | None
    reached: bool = False   # the destination itself answered (port unreachable)


def _parse_errqueue(ancdata: list) -> tuple[str, int, int] | None:
    for level, ctype, data in ancdata:
        if level == socket.SOL_IP and ctype == IP_RECVERR and len(data) >= _EE.size + 8:
            _errno, origin, icmp_type, icmp_code, _pad, _info, _d = _EE.unpack_from(data)
            if origin != SO_EE_ORIGIN_ICMP:
                continue
            addr = socket.inet_ntoa(data[_EE.size + 4:_EE.size + 8])
            return addr, icmp_type, icmp_code
    return None


async def ttl_probe(target: str, max_hops: int, timeout: float) -> list[Hop]:
    """Which routers a UDP packet to *target* passes: one probe per TTL, answers read from the
    socket error queue (IP_RECVERR), so no raw socket and no privileges are needed."""
    socks: dict[int, socket.socket] = {}
    hops: dict[int, Hop] = {}
    try:
        for ttl in range(1, max_hops + 1):
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            s.setblocking(False)
            s.setsockopt(socket.SOL_IP, IP_RECVERR, 1)
            s.setsockopt(socket.SOL_IP, socket.IP_TTL, ttl)
            s.connect((target, TRACE_BASE_PORT + ttl))
            socks[ttl] = s
        deadline = time.monotonic() + timeout
        resend_at = time.monotonic() + timeout / 2
        resent = False
        for s in socks.values():
            with contextlib.suppress(OSError):
                s.send(b"rosnet-tui path probe")
        while time.monotonic() < deadline:
            for ttl, s in socks.items():
                if ttl in hops:
                    continue
                try:
                    _data, anc, _flags, _addr = s.recvmsg(512, 512, socket.MSG_ERRQUEUE)
                except (BlockingIOError, InterruptedError):
                    continue
                except OSError:
                    continue
                got = _parse_errqueue(anc)
                if got:
                    ip, icmp_type, _code = got
                    hops[ttl] = Hop(ttl, ip, reached=(icmp_type == 3 and ip == target))
            reached = [t for t, h in hops.items() if h.reached or h.ip == target]
            if reached and all(t in hops for t in range(1, min(reached) + 1)):
                break
            if len(hops) == len(socks):
                break
            if not resent and time.monotonic() >= resend_at:
                resent = True
                for ttl, s in socks.items():
                    if ttl not in hops:
                        with contextlib.suppress(OSError):
                            s.send(b"rosnet-tui path probe")
            await asyncio.sleep(0.02)
    finally:
        for s in socks.values():
            s.close()
    out: list[Hop] = []
    for ttl in range(1, max_hops + 1):
        h = hops.get(ttl, Hop(ttl, None))
        out.append(h)
        if h.reached or h.ip == target:
            break
    return out


def _ask_modem(timeout: float, notes: list[str]):
    """The modem's own word on its external address (UPnP IGD, NAT-PMP or PCP), or None."""
    return find_modem(timeout, notes=notes)


def _route_source(target: str) -> tuple[str, str]:
    """(source address, interface) this machine would use towards *target* (no packet sent)."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        s.connect((target, TRACE_BASE_PORT))
        src = s.getsockname()[0]
    finally:
        s.close()
    for name, addrs in psutil.net_if_addrs().items():
        if any(a.family == socket.AF_INET and a.address == src for a in addrs):
            return src, name
    return src, ""


@check("isp.cgnat", "isp", "No carrier-grade or double NAT on the way out", 2.0)
async def check_cgnat(ctx: CheckContext) -> Outcome:
    out = await _cgnat(ctx)
    s = ctx.settings
    if s.ros2 and s.relayed and out.status is Status.WARN and (
            out.data.get("cgnat") or out.data.get("double_nat")):
        return Outcome(Status.PASS, f"{out.summary}. No problem here: every router dials out "
                                    f"to the relay {s.relay.host}, which carries the link, so "
                                    "nothing needs to reach this site", out.evidence, out.data)
    return out


async def _cgnat(ctx: CheckContext) -> Outcome:
    total = budget(ctx, "isp.cgnat") * 0.85
    data: dict = {"wan_ip": None, "method": "none", "cgnat": False, "double_nat": False,
                  "hop": None, "hops": []}
    evidence: list[str] = []
    urls = ctx.settings.probe.public_ip_urls
    host = urlsplit(urls[0]).hostname if urls else None
    target: str | None = None
    if host:
        if is_ip(host):
            target = host
        else:
            addrs, err = await resolve_ipv4(host, total * 0.3)
            target = addrs[0] if addrs else None
            if not addrs:
                evidence.append(f"resolve {host}: {err}")
    start = time.monotonic()

    async def upnp() -> str | None:
        if not ctx.upnp:
            evidence.append("UPnP: not asked (turned off for this run)")
            return None
        notes: list[str] = []
        try:
            modem = await run_blocking(_ask_modem, min(total * 0.45, 2.0), notes,
                                       timeout=max(total * 0.6, 0.5))
        except asyncio.TimeoutError:
            evidence.append("UPnP: the modem did not finish answering in time")
            return None
        finally:
            answered.set()
        if modem is None:
            evidence.append("UPnP IGD, PCP, NAT-PMP: no modem answered on the LAN")
            return None
        if modem.external_ip is None:
            evidence.append(f"{modem.describe()}, but did not tell its external address")
            return None
        evidence.append(f"{modem.describe()}: its external address is "
                        f"{modem.external_ip or '(none: it reports no public address)'}")
        return modem.external_ip

    async def trace() -> list[Hop] | None:
        if target is None:
            return None
        try:
            src, ifname = await run_blocking(_route_source, target, timeout=1.0)
        except (OSError, asyncio.TimeoutError) as exc:
            evidence.append(f"no route towards {target}: {exc}")
            return None
        if ifname == "lo" or is_loopback_ip(target):
            evidence.append(f"{target} is this machine itself; there is no path to probe")
            return None
        if ifname and is_overlay(ifname):
            evidence.append(f"traffic to {target} leaves through {ifname}, an overlay network; its "
                            "path says nothing about the modem, so it was not probed")
            return None
        data["source"] = src
        try:
            hops = await ttl_probe(target, MAX_HOPS, max(total - (time.monotonic() - start) - 0.2, 0.3))
        except OSError as exc:
            evidence.append(f"TTL-limited probe not possible here: {exc}")
            return None
        evidence.append(f"TTL-limited UDP probe towards {target}: " + ", ".join(
            f"{h.ttl}:{h.ip or '*'}" for h in hops))
        return hops

    # The path probe usually ends within tens of milliseconds. When it already shows public
    # hops beyond the modem and the modem has not answered (UPnP, PCP, NAT-PMP) after
    # SSDP_GRACE_S, it is unlikely to answer later: stop waiting for it (it could add only the WAN
    # address the path already vouches for).
    answered = asyncio.Event()
    up_task = asyncio.ensure_future(upnp())
    hops = await trace()
    wan_ip = None
    if hops is not None and not answered.is_set() and _public_beyond_modem(hops, target):
        done, _ = await asyncio.wait([up_task], timeout=SSDP_GRACE_S)
        if not done:
            up_task.cancel()
            await asyncio.gather(up_task, return_exceptions=True)
            evidence.append(f"UPnP IGD, PCP, NAT-PMP: no modem answered within "
                            f"{SSDP_GRACE_S:g} s; not waited for longer, since the path probe "
                            "shows public hops beyond the modem")
        else:
            wan_ip = up_task.result()
    else:
        wan_ip = await up_task
    if wan_ip == "":  # the modem answers but has no public address: its own word for carrier NAT
        data.update(wan_ip="", method="upnp")
        if hops:
            data["hops"] = [h.ip for h in hops]
            _st, _summary, seen = judge_path(hops, target or "", data.get("source"))
        else:
            seen = {}
        status, summary, updates = judge_no_wan(seen)
        data.update(updates)
        return Outcome(status, summary, evidence, data)
    if wan_ip:
        data.update(wan_ip=wan_ip, method="upnp")
        if hops:  # a modem can learn a public address from outside (STUN): the path has the say
            p_status, p_summary, seen = judge_path(hops, target or "", data.get("source"))
            if seen.get("cgnat") or seen.get("double_nat"):
                evidence.append(f"the modem reports {wan_ip} as its address, but the path out "
                                "shows NAT beyond it (a modem can learn the outside address, "
                                "e.g. by STUN)")
                data.update(seen, method="traceroute", hops=[h.ip for h in hops])
                return Outcome(p_status, p_summary, evidence, data)
        public_ip = None
        if is_public_v4(wan_ip):
            public_ip = await fetch_public_ip(ctx, max(total - (time.monotonic() - start), 0.5))
            if public_ip:
                evidence.append(f"the internet sees {public_ip}")
        status, summary, updates = judge_wan(wan_ip, public_ip)
        data.update(updates)
        return Outcome(status, summary, evidence, data)
    if hops is None:
        if target is None and not host:
            return Outcome(Status.SKIP, "cannot tell: no public-IP service in the settings to probe "
                                        "towards, and no UPnP answer from the modem", evidence, data)
        if target is None:
            return Outcome(Status.SKIP, f"cannot tell: {host} does not resolve and the modem did not "
                                        "answer UPnP", evidence, data)
        return Outcome(Status.SKIP, "cannot tell: " + (evidence[-1] if evidence else "no probe"),
                       evidence, data)
    data["method"] = "traceroute"
    data["hops"] = [h.ip for h in hops]
    status, summary, updates = judge_path(hops, target or "", data.get("source"))
    data.update(updates)
    return Outcome(status, summary, evidence, data)


SSDP_GRACE_S = 0.3


def _public_beyond_modem(hops: list[Hop], target: str | None) -> bool:
    """The path probe is conclusive: the first hop after the modem answered and is public, or
    the target itself answered right behind the modem."""
    if len(hops) < 2 or not hops[1].ip:
        return False
    return hops[1].reached or hops[1].ip == target or is_public_v4(hops[1].ip)


def judge_wan(wan_ip: str, public_ip: str | None) -> tuple[Status, str, dict]:
    """Verdict from the modem's own WAN address (UPnP) and the address the internet sees."""
    if is_shared(wan_ip):
        return (Status.WARN, f"carrier-grade NAT: the modem's internet-side address is {wan_ip} "
                             "(the carriers' shared 100.64.0.0/10); port forwarding on this modem "
                             "cannot be reached from the internet", {"cgnat": True, "hop": wan_ip})
    if is_private(wan_ip):
        return (Status.WARN, f"double NAT: the modem's internet-side address {wan_ip} is private; "
                             "the router in front of it must forward too",
                {"double_nat": True, "hop": wan_ip})
    if not is_public_v4(wan_ip):   # 0.0.0.0, loopback, multicast...: never "no carrier NAT"
        return (Status.WARN, f"cannot tell: the modem reports {wan_ip} as its internet-side "
                             f"address, {KIND_WORDS[address_kind(wan_ip)]}, not a public one",
                {"hop": wan_ip})
    if public_ip and public_ip != wan_ip:
        return (Status.WARN, f"NAT beyond the modem: its WAN address is {wan_ip} but the internet "
                             f"sees {public_ip}", {"double_nat": True, "hop": wan_ip})
    return Status.PASS, f"no carrier NAT: the modem holds the public address {wan_ip}", {}


def judge_no_wan(path: dict) -> tuple[Status, str, dict]:
    """Verdict when the modem reports no external address (miniupnpd does behind carrier NAT,
    where other modems report their 100.64.x address); *path* is what the path probe saw."""
    if path.get("double_nat"):
        return (Status.WARN, "double NAT: the modem reports no public address of its own, and the "
                             f"router after it ({path.get('hop')}) is private; that router must "
                             "forward too", {"double_nat": True, "hop": path.get("hop")})
    return (Status.WARN, "carrier-grade NAT: the modem reports no public address of its own (the "
                         "provider's NAT is in front of it); port forwarding on this modem cannot "
                         "be reached from the internet", {"cgnat": True, "hop": path.get("hop")})


def judge_path(hops: list[Hop], target: str, source: str | None) -> tuple[Status, str, dict]:
    """Verdict from the routers on the way out (hop 1 is our own modem, so it is not judged)."""
    if source and is_shared(source):
        return (Status.WARN, f"carrier-grade NAT: this machine's own address {source} is in the "
                             "carriers' range 100.64.0.0/10", {"cgnat": True, "hop": source})
    for h in hops[1:]:
        if h.ip and h.ip != target and is_shared(h.ip):
            return (Status.WARN, f"carrier-grade NAT: hop {h.ttl} on the way out is {h.ip} "
                                 "(100.64.0.0/10, the carriers' shared range); forwarding on the "
                                 "modem cannot be reached from the internet",
                    {"cgnat": True, "hop": h.ip})
    for h in hops[1:]:
        if h.ip and h.ip != target and is_private(h.ip):
            return (Status.WARN, f"double NAT: hop {h.ttl} on the way out is the private address "
                                 f"{h.ip}; the router there must forward too",
                    {"double_nat": True, "hop": h.ip})
    if any(h.ip for h in hops[1:]) or any(h.reached for h in hops):
        return Status.PASS, "no sign of carrier NAT (the hops after the modem are public)", {}
    return Status.PASS, "no sign of carrier NAT (no hop after the modem answered the probe)", {}
