"""What the sync service last saw and did, kept under the state dir for ``rosnet-tui sync status``
(and the wizard): each component's last record with its age, the last change, the last error."""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

from rosnet_tui.core.files.undo_journal import make_private_dir
from rosnet_tui.core.printable import printable
from rosnet_tui.core.saved.state import read_json, state_owner, sync_dir, write_json
from rosnet_tui.core.saved.sync_records import format_time
from rosnet_tui.core.words import age

STATUS_VERSION = 1
MAX_REFUSED = 20
ALIVE_EVERY_S = 15.0   # the running service refreshes alive_at at least this often


def status_path(state_dir: Path) -> Path:
    return sync_dir(state_dir) / "status.json"


def empty_status() -> dict[str, Any]:
    return {"version": STATUS_VERSION, "name": "", "role": "", "store": "", "store_kind": "",
            "pid": None, "started_at": None, "alive_at": None, "stopped_at": None,
            "interval_s": None, "own": {}, "peers": {}, "profile": "", "last_change": None,
            "last_error": None, "errors": {}, "refused": []}


def load_status(state_dir: Path) -> dict[str, Any] | None:
    """The saved status, or None when sync never ran here (or the file is unreadable)."""
    data = read_json(status_path(state_dir))
    if not isinstance(data, dict) or data.get("version") != STATUS_VERSION:
        return None
    out = empty_status()
    out.update(data)
    return out


def save_status(state_dir: Path, status: dict[str, Any]) -> None:
    owner = state_owner(Path(state_dir))
    make_private_dir(sync_dir(state_dir), owner)   # as root: through descriptors, no link
    write_json(status_path(state_dir), status, owner)


# --------------------------------------------------------------------------- reading it
def _pid_alive(pid: Any) -> bool:
    if not isinstance(pid, int) or pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def service_state(status: dict[str, Any], now: float | None = None) -> str:
    """'running', 'stopped' or 'gone' (died without stopping: killed, or the machine stopped)."""
    now = time.time() if now is None else now
    if status.get("stopped_at"):
        return "stopped"
    alive_at = status.get("alive_at") or 0
    if _pid_alive(status.get("pid")) and now - float(alive_at) < 4 * ALIVE_EVERY_S + 60:
        return "running"
    return "gone"


def _ago(ts: Any, now: float) -> str:
    if not isinstance(ts, (int, float)):
        return "never"
    return f"{age(now - ts, day='d')} ago ({format_time(ts)})"


def _record_line(rec: dict[str, Any] | None) -> str:
    if not rec:
        return "no record yet"
    return (f"{rec.get('role', '?')}: local {rec.get('local_ip') or '?'}, public "
            f"{rec.get('public_ip') or '?'}, record #{rec.get('seq')} written {rec.get('timestamp')}")


def with_ages(status: dict[str, Any], now: float | None = None) -> dict[str, Any]:
    """The status plus computed fields for JSON readers: service state and ages in seconds."""
    now = time.time() if now is None else now
    out = dict(status)
    out["now"] = now
    out["service"] = service_state(status, now)
    peers = {}
    for name, p in (status.get("peers") or {}).items():
        q = dict(p)
        for k, out_k in (("seen_at", "seen_age_s"), ("changed_at", "changed_age_s"),
                         ("record_time", "record_age_s")):
            if isinstance(p.get(k), (int, float)):
                q[out_k] = round(now - p[k], 1)
        peers[name] = q
    out["peers"] = peers
    return out


def render_status(status: dict[str, Any], now: float | None = None) -> list[str]:
    """``sync status`` as lines of text."""
    now = time.time() if now is None else now
    st = service_state(status, now)
    lines = []
    head = {"running": f"running (pid {status.get('pid')})",
            "stopped": f"stopped {_ago(status.get('stopped_at'), now)}",
            "gone": f"not running (pid {status.get('pid')} ended without stopping; "
                    f"last alive {_ago(status.get('alive_at'), now)})"}[st]
    lines.append(f"Sync service: {head}")
    lines.append(f"Store: {status.get('store') or '?'}; public IP polled every "
                 f"{status.get('interval_s')} s")
    own = status.get("own") or {}
    lines.append(f"This component: {status.get('name')} ({status.get('role')})")
    lines.append(f"  addresses now: local {own.get('local_ip') or '?'}, public "
                 f"{own.get('public_ip') or '?'} (public IP checked {_ago(own.get('public_checked_at'), now)})")
    lines.append(f"  published: {_record_line(own.get('record'))}"
                 + (f", {_ago(own.get('published_at'), now)}" if own.get("published_at") else ""))
    peers = status.get("peers") or {}
    lines.append(f"Peers ({len(peers)}), hosts set '{status.get('profile') or '?'}':")
    if not peers:
        lines.append("  none in the settings")
    for name, p in peers.items():
        lines.append(f"  {name}: {_record_line(p.get('record'))}")
        if p.get("record"):
            lines.append(f"    from {p.get('source')}; record age "
                         f"{age(now - p['record_time'], day='d') if isinstance(p.get('record_time'), (int, float)) else '?'}"
                         f", last changed {_ago(p.get('changed_at'), now)}, read {_ago(p.get('seen_at'), now)}")
        if p.get("address"):
            lines.append(f"    hosts entry: {p['address']} {name} ({p.get('why', '')})")
    ch = status.get("last_change")
    if ch:
        lines.append(f"Last change: {_ago(ch.get('at'), now)}: {ch.get('summary')}")
        for c in ch.get("checks") or []:
            lines.append(f"  {c['status'].upper():<4} {c['id']}: {c['summary']}")
    else:
        lines.append("Last change: none since the service started")
    errors = status.get("errors") or {}
    for part, e in errors.items():
        lines.append(f"Failing now ({part}, since {_ago(e.get('since'), now)}): {e.get('message')}"
                     + (f"; next try in about {e['retry_in_s']:.0f} s" if e.get("retry_in_s") else ""))
    le = status.get("last_error")
    if le:
        lines.append(f"Last error: {_ago(le.get('at'), now)}: {le.get('part')}: {le.get('message')}")
    else:
        lines.append("Last error: none")
    refused = status.get("refused") or []
    if refused:
        r = refused[-1]
        lines.append(f"Last refused record: {_ago(r.get('at'), now)}: {r.get('source')}: "
                     f"{r.get('why')} ({len(refused)} kept)")
    # every text here may come from a file name or a record: no control character reaches the
    # terminal (the status file is the user's, read by whoever runs `sync status`)
    return [printable(line) for line in lines]
