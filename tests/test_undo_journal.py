"""The undo journal's handlers per kind of change (core/files/undo_journal): the file writer undoes
what other modules recorded without knowing them, and never drops a change nobody can undo."""

from __future__ import annotations

import pytest

from rosnet_tui.core.files import managed_file as mf
from rosnet_tui.core.files import undo_journal as uj
from rosnet_tui.core.files.managed_text import ManagedFileError


def _entry_with(sd, mappings):
    owner = uj.owner_for(sd)
    with uj.locked(sd, owner):
        entry = uj.JournalEntry(uj.next_id(sd), uj.now(), "test", [], mappings=mappings)
        uj.save_entry(sd, entry, owner)
    return entry


def test_a_registered_handler_undoes_its_kind(tmp_path, monkeypatch):
    seen = []

    def handler(changes, force):
        seen.append((changes, force))
        for c in changes:
            c["state"] = "removed"
        return [f"removed {c['n']}" for c in changes]

    monkeypatch.setitem(uj._UNDO_HANDLERS, "test_kind", handler)
    sd = tmp_path / "state"
    _entry_with(sd, [{"kind": "test_kind", "n": 1}, {"kind": "test_kind", "n": 2}])
    result = mf.undo_last(sd)
    assert result.forwards == ["removed 1", "removed 2"]
    assert seen == [([{"kind": "test_kind", "n": 1, "state": "removed"},
                      {"kind": "test_kind", "n": 2, "state": "removed"}], False)]
    (entry,) = uj.journal_entries(sd)
    assert entry.undone and [m["state"] for m in entry.mappings] == ["removed", "removed"]


def test_a_kind_without_handler_is_refused_and_forgotten_only_with_force(tmp_path):
    sd = tmp_path / "state"
    _entry_with(sd, [{"kind": "nobody_knows", "n": 1}])
    with pytest.raises(ManagedFileError, match="cannot undo"):
        mf.undo_last(sd)
    assert not uj.journal_entries(sd)[0].undone          # nothing was marked undone
    result = mf.undo_last(sd, force=True)
    assert result.forwards == ["1 change(s) of kind 'nobody_knows': forgotten, not undone"]
    assert uj.journal_entries(sd)[0].undone


def test_the_forward_journal_registers_its_undo():
    from rosnet_tui.core.upnp import journal

    assert uj._UNDO_HANDLERS[journal.KIND] is not None


@pytest.mark.parametrize("stored_id", ["\u00b9", "../../victim", "000007"])
def test_an_entry_is_known_by_its_file_name_only(tmp_path, stored_id):
    """The journal is the user's to write: an entry whose stored id is not its file's name (a
    superscript digit int() refuses, a path out of the state dir, another entry's number) is
    damaged and skipped, so the next id never crashes and pruning never deletes by it."""
    import json

    sd = tmp_path / "state"
    victim = tmp_path / "victim"
    victim.mkdir()
    (victim / "keep").write_text("mine")
    good = _entry_with(sd, [])
    bad = {"version": 1, "id": stored_id, "created": "2026-01-01T00:00:00Z", "label": "x",
           "undone": None, "files": []}
    (sd / "journal" / "000002.json").write_text(json.dumps(bad))
    assert [e.id for e in uj.journal_entries(sd)] == [good.id]
    assert uj.next_id(sd) == "000003"          # the damaged file's number is not reused
    uj.prune(sd, keep=0)
    assert (victim / "keep").read_text() == "mine"
