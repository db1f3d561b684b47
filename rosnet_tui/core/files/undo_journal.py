"""The undo journal: one entry per apply, under the state dir, and who undoes what.

An entry (``journal/NNNNNN.json``) lists the files an apply wrote (with their backups, written by
:mod:`rosnet_tui.core.files.managed_file`) and any other changes it made (``mappings``: dicts with a
``kind``, such as a port forward on the modem). A module that records changes of its own kind
registers how to undo them (:func:`register_undo`); :func:`undo_changes` runs the handlers for an
entry, so this module and the file writer know nothing of what those changes are.

Entries and backups are private state files (0600, temp + fsync + rename, never through a link);
one writer at a time per state dir (:func:`locked`). Root writing a user's state dir (sudo) hands
what it creates back to that user.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

from rosnet_tui.core.config.paths import default_state_dir
from rosnet_tui.core.files import nofollow
from rosnet_tui.core.files.managed_text import ManagedFileError
from rosnet_tui.core.files.managed_write import (
    LOCK_TIMEOUT_S,
    MAX_FILE_BYTES,
    atomic_write,
)
from rosnet_tui.core.files.regular_file import read_regular
from rosnet_tui.core.jsonsafe import loads_bounded

JOURNAL_KEEP = 100  # applies remembered for undo; older ones (and their backups) are dropped

# --------------------------------------------------------------------------- journal
@dataclass
class JournalFile:
    path: str            # as the user named it
    real_path: str       # symlinks resolved: what was written
    existed: bool
    backup: str | None   # relative to the state dir
    before: str          # digest before our apply
    after: str           # digest after it
    mode: int | None = None
    uid: int | None = None
    gid: int | None = None
    in_place: bool = False


@dataclass
class JournalEntry:
    id: str
    created: str
    label: str
    files: list[JournalFile]
    undone: str | None = None
    version: int = 1
    # Things changed outside files (port forwards on the modem: rosnet_tui.core.upnp.journal),
    # each a dict with a "kind"; undone by the handler registered for that kind.
    mappings: list[dict] = field(default_factory=list)

    def kinds(self) -> list[str]:
        """The kinds of its changes outside files, in the order they were recorded."""
        return list(dict.fromkeys(str(m.get("kind")) for m in self.mappings))

    def made(self) -> list[tuple[str, dict]]:
        """Its changes outside files still in effect, each with its kind, in recorded order:
        each kind's handler marks a change "made" when it makes it and moves it on when it is
        undone or lost."""
        return [(str(m.get("kind")), m) for m in self.mappings if m.get("state") == "made"]

    def to_json(self) -> dict:
        d = {"version": self.version, "id": self.id, "created": self.created,
             "label": self.label, "undone": self.undone,
             "files": [f.__dict__ for f in self.files]}
        if self.mappings:
            d["mappings"] = self.mappings
        return d

    @classmethod
    def from_json(cls, d: dict) -> JournalEntry:
        return cls(id=str(d["id"]), created=str(d.get("created", "")),
                   label=str(d.get("label", "")), undone=d.get("undone"),
                   files=[JournalFile(**f) for f in d.get("files", [])],
                   version=int(d.get("version", 1)),
                   mappings=[m for m in d.get("mappings") or [] if isinstance(m, dict)])


def state_dir_path(state_dir: Path | None) -> Path:
    if state_dir is None:
        state_dir = default_state_dir()
    return Path(state_dir).expanduser().absolute()


def owner_for(state_dir: Path) -> tuple[int, int] | None:
    """Root writing a user's state dir (sudo) hands what it creates back to that user."""
    if os.geteuid() != 0:
        return None
    p = state_dir
    while not p.exists() and p != p.parent:
        p = p.parent
    try:
        st = os.stat(p)
    except OSError:
        return None
    return (st.st_uid, st.st_gid) if st.st_uid != 0 else None


def make_private_dir(path: Path, owner: tuple[int, int] | None) -> None:
    """Make the folder *path* (0700; the folders made handed to *owner*). Root does it through
    descriptors, following no link that is not root's own (:mod:`.nofollow`)."""
    if os.geteuid() == 0:
        nofollow.make_dir(path, 0o700, owner)
        return
    missing = []
    p = path
    while not p.exists():
        missing.append(p)
        p = p.parent
    for d in reversed(missing):
        with contextlib.suppress(FileExistsError):
            os.mkdir(d, 0o700)
        if owner:
            with contextlib.suppress(OSError):
                os.chown(d, *owner)
    if path.is_symlink() or not path.is_dir():
        raise ManagedFileError(f"{path} must be a folder (not a link)")


def write_private(path: Path, data: bytes, owner: tuple[int, int] | None) -> None:
    """Write a state file (journal, backup) atomically, 0600, handed to *owner* (if any)."""
    atomic_write(path, data, create_mode=0o600, uid=owner[0] if owner else None,
                 gid=owner[1] if owner else None, owner_errors=(OSError,))


