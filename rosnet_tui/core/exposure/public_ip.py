"""This component's public IP as the what-is-my-IP services of the settings see it
(``probe.public_ip_urls``): all asked at once; an address only when those that answer agree; each
address found kept in the state dir's history. The isp.public_ip check and the sync service's
watcher both ask here.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from rosnet_tui.core.addresses import is_ipv4
from rosnet_tui.core.jsonsafe import loads_bounded
from rosnet_tui.core.net.http import http_get
from rosnet_tui.core.saved.state import PublicIpRecord, now_iso, record_public_ip

ERROR = "error: "   # a service's entry in PublicIpFound.sources when it gave no address


def parse_ip(text: str) -> str | None:
    """The IPv4 address a what-is-my-IP service answered (plain text, or JSON with "ip")."""
    t = text.strip()
    if t.startswith("{"):
        with contextlib.suppress(ValueError, AttributeError):   # JsonInputError is a ValueError
            t = str(loads_bounded(t, unique_keys=False).get("ip", ""))
    t = t.split()[0] if t.split() else ""
    return t if is_ipv4(t) else None


@dataclass(frozen=True)
class PublicIpFound:
    """What the services said: each one's address or ``"error: why"`` (*sources*), one line of
    evidence each, and, when they agree, the history kept in the state dir (*record*)."""
    asked: int
    sources: dict[str, str] = field(default_factory=dict)
    evidence: list[str] = field(default_factory=list)
    record: PublicIpRecord | None = None
    record_error: str = ""      # the history could not be written (the address still counts)

    @property
    def ips(self) -> list[str]:
        return [v for v in self.sources.values() if not v.startswith(ERROR)]

    @property
    def ip(self) -> str | None:
        """The public IP: the answering services agree on it (None: none answered, or not)."""
        ips = self.ips
        return ips[0] if ips and len(set(ips)) == 1 else None

    def problem(self) -> str | None:
        """Why there is no public IP, in a sentence (None: there is one)."""
        if not self.asked:
            return "no what-is-my-IP service configured (probe.public_ip_urls)"
        ips = self.ips
        if not ips:
            return "no what-is-my-IP service answered, so the public IP is unknown"
        if len(set(ips)) > 1:
            listing = ", ".join(f"{u} says {v}" for u, v in self.sources.items()
                                if not v.startswith(ERROR))
            return (f"the services disagree about the public IP ({listing}): several exits "
                    "(a proxy, VPN or load-balancing modem)")
        return None


async def find_public_ip(urls: Sequence[str], state_dir: Path, within_s: float) -> PublicIpFound:
    """Ask every service in *urls* at once (each GET gets 85% of *within_s*); when they agree,
    keep the address in *state_dir*'s public-IP history."""
    urls = list(dict.fromkeys(urls))
    answers = await asyncio.gather(*(http_get(u, within_s * 0.85) for u in urls))
    sources: dict[str, str] = {}
    evidence: list[str] = []
    for a in answers:
        ip = parse_ip(a.text) if a.ok else None
        if ip:
            sources[a.url] = ip
            evidence.append(f"GET {a.url} -> {ip}")
        else:
            why = a.error or f"not an IPv4 address: {a.text.strip()[:60]!r}"
            sources[a.url] = f"{ERROR}{why}"
            evidence.append(f"GET {a.url} -> {why}")
    found = PublicIpFound(len(urls), sources, evidence)
    ip = found.ip
    if ip is None:
        return found
    try:
        rec = record_public_ip(state_dir, ip)
        problem = ""
    except OSError as exc:  # an unwritable state folder must not hide the address
        now = now_iso()
        rec = PublicIpRecord(ip, None, False, [{"ip": ip, "first_seen": now, "last_seen": now}])
        problem = f"could not record the address in {state_dir}: {exc.strerror or exc}"
    return PublicIpFound(found.asked, sources, evidence, rec, problem)
