"""Writing one file safely: atomic rename, or a journaled in-place rewrite where the file is a
mount point, and completing an in-place write that was cut short.

An in-place rewrite cannot be atomic, so it is journaled (:mod:`.cut_writes` says where): the old
and the new bytes go to a journal first (fsynced, renamed into place, its folder fsynced, locked
by the writer while it writes), then the file is rewritten (one write of the whole new content,
the truncation right after it when the file shrinks, then fsync: other programs may read a mix
for no longer than that), then the journal is removed. A writer killed at any moment leaves the
old content, the new one, or a mix of the two with its journal. The next run completes it
before it reads anything (:func:`complete_cut_writes`, from the command line's start-up), and so
does every read through :func:`read_bytes`. A process that may not write the file (a user, after
root's write was cut) cannot: reading a torn file then raises :class:`TornFileError`, which says
which command completes it.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import re
import secrets
import shlex
import stat
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from rosnet_tui.core.config.paths import DEFAULT_HOSTS_PATH, default_state_dir
from rosnet_tui.core.files import nofollow, tempfiles
from rosnet_tui.core.files.cut_writes import INPLACE_DIR, journal_name
from rosnet_tui.core.files.inplace_format import is_torn, journal_bytes, parse_journal
from rosnet_tui.core.files.managed_text import ManagedFileError, PermissionNeededError, decode
from rosnet_tui.core.files.regular_file import FileRefusedError, read_regular

LOCK_TIMEOUT_S = 10.0

# Test hook: called between the fsync of a managed file's temp file and the rename (crash tests
# set it).
_before_rename: Callable[[], None] | None = None
# Test hook: called between the in-place write and its truncation (crash tests set it).
_before_truncate: Callable[[], None] | None = None


class TornFileError(ManagedFileError):
    """The file holds a mix of old and new bytes (an in-place write of ours was cut short) and
    this process may not complete it; the message says which command does. *sudo* renders the
    command that runs rosnet-tui as root with the given arguments (the command line passes the
    exact one); *config* is the settings file that run should use."""

    def __init__(self, path: Path, journal_dir: Path | None = None, config: Path | None = None,
                 sudo: Callable[[list[str]], str] | None = None) -> None:
        self.path = Path(path)
        args = completion_args(path, journal_dir, config)
        self.command = sudo(args) if sudo else "sudo rosnet-tui " + shlex.join(args)
        super().__init__(
            f"{path} is torn: a write of rosnet-tui was cut short, and every program reads a mix "
            "of its old and new lines until it is completed. Only root may complete it; run: "
            + self.command)


def completion_args(path: Path, journal_dir: Path | None = None,
                    config: Path | None = None) -> list[str]:
    """rosnet-tui's arguments for a run that completes a cut write of *path* (run as root): any
    run does that first; a read-only one, told where the journal is and which settings to use."""
    args = ["hosts", "show"]
    if Path(path) != DEFAULT_HOSTS_PATH:
        args += ["--file", str(path)]
    if journal_dir is not None:
        args += ["--state-dir", str(Path(journal_dir).parent)]
    if config is not None:
        args += ["--config", str(config)]
    return args


# --------------------------------------------------------------------------- preview
def read_bytes(path: Path, *, state_dir: Path | None = None,
               wait_s: float = LOCK_TIMEOUT_S) -> bytes | None:
    """The file's bytes, or None when it does not exist. Other errors: ManagedFileError.

    Every read of a file rosnet-tui writes goes through here. An in-place write that was cut
    short (its journal is still beside the file, or in the in-place folder of *state_dir* or of
    the default state dir) is completed first, so the reader never sees a mix of the old and
    the new bytes; when this process may not complete it, TornFileError (a file that is old or
    new, with a journal this process may not act on, is read as it is). A writer still at work
    is waited for, up to *wait_s*."""
    try:
        if os.geteuid() == 0:
            nofollow.resolve(Path(path))   # root reads nothing through a user's link
        recover_in_place(
            Path(path), journal_dir=Path(state_dir) / INPLACE_DIR if state_dir else None,
            wait_s=wait_s)
        real = Path(os.path.realpath(path))
        _remove_stale_temps(real.parent, real.name)
        return _read_regular(Path(path))
    except FileNotFoundError:
        return None
    except nofollow.LinkRefusedError:
        raise
    except IsADirectoryError:
        raise ManagedFileError(f"{path} is a folder, not a file") from None
    except PermissionError:
        raise PermissionNeededError(f"this user may not read {path}", [Path(path)]) from None
    except OSError as exc:
        raise ManagedFileError(f"cannot read {path}: {exc.strerror}") from None


def read_text(path: Path, *, state_dir: Path | None = None, errors: str = "surrogateescape",
              wait_s: float = LOCK_TIMEOUT_S) -> str | None:
    """:func:`read_bytes` as text (by default bytes that are not UTF-8 survive as surrogates;
    ``errors="replace"`` for text shown or printed)."""
    data = read_bytes(path, state_dir=state_dir, wait_s=wait_s)
    if data is None:
        return None
    return decode(data) if errors == "surrogateescape" else data.decode("utf-8", errors)


def settle(path: Path, *, state_dir: Path | None = None,
           wait_s: float = LOCK_TIMEOUT_S) -> None:
    """Complete a cut-short in-place write of *path*, for readers that must open the file
    themselves (the stdlib-only programs that also run on peers); never raises."""
    with contextlib.suppress(OSError, ManagedFileError):
        recover_in_place(Path(path),
                         journal_dir=Path(state_dir) / INPLACE_DIR if state_dir else None,
                         wait_s=wait_s)


MAX_FILE_BYTES = 256 << 20   # hosts files and shell files are far smaller


def _read_regular(path: Path) -> bytes:
    """A regular file's bytes; anything else (a FIFO, a device behind a link) is refused
    without reading it, as is a file over MAX_FILE_BYTES."""
    try:
        return read_regular(path, MAX_FILE_BYTES)
    except FileRefusedError as exc:
        if exc.kind == "folder":
            raise IsADirectoryError(errno.EISDIR, "Is a directory", str(path)) from None
        if exc.kind == "big":
            raise ManagedFileError(f"{path} {exc.why} to be a file rosnet-tui edits") from None
        raise ManagedFileError(f"{path} is not a regular file (a FIFO or a device?); "
                               "nothing was read or written") from None


# --------------------------------------------------------------------------- writing
def is_mount_point(path: Path) -> bool:
    """True when *path* is itself a mount point (a bind-mounted file such as a netns /etc/hosts)."""
    try:
        real = os.path.realpath(path)
        with open("/proc/self/mountinfo", encoding="utf-8", errors="replace") as f:
            for line in f:
                parts = line.split()
                if len(parts) > 4 and _unescape_mount(parts[4]) == real:
                    return True
    except OSError:
        pass
    return False


def _unescape_mount(s: str) -> str:
    return re.sub(r"\\([0-7]{3})", lambda m: chr(int(m.group(1), 8)), s)


def can_write(path: Path) -> bool:
    """Whether this process can write *path* by one of our strategies (no privilege needed)."""
    if os.geteuid() == 0:
        return True
    try:
        real = Path(os.path.realpath(path))
        if real.exists():
            return os.access(real, os.W_OK, effective_ids=True)  # rename if the folder allows it, else in place
        parent = real.parent
        while not parent.exists() and parent != parent.parent:
            parent = parent.parent
        return os.access(parent, os.W_OK | os.X_OK, effective_ids=True)
    except OSError:
        return False


@dataclass
class WriteOutcome:
    path: Path
    in_place: bool
    deleted: bool = False


def fsync_dir(folder: Path) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _copy_xattrs(src: Path, fd: int) -> None:
    """Best effort: keep extended attributes (an SELinux label on /etc/hosts, for one)."""
    try:
        names = os.listxattr(src)
    except OSError:
        return
    for name in names:
        try:
            os.setxattr(fd, name, os.getxattr(src, name))
        except OSError:
            pass


def _remove_stale_temps(folder: Path, name: str) -> None:
    """Remove temp files that writers killed before their rename left behind."""
    tempfiles.sweep(folder, tempfiles.MANAGED_TMP, name)


def sweep_state_dir(state_dir: Path) -> list[str]:
    """Remove the temp files killed writers left in the state dir (journal entries, backups,
    status files); the names removed."""
    sd = Path(state_dir)
    if os.geteuid() == 0:     # root in a user's state dir: not through a link of the user's
        try:
            os.close(nofollow.walk(sd)[0])
        except OSError:
            return []
        if any(os.path.islink(sd / f) for f in ("journal", "backups", "sync", "inplace")):
            return []
    removed = tempfiles.sweep(sd / "journal", tempfiles.PRIVATE_TMP)
    with contextlib.suppress(OSError), os.scandir(sd / "backups") as it:
        for e in it:
            if e.is_dir(follow_symlinks=False):
                removed += tempfiles.sweep(Path(e.path), tempfiles.PRIVATE_TMP)
    for folder in (sd, sd / "sync"):
        removed += tempfiles.sweep(folder, tempfiles.MANAGED_TMP)
        removed += tempfiles.sweep(folder, tempfiles.ATOMIC_TMP)    # an earlier version's
    removed += tempfiles.sweep(sd / "inplace", tempfiles.MANAGED_TMP)
    return removed


def write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    off = 0
    while off < len(data):
        off += os.pwrite(fd, view[off:], off)


# --------------------------------------------------------------------------- in-place journal
def _rewrite(real: Path, data: bytes) -> None:
    """*data* into *real* through its own inode, keeping the time other programs may read a mix
    as short as in place allows: one write of the whole buffer, the truncation right after it
    (when the file shrinks), then one fsync."""
    fd = os.open(real, os.O_WRONLY | os.O_NOFOLLOW | os.O_CLOEXEC)
    try:
        write_all(fd, data)
        if _before_truncate is not None:
            _before_truncate()
        if os.fstat(fd).st_size != len(data):
            os.ftruncate(fd, len(data))
        os.fsync(fd)
    finally:
        os.close(fd)


def journal_dirs(journal_dir: Path | None = None) -> list[Path]:
    """Where the journal of a file whose folder may not be written can be: *journal_dir* (the
    writer's state dir), then the default state dir's in-place folder (so that a reader that is
    not told the writer's state dir, such as ``check``, still finds it)."""
    out = [Path(journal_dir)] if journal_dir else []
    with contextlib.suppress(RuntimeError, KeyError):   # no home folder: only the given one
        default = default_state_dir().expanduser().absolute() / INPLACE_DIR
        if default not in out:
            out.append(default)
    return out


@dataclass(frozen=True)
class CutWrite:
    """An in-place write that was cut short, as found, and what became of it: ``completed``
    (the file holds the new bytes now), ``left`` (this process may not write the file, or
    could not), ``dropped`` (someone else changed the file since, or the journal was not whole:
    the file is left as it is)."""

    path: Path
    journal: Path
    torn: bool        # the file held a mix of old and new bytes when found
    changed: bool     # completing it changed the file
    outcome: str

    @property
    def journal_dir(self) -> Path | None:
        """The state dir's in-place folder that held the journal (None: beside the file)."""
        return None if self.journal.parent == self.path.parent else self.journal.parent


def recover_in_place(path: Path, *, journal_dir: Path | None = None,
                     wait_s: float = LOCK_TIMEOUT_S) -> None:
    """Complete an in-place write of *path* that was cut short, from its journal (beside the
    file, in *journal_dir*, or in the default state dir's in-place folder): see
    :func:`find_cut_writes`. Raises TornFileError when the file is torn and this process may
    not complete it; OSError (FileNotFoundError when *path* does not exist)."""
    for cut in find_cut_writes(path, journal_dir=journal_dir, wait_s=wait_s):
        if cut.outcome == "left" and cut.torn:
            raise TornFileError(cut.path, cut.journal_dir)


def find_cut_writes(path: Path, *, journal_dir: Path | None = None,
                    wait_s: float = LOCK_TIMEOUT_S) -> list[CutWrite]:
    """Complete the in-place writes of *path* that were cut short, where this process may; what
    was found. A journal whose writer is still at work (it holds the journal's lock) is waited
    for, up to *wait_s*. The file is changed only when it holds the journal's old bytes, its new
    ones, or a mix that only that write leaves (it is then rolled forward to the new bytes);
    after anyone else's change the journal is dropped and the file left alone. Raises OSError
    (FileNotFoundError when *path* does not exist)."""
    real = Path(os.path.realpath(path))
    st = os.stat(real)
    name = journal_name(real.name, st)
    jpaths = [real.parent / name] + [d / name for d in journal_dirs(journal_dir)]
    found = []
    for jpath in dict.fromkeys(jpaths):
        cut = _recover_from(real, st, jpath, wait_s)
        if cut is not None:
            found.append(cut)
    return found


def complete_cut_writes(found: list[tuple[str, str | None]], *, config: Path | None = None,
                        sudo: Callable[[list[str]], str] | None = None,
                        wait_s: float = 2.0) -> list[str]:
    """Complete the cut writes :func:`rosnet_tui.core.files.cut_writes.pending` found (at start-up,
    before anything reads a file); what to tell the user, one line each: what was completed,
    and the files that stay torn because this process may not write them (with the command
    that completes them: see :class:`TornFileError`)."""
    said = []
    for path, folder in found:
        try:
            cuts = find_cut_writes(Path(path), journal_dir=Path(folder) if folder else None,
                                   wait_s=wait_s)
        except OSError:
            continue
        for c in cuts:
            if c.outcome == "completed" and c.torn:
                said.append(f"{c.path} was torn (a write of rosnet-tui was cut short): "
                            "completed, it holds the new content now")
            elif c.outcome == "completed" and c.changed:
                said.append(f"completed a write of {c.path} that a killed run had begun")
            elif c.outcome == "left" and c.torn:
                said.append(str(TornFileError(c.path, c.journal_dir, config, sudo)))
    return said


def _recover_from(real: Path, st: os.stat_result, jpath: Path, wait_s: float) -> CutWrite | None:
    deadline = time.monotonic() + wait_s
    while True:
        try:
            jfd = os.open(jpath, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC)
        except OSError:
            return None                       # none (the usual case), or not ours to read
        try:
            try:
                fcntl.flock(jfd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                if time.monotonic() >= deadline:
                    return None               # a live writer: it finishes its own write
                time.sleep(0.02)
                continue
            jst = os.fstat(jfd)
            try:
                if os.stat(jpath).st_ino != jst.st_ino:
                    continue                  # replaced while we waited: look again
            except FileNotFoundError:
                return None                   # its writer finished and removed it
            # Trust only a journal of root or of this user, that nobody else may change.
            if jst.st_uid not in (0, os.geteuid()) or jst.st_mode & 0o022 \
                    or not stat.S_ISREG(jst.st_mode):
                return None
            with os.fdopen(os.dup(jfd), "rb") as f:
                parsed = parse_journal(f.read(min(jst.st_size, 2 * MAX_FILE_BYTES + (1 << 20))))
            return _settle_from(real, st, jpath, parsed)
        finally:
            os.close(jfd)


def _settle_from(real: Path, st: os.stat_result, jpath: Path,
                 parsed: tuple[dict, bytes, bytes] | None) -> CutWrite:
    """Roll the file forward from a journal whose lock we hold; what became of it."""
    cur = real.read_bytes()
    target, torn = None, False
    if parsed is not None and parsed[0].get("path") == str(real) \
            and (parsed[0].get("dev"), parsed[0].get("ino")) == (st.st_dev, st.st_ino):
        _, old, new = parsed
        if cur == new or cur == old or is_torn(cur, old, new):
            target, torn = new, cur not in (old, new)
    changed = target is not None and target != cur
    if not (os.access(real, os.W_OK, effective_ids=True)
            and os.access(jpath.parent, os.W_OK | os.X_OK, effective_ids=True)):
        return CutWrite(real, jpath, torn, False, "left")   # a user after root's cut write
    try:
        if changed:
            _rewrite(real, target)
            if real.read_bytes() != target:
                return CutWrite(real, jpath, torn, True, "left")   # the journal stays
        os.unlink(jpath)
    except OSError:
        return CutWrite(real, jpath, torn, False, "left")   # e.g. a read-only mount
    fsync_dir(jpath.parent)
    return CutWrite(real, jpath, torn, changed, "dropped" if target is None else "completed")


def _write_in_place(real: Path, data: bytes, journal_dir: Path | None = None) -> None:
    """Rewrite an existing file through its own inode (mount points, hard links, other owners).

    Journaled (see the module docstring): a kill at any moment leaves the old bytes, the new
    ones, or a state the next run completes. Read back to verify; on a mismatch the old bytes
    are put back. The journal goes beside the file, or into *journal_dir* when the file's folder
    may not be written (then only a run that looks in that state dir completes it); with
    neither, the write is not journaled.
    """
    recover_in_place(real, journal_dir=journal_dir)
    old = real.read_bytes()
    st = os.stat(real)
    folder = real.parent if os.access(real.parent, os.W_OK | os.X_OK, effective_ids=True) \
        else journal_dir
    if folder is not None and folder == journal_dir:
        try:
            _make_journal_dir(Path(folder))
        except OSError:
            folder = None
    jfd: int | None = None
    jpath: Path | None = None
    if folder is not None:
        jpath = Path(folder) / journal_name(real.name, st)
        tmp = Path(folder) / f".{real.name}.rosnet-tui.{os.getpid()}.{secrets.token_hex(4)}.tmp"
        jfd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC,
                      stat.S_IMODE(st.st_mode) & 0o644)
        try:
            fcntl.flock(jfd, fcntl.LOCK_EX)   # held until the write is done (or we die)
            write_all(jfd, journal_bytes(real, st, old, data))
            os.fsync(jfd)
            os.rename(tmp, jpath)
            fsync_dir(Path(folder))           # the intent is on disk before the file is touched
        except BaseException:
            os.close(jfd)
            with contextlib.suppress(OSError):
                os.unlink(tmp)
            raise
    try:
        ok = False
        try:
            _rewrite(real, data)
            ok = real.read_bytes() == data
        except Exception:
            with contextlib.suppress(Exception):
                _put_back(real, old, jpath)
            raise
        if not ok:
            _put_back(real, old, jpath)
            raise ManagedFileError(f"{real}: the content read back differs from what was "
                                   "written; the previous content was put back")
        if jpath is not None:
            os.unlink(jpath)
            fsync_dir(jpath.parent)
    finally:
        if jfd is not None:
            os.close(jfd)


def _make_journal_dir(folder: Path) -> None:
    """A state dir's in-place folder: private (0700), but readable when root writes in a user's
    state dir (sudo), so that the user's next run sees root's journal (and can say the file is
    torn); only root may change it."""
    if folder.is_dir():
        return
    parent = folder.parent
    parent.mkdir(mode=0o700, parents=True, exist_ok=True)
    try:
        os.mkdir(folder, 0o700)
    except FileExistsError:
        return
    if os.geteuid() == 0 and os.stat(parent).st_uid != 0:
        os.chmod(folder, 0o755)


def _put_back(real: Path, old: bytes, jpath: Path | None) -> None:
    """After a failed in-place write: the old bytes again, and the journal dropped."""
    _rewrite(real, old)
    if jpath is not None and real.read_bytes() == old:
        os.unlink(jpath)


def atomic_write(path: Path, data: bytes, *, create_mode: int = 0o600, mode: int | None = None,
                 uid: int | None = None, gid: int | None = None, xattr_src: Path | None = None,
                 owner_errors: tuple[type[OSError], ...] = (PermissionError,),
                 before_rename: Callable[[], None] | None = None) -> None:
    """The one atomic writer: *data* to a temp file beside *path* (an unpredictable name,
    created exclusively, never through a link, locked until renamed: see :mod:`.tempfiles`),
    fsync, rename over *path*, fsync of the folder. A writer killed at any moment leaves the old
    file or the new one; its temp file is removed by the next writer of *path* (or the state
    dir's sweep).

    The temp file is created with *create_mode* (the umask applies); *mode* (exact), *uid* and
    *gid* (None: unchanged) and the extended attributes of *xattr_src* are then set on it.
    An ownership change failing with one of *owner_errors* is skipped. *before_rename* is
    called between the fsync and the rename (crash tests stop a writer there).
    """
    folder = path.parent
    dfd, roots_only = nofollow.open_folder(folder)     # first: as root, no user's link on the way
    tempfiles.sweep(folder, tempfiles.MANAGED_TMP, path.name)
    tmp = f".{path.name}.rosnet-tui.{os.getpid()}.{secrets.token_hex(4)}.tmp"
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC,
                     create_mode, dir_fd=dfd)
        try:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX)    # ours until renamed: sweepers leave it alone
                write_all(fd, data)
                if uid is not None or gid is not None:
                    try:
                        os.fchown(fd, -1 if uid is None else uid, -1 if gid is None else gid)
                    except owner_errors:
                        pass  # e.g. a normal user's own file: owner is already right
                if mode is not None:
                    os.fchmod(fd, mode if roots_only else mode & 0o777)
                if xattr_src is not None and roots_only:
                    _copy_xattrs(xattr_src, fd)
                os.fsync(fd)
                if before_rename is not None:
                    before_rename()
                os.replace(tmp, path.name, src_dir_fd=dfd, dst_dir_fd=dfd)
            finally:
                os.close(fd)
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(tmp, dir_fd=dfd)
            raise
        with contextlib.suppress(OSError):
            os.fsync(dfd)
    finally:
        os.close(dfd)