@contextlib.contextmanager
def locked(state_dir: Path, owner: tuple[int, int] | None,
            timeout_s: float = LOCK_TIMEOUT_S) -> Iterator[None]:
    """One writer at a time per state dir (bounded wait)."""
    make_private_dir(state_dir, owner)
    lock = state_dir / "lock"
    fd = nofollow.open_lock(state_dir, "lock", owner)
    try:
        if not nofollow.flock_within(fd, timeout_s, 0.05):
            raise ManagedFileError(f"another rosnet-tui is writing (lock {lock} held for "
                                   f"{timeout_s:g} s); try again when it is done")
        yield
    finally:
        os.close(fd)


def journal_entries(state_dir: Path | None = None) -> list[JournalEntry]:
    """Every recorded apply, oldest first (undone ones included, marked)."""
    folder = state_dir_path(state_dir) / "journal"
    out = []
    names = _entry_names(folder)
    for n in names:
        try:
            raw = read_regular(folder / n, MAX_FILE_BYTES).decode("utf-8")
            entry = JournalEntry.from_json(loads_bounded(raw, unique_keys=False))
        except (OSError, ValueError, TypeError, KeyError, AttributeError):
            continue  # a damaged entry is skipped, never trusted
        if entry.id == n[:-len(".json")]:    # known by its file's name only (ids make paths)
            out.append(entry)
    return out


def _entry_names(folder: Path) -> list[str]:
    """The journal's entry files, oldest first: ``NNNNNN.json``, ASCII digits."""
    try:
        return sorted(n for n in os.listdir(folder) if re.fullmatch(r"[0-9]{6,}\.json", n))
    except FileNotFoundError:
        return []
    except NotADirectoryError:
        raise ManagedFileError(f"{folder.parent} is not a folder: it cannot be the state "
                               "dir") from None
    except OSError as exc:
        raise ManagedFileError(f"cannot read the journal in {folder}: {exc.strerror}") from None


def next_id(state_dir: Path) -> str:
    names = _entry_names(state_dir_path(state_dir) / "journal")   # damaged ones too: never reused
    n = max((int(name[:-len(".json")]) for name in names), default=0) + 1
    return f"{n:06d}"


def save_entry(state_dir: Path, entry: JournalEntry, owner: tuple[int, int] | None) -> None:
    folder = state_dir / "journal"
    make_private_dir(folder, owner)
    write_private(folder / f"{entry.id}.json",
                   (json.dumps(entry.to_json(), indent=2) + "\n").encode(), owner)


def prune(state_dir: Path, keep: int | None = None) -> None:
    """Forget the oldest entries (and their backups) beyond the *keep* (default
    :data:`JOURNAL_KEEP`) most recent."""
    import shutil

    keep = JOURNAL_KEEP if keep is None else keep
    for e in journal_entries(state_dir)[:-keep]:
        with contextlib.suppress(OSError):
            shutil.rmtree(state_dir / "backups" / e.id)
            os.unlink(state_dir / "journal" / f"{e.id}.json")


def now() -> str:
    return datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


# --------------------------------------------------------------------------- undo of other changes
UndoHandler = Callable[[list[dict], bool], list[str]]
_UNDO_HANDLERS: dict[str, UndoHandler] = {}


def record_entry(label: str, records: list[dict], *, state_dir: Path | None = None) -> str:
    """Journal a change that is not a file (each record a dict with a ``kind`` whose undo is
    registered); the new entry's id."""
    sd = state_dir_path(state_dir)
    owner = owner_for(sd)
    with locked(sd, owner):
        entry = JournalEntry(next_id(sd), now(), label, [], mappings=list(records))
        save_entry(sd, entry, owner)
        prune(sd)
    return entry.id


def register_undo(kind: str, handler: UndoHandler) -> None:
    """Say how changes of *kind* (``mappings`` with that ``kind``) are undone: *handler* gets the
    entry's changes of that kind and ``force``, undoes them (updating their dicts), and returns
    one line per change on what happened; it raises ManagedFileError to refuse."""
    _UNDO_HANDLERS[kind] = handler


def undo_changes(entry: JournalEntry, *, force: bool = False) -> list[str]:
    """Undo an entry's non-file changes, kind by kind in the order they were recorded.

    A kind nobody registered a handler for is refused (ManagedFileError), or with *force*
    forgotten: the entry is never marked undone while something it made is left unsaid."""
    kinds: dict[str, list[dict]] = {}
    for m in entry.mappings:
        kinds.setdefault(str(m.get("kind")), []).append(m)
    said: list[str] = []
    for kind, changes in kinds.items():
        handler = _UNDO_HANDLERS.get(kind)
        if handler is None:
            if not force:
                raise ManagedFileError(f"entry #{entry.id} holds {len(changes)} change(s) of kind "
                                       f"{kind!r} that this program cannot undo; nothing was "
                                       "changed (force it to forget them)")
            said.append(f"{len(changes)} change(s) of kind {kind!r}: forgotten, not undone")
            continue
        said.extend(handler(changes, force))
    return said
