"""Watching the folder store, so a peer's record is read as soon as it is complete (issue 17).

Linux's inotify, through the kernel interface itself (``inotify_init1``/``inotify_add_watch`` by
ctypes, events read from the descriptor): no dependency, and the descriptor sits in the service's
selector beside netlink and the wake pipe.

Only a finished record wakes the service: a file under a record's name (``*.json``, not hidden)
closed after writing (IN_CLOSE_WRITE) or moved into place (IN_MOVED_TO), or a record that went
away (IN_DELETE, IN_MOVED_FROM). Partial writes (IN_MODIFY) are not watched, and sync tools'
temporary files never match a record's name (rsync's and our writer's ``.name.json.XXXXXX``,
Syncthing's ``.syncthing.name.json.tmp`` and ``~syncthing~name.json.tmp``), so no event makes
the service read half a file.

Watching is impossible, and the service reads the folder on its timer instead, when inotify is
refused (no inotify, too many instances or watches: EMFILE, ENOSPC), when the folder does not
exist (yet), and on network and FUSE file systems (NFS, SMB, sshfs...), where a watch is accepted
but never reports what other machines write. :class:`StoreWatch` tries again every
``RETRY_S`` and says in the log which way the folder is read, and why.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import logging
import os
import selectors
import struct
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

log = logging.getLogger("rosnet_tui.sync")

# linux/inotify.h
IN_CLOSE_WRITE = 0x00000008
IN_MOVED_FROM = 0x00000040
IN_MOVED_TO = 0x00000080
IN_DELETE = 0x00000200
IN_DELETE_SELF = 0x00000400
IN_MOVE_SELF = 0x00000800
IN_UNMOUNT = 0x00002000
IN_Q_OVERFLOW = 0x00004000
IN_IGNORED = 0x00008000
IN_ONLYDIR = 0x01000000
IN_EXCL_UNLINK = 0x04000000
IN_ISDIR = 0x40000000

COMPLETE = IN_CLOSE_WRITE | IN_MOVED_TO          # a record is there, whole
GONE = IN_DELETE | IN_MOVED_FROM                  # a record went away
FOLDER_GONE = IN_DELETE_SELF | IN_MOVE_SELF | IN_UNMOUNT | IN_IGNORED
WATCH_MASK = COMPLETE | GONE | IN_DELETE_SELF | IN_MOVE_SELF | IN_ONLYDIR | IN_EXCL_UNLINK

_EVENT = struct.Struct("iIII")      # wd, mask, cookie, len (then len bytes of NUL-padded name)
_READ_SIZE = 64 * 1024              # at least a thousand events per read
_MAX_READS = 32                     # reads per drain: a storm of events cannot hold the loop
RETRY_S = 5.0                       # how often an unwatched folder is tried again

# Where a watch is accepted but changes made by other machines are never reported.
REMOTE_FS = frozenset({
    "nfs", "nfs4", "cifs", "smb3", "smbfs", "ncpfs", "afs", "ceph", "9p", "virtiofs", "vboxsf",
    "vmhgfs", "prl_fs", "lustre", "gpfs", "ocfs2", "gfs2", "glusterfs", "coda", "orangefs",
    "beegfs", "davfs", "fuse"})


class WatchUnavailable(Exception):
    """The folder cannot be watched here; says why."""


def is_record_name(name: str) -> bool:
    """Whether a file name can be a record or a copy of one (what the folder store reads)."""
    return not name.startswith((".", "~")) and name.lower().endswith(".json")


def is_remote_fs(fstype: str) -> bool:
    return fstype in REMOTE_FS or fstype.startswith("fuse.")


def _unescape(field: str) -> str:
    # mountinfo writes space, tab, newline and backslash as \040 \011 \012 \134
    out, i = [], 0
    while i < len(field):
        if field[i] == "\\" and i + 3 < len(field) and field[i + 1:i + 4].isdigit():
            out.append(chr(int(field[i + 1:i + 4], 8)))
            i += 4
        else:
            out.append(field[i])
            i += 1
    return "".join(out)


def mount_fs_type(path: Path, mountinfo: str | None = None) -> str:
    """The file system type of the mount holding *path* ("" when unknown), from the mount table
    of this process's mount namespace (``/proc/self/mountinfo``)."""
    if mountinfo is None:
        try:
            mountinfo = Path("/proc/self/mountinfo").read_text(errors="replace")
        except OSError:
            return ""
    target = os.path.realpath(path)
    best_len, best_type = -1, ""
    for line in mountinfo.splitlines():
        fields = line.split()
        if len(fields) < 7 or "-" not in fields[6:]:
            continue
        mount_point = _unescape(fields[4])
        sep = fields.index("-", 6)
        if sep + 1 >= len(fields):
            continue
        inside = (target == mount_point or mount_point == "/"
                  or target.startswith(mount_point.rstrip("/") + "/"))
        # the longest mount point wins; of equal ones the later (mounted over the earlier)
        if inside and len(mount_point) >= best_len:
            best_len, best_type = len(mount_point), fields[sep + 1]
    return best_type