def write_file(path: Path, data: bytes | None, *, mode: int | None = None,
               uid: int | None = None, gid: int | None = None,
               new_mode: int = 0o644, journal_dir: Path | None = None) -> WriteOutcome:
    """Write *data* to *path* safely (None deletes it); keeps mode, owner and xattrs.

    Symlinks are followed (a dotfile linked into a repo stays a link); as root only root's own
    (:mod:`.nofollow`), and in a folder a user may change root only renames a whole new file
    into place through the folder's descriptor. Rename when possible; in place for mount points
    (or when rename fails with EBUSY/EXDEV), hard links, files owned by another user that we may
    write, and files in folders we may not write.
    """
    users_folder = False
    if os.geteuid() == 0:
        real, roots_only = nofollow.resolve(Path(path))
        users_folder = not roots_only
    else:
        real = Path(os.path.realpath(path))
    try:
        st: os.stat_result | None = os.lstat(real) if users_folder else os.stat(real)
    except FileNotFoundError:
        st = None
    if st is not None and not stat.S_ISREG(st.st_mode):
        raise ManagedFileError(f"{path} is not a regular file")
    if users_folder and st is not None and (st.st_nlink > 1 or is_mount_point(real)):
        raise ManagedFileError(f"{path} has other names (hard links) or is a mount point, in a "
                               "folder a user may change: root does not write it")
    if data is None:
        if st is not None:
            dfd, _ = nofollow.open_folder(real.parent)
            try:
                os.unlink(real.name, dir_fd=dfd)
                os.fsync(dfd)
            finally:
                os.close(dfd)
        return WriteOutcome(Path(path), False, deleted=True)
    if st is None:
        if users_folder:
            nofollow.make_dir(real.parent, 0o755)
            folder = os.stat(real.parent)   # a new file in a user's folder is that user's
            uid = folder.st_uid if uid is None else uid
            gid = folder.st_gid if gid is None else gid
        else:
            real.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(real, data, mode=new_mode if mode is None else mode, uid=uid, gid=gid,
                     before_rename=_before_rename)
        return WriteOutcome(Path(path), False)
    mode = stat.S_IMODE(st.st_mode) if mode is None else mode
    uid = st.st_uid if uid is None else uid
    gid = st.st_gid if gid is None else gid
    euid = os.geteuid()
    in_place = (is_mount_point(real) or st.st_nlink > 1
                or (euid != 0 and st.st_uid != euid)
                or not os.access(real.parent, os.W_OK | os.X_OK, effective_ids=True))
    if not in_place:
        try:
            atomic_write(real, data, mode=mode, uid=uid, gid=gid, xattr_src=real,
                         before_rename=_before_rename)
            return WriteOutcome(Path(path), False)
        except OSError as exc:
            if users_folder or exc.errno not in (errno.EBUSY, errno.EXDEV):
                raise
    _remove_stale_temps(real.parent, real.name)
    _write_in_place(real, data, journal_dir)
    if stat.S_IMODE(os.stat(real).st_mode) != mode:
        with contextlib.suppress(OSError):
            os.chmod(real, mode)
    return WriteOutcome(Path(path), True)
