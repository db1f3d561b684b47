"""Small persistent state under the state directory (``$XDG_STATE_HOME/rosnet-tui``).

Plain JSON files, written atomically (temp file + rename) under an advisory lock, so two
``rosnet-tui`` processes never leave a half-written file. Today: the history of this component's
public IP, which tells the user whether their address is fixed or changes, and of its local IP
(a new DHCP lease leaves the modem's forwarding pointing at the old one).
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from rosnet_tui.core.files import nofollow
from rosnet_tui.core.files.regular_file import read_regular
from rosnet_tui.core.files.undo_journal import make_private_dir
from rosnet_tui.core.jsonsafe import loads_bounded
from rosnet_tui.core.saved.settings import atomic_write_text

PUBLIC_IP_FILE = "public_ip.json"
LOCAL_IP_FILE = "local_ip.json"
MAX_HISTORY = 100


@contextlib.contextmanager
def locked(state_dir: Path, wait_s: float = 2.0) -> Iterator[None]:
    """An exclusive advisory lock on the state directory, held very briefly by anyone.

    Waits at most *wait_s*; after that it goes ahead unlocked (writes stay atomic anyway, a
    concurrent update could only be lost).
    """
    if os.geteuid() == 0:    # root in a user's state dir: through descriptors, no user's link
        make_private_dir(state_dir, None)
    else:
        state_dir.mkdir(parents=True, exist_ok=True, mode=0o700)
    fd = nofollow.open_lock(state_dir, ".lock")
    got = False
    try:
        got = nofollow.flock_within(fd, wait_s)
        yield
    finally:
        if got:
            fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)


MAX_STATE_BYTES = 16 << 20   # the biggest state file (sync status of many peers) is far smaller


def read_json(path: Path) -> Any | None:
    """The JSON in *path*, or None when missing or unreadable (state is never worth a crash).

    Damaged state counts as unreadable: JSON nested too deeply (the decoder would recurse out of
    stack), a file that is not a regular one (a FIFO would block, a device never end), one over
    MAX_STATE_BYTES."""
    try:
        return loads_bounded(read_regular(path, MAX_STATE_BYTES).decode("utf-8"),
                             unique_keys=False)
    except (OSError, ValueError):   # JsonInputError and UnicodeDecodeError are ValueErrors
        return None


def write_json(path: Path, data: Any, owner: tuple[int, int] | None = None) -> None:
    """*data* as JSON to *path* atomically, 0600 (handed to *owner*, on its descriptor)."""
    atomic_write_text(path, json.dumps(data, indent=2, sort_keys=True) + "\n", mode=0o600,
                      owner=owner)


def sync_dir(state_dir: Path) -> Path:
    """The sync service's folder in the state dir (its status, lock, applied records)."""
    return Path(state_dir) / "sync"


def state_owner(state_dir: Path) -> tuple[int, int] | None:
    """Root writing a user's state dir (the system service) hands its files to that user."""
    if os.geteuid() != 0:
        return None
    try:
        st = os.stat(state_dir)
    except OSError:
        return None
    return (st.st_uid, st.st_gid) if st.st_uid != 0 else None


def now_iso() -> str:
    return datetime.now(timezone.utc).replace(microsecond=0).isoformat()


@dataclass
class PublicIpRecord:
    ip: str
    previous_ip: str | None      # the address seen on the run before this one
    changed: bool
    history: list[dict[str, str]] = field(default_factory=list)  # oldest first


def _clean_history(raw: Any) -> list[dict[str, str]]:
    out: list[dict[str, str]] = []
    if isinstance(raw, list):
        for e in raw:
            if isinstance(e, dict) and all(isinstance(e.get(k), str)
                                           for k in ("ip", "first_seen", "last_seen")):
                out.append({"ip": e["ip"], "first_seen": e["first_seen"], "last_seen": e["last_seen"]})
    return out


def public_ip_history(state_dir: Path) -> list[dict[str, str]]:
    """Every public address seen so far: [{"ip", "first_seen", "last_seen"}], oldest first."""
    data = read_json(state_dir / PUBLIC_IP_FILE)
    return _clean_history(data.get("history") if isinstance(data, dict) else None)


def record_public_ip(state_dir: Path, ip: str, *, when: str | None = None) -> PublicIpRecord:
    """Add *ip* to the history (a new entry when it differs from the last one seen)."""
    return _record(state_dir, PUBLIC_IP_FILE, ip, when)


def record_local_ip(state_dir: Path, ip: str, *, when: str | None = None) -> PublicIpRecord:
    """Add this component's local IP to its own history (as :func:`record_public_ip` does):
    a changed local IP is the classic reason a modem's forwarding stops working."""
    return _record(state_dir, LOCAL_IP_FILE, ip, when)


def _record(state_dir: Path, name: str, ip: str, when: str | None) -> PublicIpRecord:
    when = when or now_iso()
    path = state_dir / name
    with locked(state_dir):
        data = read_json(path)
        history = _clean_history(data.get("history") if isinstance(data, dict) else None)
        previous = history[-1]["ip"] if history else None
        if history and history[-1]["ip"] == ip:
            history[-1]["last_seen"] = when
        else:
            history.append({"ip": ip, "first_seen": when, "last_seen": when})
        history = history[-MAX_HISTORY:]
        write_json(path, {"version": 1, "history": history})
    return PublicIpRecord(ip, previous, previous is not None and previous != ip, history)