# --------------------------------------------------------------------------- the kernel side
_libc: Any = None


def _inotify_functions() -> tuple[Any, Any]:
    global _libc
    if _libc is None:
        try:
            lib = ctypes.CDLL(None, use_errno=True)
            lib.inotify_init1.argtypes = [ctypes.c_int]
            lib.inotify_init1.restype = ctypes.c_int
            lib.inotify_add_watch.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_uint32]
            lib.inotify_add_watch.restype = ctypes.c_int
        except (OSError, AttributeError):
            lib = False
        _libc = lib
    if _libc is False:
        raise WatchUnavailable("this system has no inotify")
    return _libc.inotify_init1, _libc.inotify_add_watch


def _why(err: int, what: str) -> str:
    hints = {errno.EMFILE: "too many inotify instances or open files "
                           "(fs.inotify.max_user_instances)",
             errno.ENFILE: "too many open files on the system",
             errno.ENOSPC: "no inotify watches left (fs.inotify.max_user_watches)",
             errno.ENOENT: "it does not exist", errno.ENOTDIR: "it is not a folder",
             errno.EACCES: "permission denied", errno.ENOSYS: "inotify is not available"}
    return f"{what}: {hints.get(err, os.strerror(err))}"


@dataclass(frozen=True)
class Drained:
    changed: bool                 # a record was completed or removed (or events were lost)
    lost: bool                    # the watch ended (folder deleted, moved, unmounted)
    names: tuple[str, ...] = ()   # the records' file names that changed (at most a few)


class FolderWatch:
    """An inotify descriptor watching one folder; readable when something happened in it."""

    def __init__(self, fd: int, folder: Path, key: tuple[int, int]) -> None:
        self.fd = fd
        self.folder = folder
        self.key = key            # (st_dev, st_ino) of the watched folder

    @classmethod
    def open(cls, folder: Path, *, check_fs: bool = True) -> FolderWatch:
        """Watch *folder*; raises WatchUnavailable (with the reason) where that is impossible."""
        folder = Path(folder)
        try:
            st = os.stat(folder)
        except OSError as exc:
            raise WatchUnavailable(_why(exc.errno or 0, "the folder cannot be reached")) from None
        if check_fs:
            fstype = mount_fs_type(folder)
            if is_remote_fs(fstype):
                raise WatchUnavailable(f"it is on {fstype}, where a watch never hears of "
                                       "changes made by other machines")
        init1, add_watch = _inotify_functions()
        fd = init1(os.O_NONBLOCK | os.O_CLOEXEC)
        if fd < 0:
            raise WatchUnavailable(_why(ctypes.get_errno(), "inotify refused"))
        try:
            wd = add_watch(fd, os.fsencode(folder), WATCH_MASK)
            if wd < 0:
                raise WatchUnavailable(_why(ctypes.get_errno(), "inotify refused the watch"))
            st2 = os.stat(folder)
            if (st2.st_dev, st2.st_ino) != (st.st_dev, st.st_ino):
                raise WatchUnavailable("the folder was replaced while the watch was set up")
        except BaseException:
            os.close(fd)
            raise
        return cls(fd, folder, (st.st_dev, st.st_ino))

    def fileno(self) -> int:
        return self.fd

    def still_valid(self) -> bool:
        """The path still leads to the watched folder (not replaced, not remounted)."""
        try:
            st = os.stat(self.folder)
        except OSError:
            return False
        return (st.st_dev, st.st_ino) == self.key

    def drain(self) -> Drained:
        """Read what is pending (bounded) and say what it means for the records."""
        changed = lost = False
        names: list[str] = []
        for _ in range(_MAX_READS):
            try:
                data = os.read(self.fd, _READ_SIZE)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                lost = True
                break
            if not data:
                break
            off = 0
            while off + _EVENT.size <= len(data):
                _wd, mask, _cookie, length = _EVENT.unpack_from(data, off)
                raw = data[off + _EVENT.size: off + _EVENT.size + length]
                off += _EVENT.size + length
                if mask & IN_Q_OVERFLOW:
                    changed = True          # events were dropped: read the folder anyway
                    continue
                if mask & FOLDER_GONE:
                    lost = True
                    continue
                if mask & IN_ISDIR or not mask & (COMPLETE | GONE):
                    continue
                name = os.fsdecode(raw.split(b"\0", 1)[0])
                if is_record_name(name):
                    changed = True
                    if len(names) < 8 and name not in names:
                        names.append(name)
        return Drained(changed or lost, lost, tuple(names))

    def close(self) -> None:
        if self.fd >= 0:
            with contextlib.suppress(OSError):
                os.close(self.fd)
            self.fd = -1


