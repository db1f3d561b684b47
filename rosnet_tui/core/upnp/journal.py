"""Forwards we made, in the undo journal (the same one the file writers use).

A forward is recorded in a journal entry of its own (``mappings``, no files) *before* the modem is
asked, with the modem's identity (gateway address, MAC, UPnP device id) and, for PCP, the nonce
that alone can renew or delete it. ``rosnet-tui undo`` (and the wizard's ``u``) removes the last
entry's forwards through the undo handler this module registers with
:mod:`rosnet_tui.core.files.undo_journal`; ``router unmap`` removes every live one; the sync
service renews them. Only recorded forwards are ever removed, and only on the modem they were
made on.
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from pathlib import Path

from rosnet_tui.core.files import undo_journal as uj
from rosnet_tui.core.files.managed_text import ManagedFileError
from rosnet_tui.core.upnp.modem import find_modem
from rosnet_tui.core.upnp.wire import ModemError

KIND = "port_mapping"
UNDO_TIMEOUT_S = 6.0


class ForwardUndoError(ManagedFileError):
    """A recorded forward could not be removed (the modem is gone, or is another one)."""


def new_entry(label: str, mappings: list[dict], state_dir: Path | None = None) -> uj.JournalEntry:
    """Record *mappings* (planned) as a new journal entry and return it."""
    sd = uj.state_dir_path(state_dir)
    owner = uj.owner_for(sd)
    with uj.locked(sd, owner):
        entry = uj.JournalEntry(uj.next_id(sd), uj.now(), label, [],
                                mappings=[{"kind": KIND, **m} for m in mappings])
        uj.save_entry(sd, entry, owner)
    return entry


def save(entry: uj.JournalEntry, state_dir: Path | None = None) -> None:
    sd = uj.state_dir_path(state_dir)
    owner = uj.owner_for(sd)
    with uj.locked(sd, owner):
        uj.save_entry(sd, entry, owner)
        uj.prune(sd)


def close(entry: uj.JournalEntry, note: str, state_dir: Path | None = None) -> None:
    """Mark *entry* done with (undone), saying why."""
    entry.undone = f"{uj.now()} ({note})"
    save(entry, state_dir)


def live(state_dir: Path | None = None) -> list[tuple[uj.JournalEntry, dict]]:
    """Every recorded forward not yet removed, oldest first, with its entry."""
    out = []
    for e in uj.journal_entries(state_dir):
        if e.undone:
            continue
        for m in e.mappings:
            if isinstance(m, dict) and m.get("kind") == KIND and m.get("state") == "made":
                out.append((e, m))
    return out


def describe(m: dict) -> str:
    modem = m.get("modem") or {}
    return (f"{m.get('protocol')} {m.get('port')} -> {m.get('internal_client')}:{m.get('port')} "
            f"on the modem {modem.get('gateway', '?')} ({modem.get('protocol', m.get('via'))})")


def remove_recorded(mappings: Iterable[dict], *, force: bool = False,
                    timeout: float = UNDO_TIMEOUT_S) -> list[str]:
    """Remove recorded forwards from the modem they were made on; what happened, per forward.

    Refuses (ForwardUndoError) when the modem does not answer or is another one; with *force*
    such forwards are forgotten instead (their lease ends them)."""
    todo = [m for m in mappings if isinstance(m, dict) and m.get("kind") == KIND
            and m.get("state") == "made"]
    if not todo:
        return []
    gateway = (todo[0].get("modem") or {}).get("gateway")
    notes: list[str] = []
    deadline = time.monotonic() + timeout
    modem = find_modem(min(timeout / 2, 2.0), notes=notes)
    said: list[str] = []
    for m in todo:
        why = ""
        if modem is None:
            why = f"no modem answers now ({'; '.join(notes[-2:]) or 'nothing tried'})"
        else:
            same, why = modem.same_as(m.get("modem") or {})
            if same and m.get("internal_client") != modem.local_ip:
                same, why = False, (f"this machine is {modem.local_ip} now; the forward points "
                                    f"at {m.get('internal_client')}")
            if same:
                try:
                    said.append(modem.remove(m, max(deadline, time.monotonic() + 1.0)))
                    m["state"] = "removed"
                    continue
                except ModemError as exc:
                    why = str(exc)
        if not force:
            raise ForwardUndoError(
                f"cannot remove {describe(m)}: {why}. Nothing was changed; on the network where "
                f"it was made (gateway {gateway}) run the undo again, or force it to forget the "
                "forward (its lease ends it)")
        m["state"] = "forgotten"
        said.append(f"{m.get('protocol')} {m.get('port')}: forgotten, not removed ({why}); "
                    f"its lease ends it")
    return said


def _undo(mappings: list[dict], force: bool) -> list[str]:
    return remove_recorded(mappings, force=force)


uj.register_undo(KIND, _undo)    # the undo of an entry's forwards (managed_file.apply_undo)
