"""The hosts entries this component needs, from its own point of view, per network profile,
and the writer that puts the active set into /etc/hosts (our marked block only)."""

from __future__ import annotations

import ipaddress
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from rosnet_tui.core.addresses import is_loopback_ip
from rosnet_tui.core.config.paths import DEFAULT_HOSTS_PATH
from rosnet_tui.core.config.settings_model import (
    PROFILES,
    Peer,
    Settings,
    SettingsError,
    validate_ip,
)
from rosnet_tui.core.files import managed_file as mf
from rosnet_tui.core.files import managed_text as mt
from rosnet_tui.core.files import managed_write as mw


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
    the office and portable profiles. Entries with no known address are left out, and on the
    remote profile so are the peers reached through the relay ([relay.tunnels]): nothing of
    theirs answers at a carrier's address, and SSH reaches them without their name resolving.
    """
    profile = profile or settings.this.profile
    out: list[HostsEntry] = []
    mine = own_ip(settings, profile)
    if settings.this.name and mine:
        out.append(HostsEntry(mine, settings.this.name, "this component, its own local IP"))
    relayed = settings.relay.tunnels if settings.relay.host and profile == "remote" else {}
    for p in settings.peers:
        if p.name in relayed:
            continue
        ip = _peer_ip(p, profile)
        if ip:
            where = "public IP (its modem)" if profile == "remote" else f"address on the {profile} LAN"
            out.append(HostsEntry(ip, p.name, f"peer, {where}"))
    return out


# --------------------------------------------------------------------------- the hosts writer
# Everything below writes /etc/hosts through rosnet_tui.core.files.managed_file: our block only, at the
# top of the file (a resolver that stops at the first match then finds ours first).

PROFILE_TITLES = {
    "remote": "remote (peers by their public IP, across the internet)",
    "office": "office (everyone by their address on the office LAN)",
    "portable": "portable (everyone by their address on the portable hotspot's LAN)",
}
CONFLICT_REASON = (
    "another line gives the same name a different address; the resolver may return either one "
    "(glibc sorts 127.0.1.1 first), so this component or ROS would use the wrong address")
_ACTIVE_RE = re.compile(r"^# Active set: ([a-z]+)\b")
_TAG = "rosnet-tui"


class WriterSettingsError(SettingsError):
    """Settings that would produce a wrong file: nothing is written. ``problems``: (key, why)."""

    def __init__(self, problems: Sequence[tuple[str, str]]) -> None:
        self.problems = list(problems)
        text = "; ".join(f"{k}: {why}" for k, why in self.problems)
        super().__init__(f"nothing was written, the settings are not usable: {text}")


def _ip_problem(value: str) -> str | None:
    why = validate_ip(value, required=True)
    if why is None and is_loopback_ip(value):
        why = f"{value} is a loopback address; use the address on the network instead"
    return why


def hosts_problems(settings: Settings, profile: str | None = None) -> list[tuple[str, str]]:
    """Why the hosts set of *profile* cannot be written from *settings* (empty: it can)."""
    profile = profile or settings.this.profile
    out: list[tuple[str, str]] = []
    if profile not in PROFILES:
        return [("profile", f"must be one of {', '.join(PROFILES)}")]
    relevant = re.compile(r"^(this\.(name|profile|\w*_ip)|peer\[\d+\]\.(name|\w*_ip))$")
    out += [(k, why) for k, why in settings.problems() if relevant.match(k)]
    if not out:
        key = {"office": "this.office_ip", "portable": "this.portable_ip"}.get(profile,
                                                                             "this.local_ip")
        mine = own_ip(settings, profile)
        if not mine:
            out.append((key, f"this component's address for the {profile} profile is not set"))
        elif (why := _ip_problem(mine)) is not None:
            out.append((key, why))
        for i, p in enumerate(settings.peers):
            ip = _peer_ip(p, profile)
            if ip and (why := _ip_problem(ip)) is not None:
                out.append((f"peer[{i + 1}]", why))
    return out


def _entry_lines(entries: Sequence[HostsEntry], prefix: str = "") -> list[str]:
    width = max((len(e.name) for e in entries), default=0)
    return [f"{prefix}{e.ip:<15} {e.name:<{width}}  # {e.why}" for e in entries]


def render_hosts_block(settings: Settings, profile: str | None = None) -> list[str]:
    """The lines of our /etc/hosts block (between the markers) with *profile* active.

    The other profiles' sets follow as comments, so a technician can switch by hand too.
    Raises WriterSettingsError when the settings would give a wrong set.
    """
    profile = profile or settings.this.profile
    problems = hosts_problems(settings, profile)
    if problems:
        raise WriterSettingsError(problems)
    lines = [
        "# Managed by rosnet-tui: edits inside this block are replaced.",
        f"# Active set: {PROFILE_TITLES[profile]}",
        "# Switch sets with: rosnet-tui hosts use remote|office|portable",
        *_entry_lines(hosts_entries(settings, profile)),
    ]
    for other in PROFILES:
        if other == profile:
            continue
        entries = hosts_entries(settings, other)
        if entries and not hosts_problems(settings, other):
            lines.append(f"# Inactive set: {other}")
            lines += _entry_lines(entries, prefix="#  ")
    return lines


def render_hosts_text(settings: Settings, profile: str | None = None) -> str:
    """The whole block as text, markers included (for display)."""
    return "\n".join([mt.BEGIN_MARKER, *render_hosts_block(settings, profile), mt.END_MARKER]) + "\n"


def active_profile(text: str | None) -> str | None:
    """Which profile our block in a hosts file's *text* has active (None: no block)."""
    try:
        body = mt.extract_block(text)
    except mt.DamagedBlockError:
        return None
    for line in body or ():
        m = _ACTIVE_RE.match(line)
        if m and m.group(1) in PROFILES:
            return m.group(1)
    return None