# --------------------------------------------------------------------------- for the service
class StoreWatch:
    """The service's side: keeps a watch on the store's folder while it has one (a folder store
    on a local file system), registered in the loop's selector under ``"folder"``; tries again
    every RETRY_S where it cannot watch, and logs which way the folder is read."""

    SELECTOR_KEY = "folder"

    def __init__(self, enabled: bool = True, *, check_fs: bool = True) -> None:
        self.enabled = enabled
        self.check_fs = check_fs
        self.watch: FolderWatch | None = None
        self.folder: Path | None = None
        self.why_not = ""
        self._retry_at = 0.0
        self._said: tuple[Path | None, str] | None = None

    @property
    def active(self) -> bool:
        return self.watch is not None

    def describe(self) -> dict[str, Any]:
        """For the service's status: {"folder", "watching", "why_not"}."""
        return {"folder": str(self.folder) if self.folder else "", "watching": self.active,
                "why_not": "" if self.active else self.why_not}

    def follow(self, store: Any, sel: selectors.BaseSelector, poll_s: float) -> bool:
        """Open, keep or drop the watch for *store*; True when it started or ended (the caller
        reads the store at once: something may have changed unseen). Cheap: one stat."""
        folder = Path(store.folder) if getattr(store, "kind", "") == "folder" else None
        if folder != self.folder:               # another store (the settings changed)
            was = self.active
            self._drop(sel)
            self.folder, self._retry_at, self.why_not = folder, 0.0, ""
            if folder is None:
                return was
        if folder is None:
            return False
        if self.watch is not None:
            if self.watch.still_valid():
                return False
            self.lose(sel, "the folder was replaced, moved or unmounted", poll_s)
        if not self.enabled:
            self.why_not = "watching is turned off"
            self._say(logging.INFO, "off", f"the shared folder {folder} is read every "
                                           f"{poll_s:g} s (watching is turned off)")
            return False
        now = time.monotonic()
        if now < self._retry_at:
            return False
        try:
            self.watch = FolderWatch.open(folder, check_fs=self.check_fs)
        except WatchUnavailable as exc:
            self._retry_at = now + RETRY_S
            self.why_not = str(exc)
            self._say(logging.INFO, self.why_not, f"cannot watch the shared folder {folder} "
                      f"({self.why_not}): it is read every {poll_s:g} s instead")
            return False
        sel.register(self.watch.fileno(), selectors.EVENT_READ, self.SELECTOR_KEY)
        self.why_not = ""
        self._say(logging.INFO, "", f"watching the shared folder {folder} (inotify): a peer's "
                                    "record is read as soon as it is complete")
        return True

    def drain(self, sel: selectors.BaseSelector, poll_s: float) -> bool:
        """Events are pending: True when the records should be read now."""
        if self.watch is None:
            return False
        got = self.watch.drain()
        if got.names:
            log.debug("shared folder: %s changed", ", ".join(got.names))
        if got.lost:
            self.lose(sel, "the folder was deleted, moved or unmounted", poll_s)
        return got.changed

    def lose(self, sel: selectors.BaseSelector, why: str, poll_s: float) -> None:
        if self.watch is None:
            return
        self._drop(sel)
        self.why_not = why
        self._retry_at = time.monotonic()       # try again at once (the folder may be back)
        self._say(logging.WARNING, f"lost: {why}", f"the watch on the shared folder "
                  f"{self.folder} ended ({why}): it is read every {poll_s:g} s until it can be "
                  "watched again")

    def _drop(self, sel: selectors.BaseSelector) -> None:
        if self.watch is not None:
            with contextlib.suppress(KeyError, ValueError):
                sel.unregister(self.watch.fileno())
            self.watch.close()
            self.watch = None

    def close(self, sel: selectors.BaseSelector | None = None) -> None:
        if self.watch is not None:
            if sel is not None:
                self._drop(sel)
            else:
                self.watch.close()
                self.watch = None

    def _say(self, level: int, key: str, text: str) -> None:
        """Log a change of the way the folder is read (once per folder and reason)."""
        if (self.folder, key) == self._said:
            return
        self._said = (self.folder, key)
        log.log(level, "%s", text)
