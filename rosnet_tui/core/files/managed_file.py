"""Safe edits of system and shell files: our marked block only, previewed, atomic, undoable.

rosnet-tui owns one block per file, between ``# BEGIN rosnet-tui`` and ``# END rosnet-tui``; every
other byte (line endings, tabs, comments, a missing final newline, bytes that are not UTF-8) is kept.

The flow the UI and the CLI share:

1. :func:`preview_block` computes the new content and returns a :class:`Preview` (diff text, the
   digest of the bytes it was computed from). Nothing is written.
2. :func:`apply_preview` writes it: it refuses when the file changed since the preview, keeps a
   backup and a journal entry under the state dir, writes atomically (temp file in the same folder,
   fsync, rename, fsync of the folder), keeps mode, owner and extended attributes, and falls back to
   a verified in-place rewrite where the file is a mount point (``/etc/hosts`` in containers and
   under ``ip netns exec``), where rename fails with EBUSY/EXDEV.
3. :func:`plan_undo` / :func:`apply_undo` put the files of the last apply back, byte for byte.

Applies and undos write through one writer, :func:`rosnet_tui.core.files.managed_write.write_file`. An
in-place rewrite cannot be atomic, so it is journaled first (:mod:`rosnet_tui.core.files.cut_writes`):
a writer killed at any moment leaves the old content, the new one, or a mix of the two with its
journal, and the next run of rosnet-tui completes it before it reads anything (or, as a user who
may not write the file, says it is torn and which command completes it). Temp files of killed
writers (beside the target, in the state dir) are removed by the next run.
"""

from __future__ import annotations

import contextlib
import difflib
import hashlib
import json
import os
import stat
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from rosnet_tui.core.files import nofollow
from rosnet_tui.core.files.cut_writes import INPLACE_DIR
from rosnet_tui.core.files.managed_text import (
    ManagedFileError,
    NothingToUndoError,
    PermissionNeededError,
    StalePreviewError,
    UndoConflictError,
    compose_block,
    decode,
    encode,
    file_digest,
    line_content,
    split_lines,
)
from rosnet_tui.core.files.managed_write import (
    MAX_FILE_BYTES,
    WriteOutcome,
    can_write,
    read_bytes,
    recover_in_place,
    sweep_state_dir,
    write_file,
)
from rosnet_tui.core.files.regular_file import FileRefusedError, read_regular
from rosnet_tui.core.files.undo_journal import (
    JournalEntry,
    JournalFile,
    journal_entries,
    locked,
    make_private_dir,
    next_id,
    now,
    owner_for,
    prune,
    save_entry,
    state_dir_path,
    undo_changes,
    write_private,
)


# --------------------------------------------------------------------------- preview
@dataclass(frozen=True)
class Preview:
    """What a write would do to one file: old and new bytes (None = no file) and why."""

    path: Path
    old: bytes | None
    new: bytes | None
    label: str = ""
    notes: tuple[str, ...] = ()
    new_mode: int = 0o644  # mode of a file we create

    @property
    def digest(self) -> str:
        """Digest of the bytes this preview was computed from; apply refuses if it changed."""
        return file_digest(self.old)

    @property
    def new_digest(self) -> str:
        return file_digest(self.new)

    @property
    def write_digest(self) -> str:
        """Digest of exactly what writing this preview does: the path (as named and as
        resolved), the old and the new bytes, the file's mode and owner now (or the mode of a
        file created). A privileged re-run (sudo) recomputes the preview and writes only when
        this matches the one the user saw, so settings changed since write nothing."""
        real = os.path.realpath(self.path)
        try:
            st = os.stat(real)
            meta: list[int] | None = [stat.S_IMODE(st.st_mode), st.st_uid, st.st_gid]
        except OSError:
            meta = None
        what = {"path": str(Path(self.path).absolute()), "real": real, "old": self.digest,
                "new": self.new_digest, "meta": meta, "new_mode": self.new_mode}
        return "sha256:" + hashlib.sha256(
            json.dumps(what, sort_keys=True).encode()).hexdigest()

    @property
    def changed(self) -> bool:
        return self.old != self.new

    @property
    def needs_privilege(self) -> bool:
        """True when this process may not write the file (it would need sudo)."""
        return self.changed and not can_write(self.path)

    def diff(self, context: int = 3) -> str:
        """A unified diff, printable on any terminal; empty when nothing changes."""
        if not self.changed:
            return ""
        return render_diff(self.old, self.new, str(self.path), context=context)


