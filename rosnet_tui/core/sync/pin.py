"""Pinning the peers' sync keys over SSH (`rosnet-tui sync pin`).

A record counts only when signed by the key pinned for its name (:mod:`.signing`). Copying every
component's key by hand onto every other is what a fleet would otherwise need after upgrading; so
this asks each peer for its public key over the channel the product already trusts: SSH with the
peer's host key verified (as every check's). The peer runs its own installed rosnet-tui's
``sync key`` (found as `ros pair` finds it: the pipx, uv or root-owned install, never the peer's
bare python3). The peers are asked at once, each within its own time limit; one that fails says
why and never stops the others. Writing changes only ``sync_key`` lines in the settings file
(comments and layout kept), atomically.
"""

from __future__ import annotations

import asyncio
import os
import re
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from rosnet_tui.core.config.settings_model import Peer, Settings, SettingsError
from rosnet_tui.core.peer.commands import NO_INSTALL_EXIT, installed_python_command
from rosnet_tui.core.printable import printable as shown
from rosnet_tui.core.ros.pairing import SERVE_BOOT
from rosnet_tui.core.saved.settings import (
    atomic_write_text,
    parse_settings,
    read_settings_text,
    with_peer_values,
)
from rosnet_tui.core.ssh.session import ssh_run
from rosnet_tui.core.sync.signing import fingerprint, parse_public

PIN_TIMEOUT_S = 10.0      # per peer: SSH in, start the peer's Python, print a line
KEY_MARK = "ROSNET_SYNC_KEY "
_KEY_LINE = re.compile(r'^sync_key = "(ed25519:[A-Za-z0-9+/=]+)"\s*$')


@dataclass
class PeerKey:
    """One peer's answer: the key it gave (or why none), and the one pinned here now."""

    name: str
    pinned: str = ""
    key: str = ""
    error: str = ""

    @property
    def state(self) -> str:
        """``failed``, ``same`` (already pinned), ``new`` (none pinned) or ``changed``."""
        if self.error:
            return "failed"
        if self.key == self.pinned:
            return "same"
        return "new" if not self.pinned else "changed"

    @property
    def fingerprint(self) -> str:
        return fingerprint(self.key) if self.key else ""

    @property
    def pinned_fingerprint(self) -> str:
        try:
            return fingerprint(self.pinned)
        except ValueError:
            return "not a sync key"


def key_command() -> str:
    """What a peer is asked to run: its own installed rosnet-tui's ``sync key``."""
    return installed_python_command("sync", "key", mark=KEY_MARK, boot=SERVE_BOOT)


def choose_peers(s: Settings, names: list[str]) -> tuple[list[Peer], list[PeerKey]]:
    """The peers to ask (*names*, or every peer with an ``ssh_user``) and the named ones that
    cannot be asked (no ssh_user), as failures. Raises ValueError for a name that is no peer."""
    if not names:
        return [p for p in s.peers if p.ssh_user], []
    chosen, failed = [], []
    for n in dict.fromkeys(names):
        p = peer_named(s, n)
        if p is None:
            raise ValueError(f"{shown(n, 80)} is no peer in the settings "
                             f"(peers: {', '.join(q.name for q in s.peers) or 'none'})")
        if any(q.name == p.name for q in chosen) or any(f.name == p.name for f in failed):
            continue
        if not p.ssh_user:
            failed.append(PeerKey(p.name, p.sync_key, error="no ssh_user in its [[peer]] "
                                  "table: set it, or copy the line `rosnet-tui sync key` "
                                  "prints there"))
        else:
            chosen.append(p)
    return chosen, failed


def peer_named(s: Settings, name: str) -> Peer | None:
    """The peer called *name* (names compare without case)."""
    return next((p for p in s.peers if p.name.lower() == name.lower()), None)


