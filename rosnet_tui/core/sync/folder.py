"""The folder store: one small JSON record per component in a folder a file-sync tool shares.

``<folder>/<name>.json`` is written atomically (temp file in the same folder, fsync, rename).
Sync tools leave other copies beside it: Syncthing's ``name.sync-conflict-DATE-ID.json``,
Dropbox's and Nextcloud's ``name (conflicted copy DATE).json``, and half-transferred files. Every
copy whose file name starts with a component's name is read; malformed ones are refused (with the
reason), valid ones compete by seq then timestamp (:func:`records.choose_best`).
"""

from __future__ import annotations

import contextlib
import os
import re
import stat
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rosnet_tui.core.files.regular_file import FileRefusedError, read_regular
from rosnet_tui.core.saved.settings import atomic_write_text
from rosnet_tui.core.saved.sync_records import (
    MAX_RECORD_BYTES,
    Candidate,
    Record,
    RecordError,
    parse_record,
)

from .store import FetchResult, Refusal, StoreError

MAX_FILES = 2000        # entries of the folder looked at (a shared folder may hold other things)
SUFFIX = ".json"
# After the name: the end, or a separator that sync tools put before their conflict tag.
_AFTER_NAME = re.compile(r"^(?:$|[ ._~(-])")


def record_file_name(name: str) -> str:
    return f"{name}{SUFFIX}"


def copy_owner(file_name: str, names: Iterable[str]) -> str | None:
    """Which of *names* a file in the folder is a copy of (the longest name that fits), or None.

    ``turtlebot.json``, ``turtlebot.sync-conflict-20250101-120000-ABC.json`` and
    ``turtlebot (conflicted copy 2025-01-01).json`` are all copies of turtlebot's record.
    """
    if file_name.startswith(".") or not file_name.lower().endswith(SUFFIX):
        return None
    stem = file_name[: -len(SUFFIX)]
    best = None
    for n in names:
        if stem.lower().startswith(n.lower()) and _AFTER_NAME.match(stem[len(n):]):
            if best is None or len(n) > len(best):
                best = n
    return best


@dataclass
class _Cached:
    key: tuple[int, int, int]    # (mtime_ns, size, inode)
    result: Record | RecordError


class FolderStore:
    kind = "folder"

    def __init__(self, folder: Path) -> None:
        self.folder = Path(folder)
        self._cache: dict[str, _Cached] = {}

    def describe(self) -> str:
        return f"folder {self.folder}"

    # ------------------------------------------------------------------ the folder itself
    def _ensure_folder(self, create: bool) -> None:
        try:
            st = os.stat(self.folder)
        except FileNotFoundError:
            parent = self.folder.parent
            if create and parent.is_dir():
                try:
                    self.folder.mkdir(mode=0o755)
                    return
                except OSError as exc:
                    raise StoreError(f"cannot create the shared folder {self.folder}: "
                                     f"{exc.strerror}") from None
            raise StoreError(f"the shared folder {self.folder} does not exist (is it mounted, "
                             "is the sync tool running?)") from None
        except OSError as exc:
            raise StoreError(f"cannot reach the shared folder {self.folder}: {exc.strerror}") \
                from None
        if not stat.S_ISDIR(st.st_mode):
            raise StoreError(f"{self.folder} is not a folder")

    # ------------------------------------------------------------------ publish
    def publish(self, record: Record) -> None:
        self._ensure_folder(create=True)
        path = self.folder / record_file_name(record.name)
        try:
            atomic_write_text(path, record.to_text(), mode=0o644)
        except OSError as exc:
            raise StoreError(f"cannot write {path}: {exc.strerror or exc}") from None

    def remove_stale_copies(self, name: str, keep: Record) -> list[str]:
        """Delete this component's own conflict copies that *keep* supersedes; their names."""
        removed = []
        canonical = record_file_name(name)
        for entry in self._entries():
            if entry.name == canonical or copy_owner(entry.name, [name]) != name:
                continue
            rec = self._read(entry)
            if isinstance(rec, Record) and rec.name.lower() == name.lower() \
                    and rec.rank <= keep.rank:
                with contextlib.suppress(OSError):
                    os.unlink(entry.path)
                    removed.append(entry.name)
        return removed

    # ------------------------------------------------------------------ fetch
    def _entries(self) -> list[os.DirEntry]:
        try:
            with os.scandir(self.folder) as it:
                out = []
                for i, e in enumerate(it):
                    if i >= MAX_FILES:
                        break
                    out.append(e)
                return out
        except FileNotFoundError:
            raise StoreError(f"the shared folder {self.folder} does not exist (is it mounted, "
                             "is the sync tool running?)") from None
        except OSError as exc:
            raise StoreError(f"cannot list the shared folder {self.folder}: {exc.strerror}") \
                from None

    def _read(self, entry: os.DirEntry) -> Record | RecordError:
        try:
            st = entry.stat(follow_symlinks=False)
        except OSError as exc:
            return RecordError(f"cannot stat it: {exc.strerror}")
        key = (st.st_mtime_ns, st.st_size, st.st_ino)
        cached = self._cache.get(entry.path)
        if cached is not None and cached.key == key:
            return cached.result
        result: Record | RecordError
        if not stat.S_ISREG(st.st_mode):
            result = RecordError("not a regular file")
        elif st.st_size > MAX_RECORD_BYTES:
            result = RecordError(f"too big ({st.st_size} bytes)")
        else:
            try:   # swapped for a FIFO since the stat: refused, never waited on
                result = parse_record(read_regular(entry.path, MAX_RECORD_BYTES))
            except RecordError as exc:
                result = exc
            except FileRefusedError as exc:
                result = RecordError(exc.why)
            except OSError as exc:
                result = RecordError(f"cannot read it: {exc.strerror}")
            except Exception as exc:  # noqa: BLE001 - one bad file never stops the others
                result = RecordError(f"cannot be read as a record ({type(exc).__name__})")
        self._cache[entry.path] = _Cached(key, result)
        return result

    def fetch(self, names: Iterable[str], own_name: str,
              keys: Mapping[str, Any]) -> FetchResult:
        self._ensure_folder(create=False)
        names = list(dict.fromkeys([*names, own_name]))
        copies: dict[str, list[Candidate]] = {n: [] for n in names}
        out = FetchResult(keys=keys)
        seen = set()
        for entry in self._entries():
            owner = copy_owner(entry.name, names)
            if owner is None:
                continue
            seen.add(entry.path)
            rec = self._read(entry)
            if isinstance(rec, RecordError):
                out.refused.append(Refusal(entry.name, owner, str(rec)))
                continue
            if rec.name.lower() != owner.lower():
                if copy_owner(entry.name, [rec.name]) == rec.name:
                    continue  # another component's record (its name starts like ours)
                out.refused.append(Refusal(entry.name, owner,
                                           f"it names {rec.name!r}, not {owner!r}"))
                continue
            copies[owner].append(Candidate(rec, entry.name))
        for path in list(self._cache):
            if path not in seen:
                del self._cache[path]
        for n, cands in copies.items():
            out.add_copies(n, cands, own_name)
        return out