def render_diff(old: bytes | None, new: bytes | None, name: str, context: int = 3) -> str:
    """Unified diff of two versions of a file, with GNU diff's no-newline and CRLF conventions."""
    a = split_lines(decode(old)) if old is not None else []
    b = split_lines(decode(new)) if new is not None else []
    crlf = any(x.endswith("\r\n") for x in a + b)
    out: list[str] = []
    for line in difflib.unified_diff(a, b, f"{name} (now)" if old is not None else "/dev/null",
                                     f"{name} (after)" if new is not None else "/dev/null",
                                     n=context):
        if line.startswith(("---", "+++", "@@")):
            out.append(line if line.endswith("\n") else line + "\n")
            continue
        if line.endswith("\n"):
            out.append(line_content(line) + "\n")
        else:
            out.append(line + "\n\\ No newline at end of file\n")
    if crlf:
        out.append("(the file uses CRLF line endings; they are kept)\n")
    text = "".join(out)
    return text.encode("utf-8", "backslashreplace").decode("utf-8")


def preview_block(path: Path, body: Sequence[str], *, position: str = "end", label: str = "",
                  notes: Iterable[str] = (), replace_lines: Mapping[int, str] | None = None,
                  new_mode: int = 0o644, current: bytes | None = None,
                  use_current: bool = False) -> Preview:
    """Preview setting our block in *path* to *body*; writes nothing.

    *current* with ``use_current=True`` computes from given bytes instead of reading the file.
    """
    path = Path(path)
    old = current if use_current else read_bytes(path)
    text = decode(old) if old is not None else None
    new = encode(compose_block(text, body, position=position, replace_lines=replace_lines))
    return Preview(path, old, new, label, tuple(notes), new_mode)


@dataclass
class ApplyResult:
    changed: bool
    entry_id: str | None = None
    files: list[WriteOutcome] = field(default_factory=list)
    backups: list[Path] = field(default_factory=list)

    @property
    def in_place(self) -> bool:
        return any(f.in_place for f in self.files)


def apply_previews(previews: Sequence[Preview], *, state_dir: Path | None = None,
                   label: str = "") -> ApplyResult:
    """Write every changed preview, as one journal entry (one ``undo`` restores them all).

    Refuses (StalePreviewError) if any file changed since its preview, and
    (PermissionNeededError) if this process may not write one of them; nothing is written then.
    """
    todo = [p for p in previews if p.changed]
    if not todo:
        for p in previews:
            _check_fresh(p)
        return ApplyResult(False)
    blocked = [p.path for p in todo if not can_write(p.path)]
    if blocked:
        raise PermissionNeededError(
            "this user may not write " + ", ".join(map(str, blocked))
            + "; run the writer with sudo", blocked)
    sd = state_dir_path(state_dir)
    owner = owner_for(sd)
    with locked(sd, owner):
        sweep_state_dir(sd)
        for p in previews:
            # an in-place write of this file cut short, journaled in the state dir
            with contextlib.suppress(OSError):
                recover_in_place(p.path, journal_dir=sd / INPLACE_DIR)
            _check_fresh(p)
        entry = JournalEntry(next_id(sd), now(), label or "; ".join(p.label for p in todo if p.label), [])
        bdir = sd / "backups" / entry.id
        make_private_dir(bdir, owner)
        result = ApplyResult(True, entry.id)
        for i, p in enumerate(todo):
            real = root_target(p.path) if os.geteuid() == 0 else Path(os.path.realpath(p.path))
            st = os.stat(real) if p.old is not None else None
            backup = None
            if st is not None and owner is not None and not readable_by(st, owner):
                raise ManagedFileError(
                    f"{p.path}: its user may not read it, so root keeps no copy of it in that "
                    f"user's {sd}; nothing was written")
            if p.old is not None:
                bpath = bdir / f"{i}-{real.name}"
                write_private(bpath, p.old, owner)
                backup = str(bpath.relative_to(sd))
                result.backups.append(bpath)
            entry.files.append(JournalFile(
                path=str(Path(p.path).absolute()), real_path=str(real), existed=p.old is not None,
                backup=backup, before=p.digest, after=p.new_digest,
                mode=stat.S_IMODE(st.st_mode) if st else None,
                uid=st.st_uid if st else None, gid=st.st_gid if st else None))
        save_entry(sd, entry, owner)  # before any write: a crash leaves an undoable record
        done: list[int] = []
        try:
            for i, p in enumerate(todo):
                outcome = write_file(p.path, p.new, new_mode=p.new_mode,
                                     journal_dir=sd / INPLACE_DIR)
                entry.files[i].in_place = outcome.in_place
                result.files.append(outcome)
                done.append(i)
        except BaseException as exc:
            # The file being written when it failed may be half written (in place): put back
            # too (its journal is completed first), so no file keeps an apply marked undone.
            cut = len(done)
            if cut < len(todo):
                with contextlib.suppress(Exception):
                    if file_digest(read_bytes(todo[cut].path)) != entry.files[cut].before:
                        done = [*done, cut]
            _roll_back(sd, entry, done)
            entry.undone = now() + " (rolled back: the apply failed)"
            with contextlib.suppress(Exception):
                save_entry(sd, entry, owner)
            if isinstance(exc, PermissionError):
                raise PermissionNeededError(f"this user may not write {exc.filename}",
                                            [Path(exc.filename or "")]) from exc
            if isinstance(exc, OSError) and not isinstance(exc, ManagedFileError):
                raise ManagedFileError(f"could not write {exc.filename}: {exc.strerror}; "
                                       "nothing was changed") from exc
            raise
        save_entry(sd, entry, owner)
        prune(sd)
        return result