def key_of(stdout: str, stderr: str, exit_status: int | None) -> tuple[str, str]:
    """(the key, "") from the peer's output, or ("", why not)."""
    for line in reversed((stdout or "").splitlines()):
        m = _KEY_LINE.match(line.strip())
        if m:
            try:
                parse_public(m.group(1))
            except ValueError:
                return "", "its answer is not a sync key"
            return m.group(1), ""
    if exit_status == NO_INSTALL_EXIT and KEY_MARK in (stdout or ""):
        return "", "no rosnet-tui installed there: install it as the README says"
    err = (stderr or "").strip()
    if "invalid choice" in err and "key" in err:
        return "", "its rosnet-tui has no `sync key` yet: upgrade it there"
    tail = " | ".join(shown(x, 160) for x in err.splitlines()[-2:])
    return "", f"gave no key (exit status {exit_status}{': ' + tail if tail else ''})"


async def ask_peer(peer: Peer, opts: Any = None, timeout: float = PIN_TIMEOUT_S) -> PeerKey:
    """*peer*'s public sync key, asked over SSH within *timeout* seconds."""
    out = PeerKey(peer.name, peer.sync_key)
    try:
        res = await ssh_run(opts, peer, key_command(), timeout=timeout)
    except Exception as exc:  # noqa: BLE001 - one peer's trouble never stops the others
        out.error = f"SSH failed: {shown(str(exc), 200)}"
        return out
    if res.failure:
        out.error = f"SSH failed ({res.failure}): {shown(res.detail, 200)}"
        return out
    out.key, out.error = key_of(res.stdout, res.stderr, res.exit_status)
    return out


async def ask_peers(peers: list[Peer], opts: Any = None,
                    timeout: float = PIN_TIMEOUT_S) -> list[PeerKey]:
    """Each peer's answer (in order), all asked at once."""
    return list(await asyncio.gather(*(ask_peer(p, opts, timeout) for p in peers)))


def pinned_text(text: str, pins: dict[str, str]) -> str:
    """The settings text with each peer's ``sync_key`` set to *pins*' (name -> key), nothing
    else changed (checked by loading both). Raises SettingsError."""
    new = text
    for name, key in pins.items():
        new = with_peer_values(new, name, sync_key=key)
    was, got = parse_settings(text), parse_settings(new)
    want = {name.lower(): key for name, key in pins.items()}
    expected = [replace(p, sync_key=want.get(p.name.lower(), p.sync_key)) for p in was.peers]
    if got.peers != expected or got.this != was.this or got.sync != was.sync:
        raise SettingsError("the settings file's layout is beyond this edit: put the sync_key "
                            "lines in by hand")
    return new


def read_for_pin(path: Path) -> str:
    """The settings text as it is now (it must load). Raises SettingsError."""
    text = read_settings_text(path)
    if text is None:
        raise SettingsError(f"no settings file at {path}", path=path)
    parse_settings(text, path)
    return text


def write_pins(path: Path, before: str, pins: dict[str, str]) -> None:
    """Write the pins into the settings file at *path*, atomically, keeping its mode and owner.
    Raises SettingsError when the file changed since *before* was read, OSError."""
    now = read_settings_text(path)
    if now != before:
        raise SettingsError(f"{path} changed while the peers were asked: run it again", path=path)
    st = os.stat(path)
    owner = (st.st_uid, st.st_gid) if os.geteuid() == 0 else None
    atomic_write_text(path, pinned_text(before, pins), mode=st.st_mode & 0o7777, owner=owner)


def pin_from_pairing(path: Path, name: str, key: str) -> str:
    """`ros pair` on a member: pin the master *name*'s sync key that came back in the same SSH
    session as its signed certificate (host key verified), when none is pinned yet; a different
    one is never replaced here. What happened, in words ("" when the key was already pinned).
    Raises SettingsError, OSError."""
    try:
        fp = fingerprint(key)
    except ValueError:
        return f"{name}'s answer carried no usable sync key: `rosnet-tui sync pin {name}`"
    before = read_for_pin(path)
    peer = peer_named(parse_settings(before, path), name)
    if peer is None or peer.sync_key == key:
        return ""
    if peer.sync_key:
        return (f"KEY CHANGED: {name}'s sync key ({fp}) is not the one pinned here; not "
                f"replaced: `rosnet-tui sync pin {name}` shows both and asks")
    write_pins(path, before, {peer.name: key})
    return f"Pinned {name}'s sync key ({fp}) in {path}: its sync records count here now."