def parse_hosts(text: str) -> list[tuple[int, str, list[str]]]:
    """(line number, address, names) for every entry of a hosts file."""
    out = []
    for n, line in enumerate(text.splitlines(), 1):
        parsed = parse_hosts_line(line)
        if parsed is not None:
            out.append((n, parsed[0], parsed[1]))
    return out


def parse_hosts_line(content: str) -> tuple[str, list[str], str] | None:
    """(address, names, comment) of a hosts line; None where the resolver reads no entry: a
    blank or comment line, one field alone, a first field that is no address (glibc skips it).
    The one reading of a hosts line: the checks, the conflict finder and the sync service's."""
    data, sep, comment = content.partition("#")
    fields = data.split()
    if len(fields) < 2:
        return None
    try:
        ipaddress.ip_address(fields[0].split("%")[0])
    except ValueError:
        return None
    return fields[0], fields[1:], (sep + comment) if sep else ""


def _same_ip(a: str, b: str) -> bool:
    try:
        return ipaddress.ip_address(a.split("%")[0]) == ipaddress.ip_address(b)
    except ValueError:
        return False


def find_hosts_conflicts(text: str | None, settings: Settings,
                         profile: str | None = None) -> list[mt.LineChange]:
    """Lines outside our block that give one of our names another address, and their fix.

    The fix comments the line out, or, when the line also names others (``127.0.0.1 localhost
    turtlebot``), takes only our names out of it, saying so in a comment.
    """
    profile = profile or settings.this.profile
    wanted = {e.name.lower(): e.ip for e in hosts_entries(settings, profile)}
    lines = mt.split_lines(text or "")
    span = mt.find_block(lines)
    out: list[mt.LineChange] = []
    for i, line in enumerate(lines):
        if span and span[0] <= i <= span[1]:
            continue
        content = mt.line_content(line)
        parsed = parse_hosts_line(content)
        if parsed is None:
            continue
        ip, names, comment = parsed
        bad = [n for n in names if n.lower() in wanted and not _same_ip(ip, wanted[n.lower()])]
        if not bad:
            continue
        keep = [n for n in names if n not in bad]
        if keep:
            indent = content[:len(content) - len(content.lstrip())]
            new = f"{indent}{ip}\t{' '.join(keep)}"
            new += f" {comment.strip()}" if comment else ""
            new += f" # {_TAG} took out: {' '.join(bad)}"
        else:
            new = f"# {_TAG}: {content}"
        out.append(mt.LineChange(i, content, new,
                                 f"maps {', '.join(bad)} to {ip}, not {wanted[bad[0].lower()]}: "
                                 f"{CONFLICT_REASON}"))
    return out


def _environment_notes(text: str | None) -> list[str]:
    notes = []
    if text and "manage_etc_hosts" in text:
        notes.append("cloud-init manages this file ('manage_etc_hosts') and rewrites it at boot: "
                     "set manage_etc_hosts to false in /etc/cloud/cloud.cfg, or the block is lost")
    return notes


def preview_hosts(settings: Settings, profile: str | None = None,
                  path: Path = DEFAULT_HOSTS_PATH, *, fix_conflicts: bool = False,
                  state_dir: Path | None = None) -> mf.Preview:
    """Preview our block in *path* with *profile*'s set active; writes nothing.

    Conflicting lines outside the block are listed in the notes; with *fix_conflicts* (only
    after the user agreed) they are commented out (see :func:`find_hosts_conflicts`).
    """
    profile = profile or settings.this.profile
    body = render_hosts_block(settings, profile)
    old = mw.read_bytes(Path(path), state_dir=state_dir)
    text = mt.decode(old) if old is not None else None
    conflicts = find_hosts_conflicts(text, settings, profile)
    notes = _environment_notes(text)
    for c in conflicts:
        then = (f"it becomes '{c.new.strip()}'" if fix_conflicts
                else "agree to fix it (--comment-conflicts) or edit it by hand")
        notes.append(f"line {c.lineno} '{c.old.strip()}' {c.why}; {then}")
    replace = {c.index: c.new for c in conflicts} if fix_conflicts else None
    return mf.preview_block(Path(path), body, position="top", label=f"hosts: {profile} set",
                            notes=notes, replace_lines=replace, new_mode=0o644,
                            current=old, use_current=True)


def apply_hosts(settings: Settings, profile: str | None = None,
                path: Path = DEFAULT_HOSTS_PATH, *, expect_digest: str | None = None,
                fix_conflicts: bool = False, state_dir: Path | None = None) -> mf.ApplyResult:
    """Preview and write in one go; *expect_digest* (from an earlier preview) guards staleness."""
    preview = preview_hosts(settings, profile, path, fix_conflicts=fix_conflicts,
                            state_dir=state_dir)
    if expect_digest is not None and preview.digest != expect_digest:
        raise mt.StalePreviewError(f"{path} changed since the preview was made; nothing was written")
    return mf.apply_preview(preview, state_dir=state_dir)