def apply_preview(preview: Preview, *, state_dir: Path | None = None) -> ApplyResult:
    """Write one preview (see :func:`apply_previews`)."""
    return apply_previews([preview], state_dir=state_dir, label=preview.label)


def _check_fresh(p: Preview) -> None:
    now = file_digest(read_bytes(p.path))
    if now != p.digest:
        raise StalePreviewError(
            f"{p.path} changed since the preview was made (someone else edited it); "
            "nothing was written: look at the new preview and apply again")


def _backup_path(sd: Path, f: JournalFile) -> Path | None:
    if not f.backup:
        return None
    b = (sd / f.backup).resolve()
    if not b.is_relative_to(sd.resolve()):
        raise ManagedFileError(f"the journal names a backup outside {sd}: refused")
    return b


def _read_backup(sd: Path, f: JournalFile) -> bytes | None:
    """The backup's bytes (None: the file did not exist before the apply). A backup that is
    missing, not a regular file or too big is refused (ManagedFileError), never waited on."""
    b = _backup_path(sd, f)
    if b is None:
        return None
    try:
        return read_regular(b, MAX_FILE_BYTES)
    except FileNotFoundError:
        raise ManagedFileError(f"the backup {b} is missing; {f.path} was left as it is") from None
    except FileRefusedError as exc:
        raise ManagedFileError(f"the backup {exc}; {f.path} was left as it is") from None
    except OSError as exc:
        raise ManagedFileError(f"cannot read the backup {b}: {exc.strerror}; {f.path} was left "
                               "as it is") from None


# Files root may restore from a journal that a normal user owns (sudo): the system files we write.
ROOT_RESTORABLE = ("/etc/hosts",)


def root_target(path: Path) -> Path:
    """Where root writing *path* lands: links followed only when root's own (a user's link is
    refused: :class:`~rosnet_tui.core.files.nofollow.LinkRefusedError`)."""
    return nofollow.resolve(Path(path))[0]


def readable_by(st: os.stat_result, owner: tuple[int, int]) -> bool:
    """Whether the user *owner* (uid, gid) may read a file of stat *st* (supplementary groups
    not counted: when in doubt, no)."""
    mode = st.st_mode
    return bool(mode & 0o004 or (st.st_uid == owner[0] and mode & 0o400)
                or (st.st_gid == owner[1] and mode & 0o040))


def _check_root_safe(sd: Path, entry: JournalEntry) -> None:
    """Root undoing from a user's journal (which that user may have written anything into)
    restores only the system files rosnet-tui writes, by their own names, and files in that
    user's folders that are the user's, reached without following the user's links."""
    owner = owner_for(sd)
    if owner is None:
        return
    for f in entry.files:
        if f.real_path in ROOT_RESTORABLE:
            continue
        try:
            real = root_target(Path(f.real_path))
            mine = os.lstat(real).st_uid == owner[0]
        except FileNotFoundError:
            mine = False
        if not mine:
            raise ManagedFileError(
                f"as root, undo from a user's journal restores only {', '.join(ROOT_RESTORABLE)}"
                f" and that user's files; not {f.real_path}")


def _restore_one(sd: Path, f: JournalFile) -> None:
    data = _read_backup(sd, f)
    if data is not None and file_digest(data) != f.before:
        raise ManagedFileError(f"the backup {_backup_path(sd, f)} is damaged (digest mismatch); "
                               f"{f.path} was left as it is")
    if owner_for(sd) is not None:
        # root, from a user's journal: the mode and owner it sees itself, never the entry's
        write_file(Path(f.real_path), data, journal_dir=sd / INPLACE_DIR)
        return
    write_file(Path(f.real_path), data, mode=f.mode, uid=f.uid, gid=f.gid,
               journal_dir=sd / INPLACE_DIR)


