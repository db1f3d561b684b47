"""From the records to this component's hosts set: which address each peer gets, and why.

The profile is chosen by evidence, not by address prefixes: a peer whose record shows the same
public IP as ours sits behind our modem, on our LAN, so it gets its local address; any other peer
is remote and gets its public address. All peers on our LAN -> a LAN profile (office, or the
portable one when that is the active profile); any remote peer -> the remote profile (a peer
that shares our LAN there still gets its LAN address, said so in the comment).
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from dataclasses import dataclass, field

from rosnet_tui.core.config.settings_model import Settings
from rosnet_tui.core.files import managed_text as mt
from rosnet_tui.core.files.hosts import (
    HostsEntry,
    hosts_entries,
    parse_hosts,
    parse_hosts_line,
    render_hosts_block,
)
from rosnet_tui.core.saved.sync_records import Record

LAN_WHY = "peer, on this LAN (same public IP as us)"


class PlanError(Exception):
    """The records and settings do not give a hosts set we may write; nothing is written."""


@dataclass(frozen=True)
class PeerChoice:
    name: str
    address: str          # what the hosts set maps the name to ("" when unknown)
    where: str            # "lan" | "remote" | "unknown" (no record: the settings' address)
    why: str


@dataclass
class Plan:
    profile: str
    settings: Settings            # what the block and the checks are computed from
    learned: Settings             # the addresses to keep in the settings file (no LAN trick)
    choices: list[PeerChoice] = field(default_factory=list)
    mixed: bool = False           # remote profile with some peers on our LAN

    @property
    def entries(self) -> list[HostsEntry]:
        return hosts_entries(self.settings, self.profile)

    def body(self) -> list[str]:
        """Our hosts block's lines (raises hosts.WriterSettingsError on unusable settings)."""
        lines = render_hosts_block(self.settings, self.profile)
        if not self.mixed:
            return lines
        lan = {c.name for c in self.choices if c.where == "lan"}
        out = []
        active = True
        for line in lines:
            if line.startswith("# Inactive set"):
                active = False
            parsed = parse_hosts_line(line)
            if active and parsed and len(parsed[1]) == 1 and parsed[1][0] in lan \
                    and "  # " in line:
                line = line.split("  # ", 1)[0] + "  # " + LAN_WHY
            out.append(line)
        return out


def plan_hosts(settings: Settings, *, local_ip: str, public_ip: str,
               records: Mapping[str, Record]) -> Plan:
    """The hosts set for *settings*, this component's observed addresses (empty: unknown,
    the settings' value stands) and the peers' valid records."""
    learned = copy.deepcopy(settings)
    if local_ip:
        learned.this.local_ip = local_ip
    if public_ip:
        learned.this.public_ip = public_ip
    ours = learned.this.public_ip
    lan, remote, choices = [], [], []
    for p in learned.peers:
        r = records.get(p.name)
        if r is None:
            choices.append(PeerChoice(p.name, "", "unknown", "no record yet: the settings' address"))
            continue
        if r.local_ip:
            p.local_ip = r.local_ip
        if r.public_ip:
            p.public_ip = r.public_ip
        if ours and r.public_ip == ours and r.local_ip:
            lan.append(p.name)
        elif r.public_ip:
            remote.append(p.name)
        else:
            choices.append(PeerChoice(p.name, "", "unknown",
                                      "its record has no public IP: the settings' address"))
            continue
    if lan and not remote:
        profile = settings.this.profile if settings.this.profile in ("office", "portable") \
            else "office"
    elif lan or remote:
        profile = "remote"
    else:
        profile = settings.this.profile  # no evidence at all: keep what the user chose
    learned.this.profile = profile
    render = copy.deepcopy(learned)
    mixed = bool(lan and remote)
    if profile != "remote":
        # Observed addresses beat the per-LAN overrides of the settings.
        if local_ip:
            render.this.office_ip = render.this.portable_ip = ""
        for p in render.peers:
            if p.name in lan:
                p.office_ip = p.portable_ip = ""
    elif mixed:
        for p in render.peers:
            if p.name in lan:
                p.public_ip = p.local_ip
    for p in render.peers:
        if p.name in lan:
            choices.append(PeerChoice(p.name, p.local_ip, "lan",
                                      f"same public IP as us ({ours}): on this LAN"))
        elif p.name in remote:
            choices.append(PeerChoice(p.name, p.public_ip, "remote",
                                      "another public IP: remote, by its public IP"))
    addr = {e.name: e.ip for e in hosts_entries(render, profile)}
    choices = [PeerChoice(c.name, addr.get(c.name, ""), c.where, c.why) for c in choices]
    order = {p.name: i for i, p in enumerate(settings.peers)}
    choices.sort(key=lambda c: order.get(c.name, 0))
    return Plan(profile, render, learned, choices, mixed)


def block_names(text: str | None) -> set[str]:
    """Names our block in a hosts file's *text* maps now (active set only)."""
    try:
        body = mt.extract_block(text)
    except mt.DamagedBlockError:
        return set()
    return {x.lower() for _, _, names in parse_hosts("\n".join(body or ())) for x in names}


def check_complete(plan: Plan, current_text: str | None) -> None:
    """Refuse a set that would drop a name: this component, every peer with a record, and every
    name our block maps now must stay. Raises PlanError."""
    have = {e.name.lower() for e in plan.entries}
    need = {plan.settings.this.name.lower()}
    need |= {c.name.lower() for c in plan.choices if c.where in ("lan", "remote")}
    need |= block_names(current_text) & {p.name.lower() for p in plan.settings.peers}
    missing = sorted(need - have)
    if missing:
        raise PlanError("the new hosts set would leave out " + ", ".join(missing)
                        + " (no usable address); the current one is kept")
