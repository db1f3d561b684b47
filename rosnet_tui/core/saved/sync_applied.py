"""The record of each peer last applied here, kept in the state dir (``sync/applied.json``).

Both ``sync --once`` and the service read it at start and write it whenever they take a peer's
record, so an old copy that comes back (a sync tool restoring a file, a stale DNS answer, a
replay) is refused even after a restart: a record is taken only when
:func:`sync_records.successor_problem` finds nothing against it.
"""

from __future__ import annotations

import contextlib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from rosnet_tui.core.files.undo_journal import make_private_dir
from rosnet_tui.core.saved.state import read_json, state_owner, sync_dir, write_json
from rosnet_tui.core.saved.sync_records import Record, RecordError, parse_record

APPLIED_VERSION = 1
MAX_PEERS = 1000


def applied_path(state_dir: Path) -> Path:
    return sync_dir(state_dir) / "applied.json"


def load_applied(state_dir: Path) -> dict[str, Record]:
    """The last applied record of each peer, by lower-case name ({} when none or unreadable;
    a damaged entry is left out)."""
    try:
        data = read_json(applied_path(state_dir))
    except RecursionError:
        data = None
    peers = data.get("peers") if isinstance(data, dict) \
        and data.get("version") == APPLIED_VERSION else None
    out: dict[str, Record] = {}
    if not isinstance(peers, dict):
        return out
    for name, raw in list(peers.items())[:MAX_PEERS]:
        # Far-future check off: the record was valid when it was applied, and the clock may
        # have been moved back since; what matters is its seq.
        with contextlib.suppress(RecordError, TypeError, AttributeError):
            rec = parse_record(raw, expect_name=str(name), now=float("inf"))
            out[rec.name.lower()] = rec
    return out


def save_applied(state_dir: Path, records: Mapping[str, Record]) -> None:
    """Write the applied records atomically (raises OSError)."""
    owner = state_owner(Path(state_dir))
    make_private_dir(sync_dir(state_dir), owner)   # as root: through descriptors, no link
    data: dict[str, Any] = {"version": APPLIED_VERSION,
                            "peers": {r.name.lower(): r.to_json() for r in records.values()}}
    path = applied_path(state_dir)
    write_json(path, data, owner)