def _roll_back(sd: Path, entry: JournalEntry, done: Iterable[int]) -> None:
    for i in done:
        with contextlib.suppress(Exception):
            _restore_one(sd, entry.files[i])


# --------------------------------------------------------------------------- undo
@dataclass
class UndoPlan:
    """What undo would do: the entry and, per file, a preview from now back to the backup."""

    state_dir: Path
    entry: JournalEntry
    previews: list[Preview]
    conflicts: list[str]  # files someone changed after our apply (undo needs force)

    @property
    def needs_privilege(self) -> bool:
        # "nft_table": firewall.KIND (core/exposure, a floor above: not imported here)
        nft = any(kind == "nft_table" for kind, _change in self.entry.made())
        return any(p.needs_privilege for p in self.previews) or (nft and os.geteuid() != 0)

    def diff(self) -> str:
        return "".join(p.diff() for p in self.previews)


@dataclass
class UndoResult:
    entry_id: str
    label: str
    files: list[Path]
    forwards: list[str] = field(default_factory=list)  # what happened to the entry's forwards


def last_entry(state_dir: Path | None = None) -> JournalEntry | None:
    """The most recent apply that was not undone, or None."""
    live = [e for e in journal_entries(state_dir) if not e.undone]
    return live[-1] if live else None


def plan_undo(state_dir: Path | None = None, *, entry_id: str | None = None) -> UndoPlan:
    """Preview undoing the last apply (or *entry_id*, which must be the last one)."""
    sd = state_dir_path(state_dir)
    entry = last_entry(sd)
    if entry is None:
        raise NothingToUndoError("nothing to undo: every recorded change was undone already "
                                 "(or rosnet-tui never wrote a file here)")
    if entry_id is not None and entry.id != entry_id:
        raise StalePreviewError(f"the last change is now #{entry.id}, not #{entry_id}; "
                                "look at the new preview and try again")
    sweep_state_dir(sd)
    _check_root_safe(sd, entry)     # before root reads anything the entry names
    previews, conflicts = [], []
    for f in entry.files:
        with contextlib.suppress(OSError):
            recover_in_place(Path(f.real_path), journal_dir=sd / INPLACE_DIR)
        current = read_bytes(Path(f.real_path))
        target = _read_backup(sd, f)
        digest = file_digest(current)
        if digest not in (f.after, f.before):
            conflicts.append(f.path)
        previews.append(Preview(Path(f.path), current, target,
                                f"undo #{entry.id}: {entry.label}".rstrip(": "),
                                new_mode=f.mode if f.mode is not None else 0o644))
    return UndoPlan(sd, entry, previews, conflicts)


def apply_undo(plan: UndoPlan, *, force: bool = False) -> UndoResult:
    """Restore the files of *plan* byte for byte and mark its entry undone."""
    if plan.conflicts and not force:
        raise UndoConflictError(
            "changed by someone else after rosnet-tui wrote it: " + ", ".join(plan.conflicts)
            + "; undoing would lose that change (force it to restore anyway)")
    blocked = [p.path for p in plan.previews if p.needs_privilege]
    if blocked:
        raise PermissionNeededError("this user may not write " + ", ".join(map(str, blocked))
                                    + "; run undo with sudo", blocked)
    sd = plan.state_dir
    owner = owner_for(sd)
    _check_root_safe(sd, plan.entry)
    with locked(sd, owner):
        current = last_entry(sd)
        if current is None or current.id != plan.entry.id:
            raise StalePreviewError("the journal changed since the undo preview; try again")
        for p in plan.previews:
            _check_fresh(p)
        forwards: list[str] = []
        if plan.entry.mappings:  # forwards on the modem, our firewall table: each kind's undo
            forwards = undo_changes(plan.entry, force=force)
        restored = []
        for p, f in zip(plan.previews, plan.entry.files, strict=True):
            if p.changed:
                _restore_one(sd, f)
            if file_digest(read_bytes(Path(f.real_path))) != f.before:
                raise ManagedFileError(f"{f.path}: restored content does not match the backup")
            restored.append(Path(f.path))
        plan.entry.undone = now()
        save_entry(sd, plan.entry, owner)
        return UndoResult(plan.entry.id, plan.entry.label, restored, forwards)


def undo_last(state_dir: Path | None = None, *, force: bool = False) -> UndoResult:
    """Undo the last apply in one call (plan + apply)."""
    return apply_undo(plan_undo(state_dir), force=force)
