"""The hosts entries this component needs, from its own point of view, per network profile."""

from __future__ import annotations

from dataclasses import dataclass

from rosnet_tui.core.settings import Peer, Settings


@dataclass(frozen=True)
class HostsEntry:
    ip: str
    name: str
    why: str  # a short reason, written as a comment beside the entry


def _peer_ip(peer: Peer, profile: str) -> str:
    if profile == "remote":
        return peer.public_ip
    if profile == "office":
        return peer.office_ip or peer.local_ip
    return peer.portable_ip or peer.local_ip


def own_ip(settings: Settings, profile: str) -> str:
    t = settings.this
    if profile == "office":
        return t.office_ip or t.local_ip
    if profile == "portable":
        return t.portable_ip or t.local_ip
    return t.local_ip


def hosts_entries(settings: Settings, profile: str | None = None) -> list[HostsEntry]:
    """This component's entries for *profile* (default: the active one).

    Own name -> own local IP; each peer -> its public IP on the remote profile, its LAN address on
    the office and portable profiles. Entries with no known address are left out.
    """
    profile = profile or settings.this.profile
    out: list[HostsEntry] = []
    mine = own_ip(settings, profile)
    if settings.this.name and mine:
        out.append(HostsEntry(mine, settings.this.name, "this component, its own local IP"))
    for p in settings.peers:
        ip = _peer_ip(p, profile)
        if ip:
            where = "public IP (its modem)" if profile == "remote" else f"address on the {profile} LAN"
            out.append(HostsEntry(ip, p.name, f"peer, {where}"))
    return out
