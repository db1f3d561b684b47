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
"""

from __future__ import annotations

import contextlib
import difflib
import errno
import fcntl
import hashlib
import json
import os
import re
import secrets
import stat
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

BEGIN_MARKER = "# BEGIN rosnet-tui"
END_MARKER = "# END rosnet-tui"
ABSENT = "absent"  # the digest of a file that does not exist
LOCK_TIMEOUT_S = 10.0
JOURNAL_KEEP = 100  # applies remembered for undo; older ones (and their backups) are dropped

_MARKER_RE = re.compile(r"^[ \t]*#[ \t]*(BEGIN|END)[ \t]+rosnet-tui(?:[ \t]|$)")
_TMP_RE = re.compile(r"^\.(?P<name>.+)\.rosnet-tui\.(?P<pid>\d+)\.[0-9a-f]+\.tmp$")

# Test hook: called between the fsync of the temp file and the rename (crash tests set it).
_before_rename: Callable[[], None] | None = None
# Test hook: called between the in-place write and its truncation (crash tests set it).
_before_truncate: Callable[[], None] | None = None


# --------------------------------------------------------------------------- errors
class ManagedFileError(Exception):
    """A file we will not or could not write; the message says why, in plain words."""


class DamagedBlockError(ManagedFileError):
    """The file has a BEGIN without END (or the reverse, or two blocks): we do not guess."""


class StalePreviewError(ManagedFileError):
    """The file changed between the preview and the apply."""


class PermissionNeededError(ManagedFileError):
    """This user may not write the file (use the sudo command from rosnet_tui.core.privilege)."""

    def __init__(self, message: str, paths: Sequence[Path] = ()) -> None:
        super().__init__(message)
        self.paths = list(paths)


class NothingToUndoError(ManagedFileError):
    """The journal holds no apply that has not been undone yet."""


class UndoConflictError(ManagedFileError):
    """A file was changed by someone else after our apply; undoing would lose that change."""


# --------------------------------------------------------------------------- text helpers
def decode(data: bytes) -> str:
    """Bytes to text that encodes back to the very same bytes (undecodable bytes survive)."""
    return data.decode("utf-8", "surrogateescape")


def encode(text: str) -> bytes:
    return text.encode("utf-8", "surrogateescape")


def file_digest(data: bytes | None) -> str:
    """The digest a preview carries: sha256 of the bytes, or ``absent`` for a missing file."""
    return ABSENT if data is None else hashlib.sha256(data).hexdigest()


def split_lines(text: str) -> list[str]:
    """Lines with their terminators; only ``\\n`` ends a line (a ``\\r`` before it stays with it)."""
    if not text:
        return []
    lines = text.split("\n")
    out = [line + "\n" for line in lines[:-1]]
    if lines[-1]:
        out.append(lines[-1])
    return out


def line_content(line: str) -> str:
    """A line without its terminator (``\\n`` or ``\\r\\n``)."""
    if line.endswith("\n"):
        line = line[:-1]
        if line.endswith("\r"):
            line = line[:-1]
    return line


def detect_newline(text: str | None) -> str:
    """``\\r\\n`` when most lines of *text* end that way, else ``\\n``."""
    if not text:
        return "\n"
    crlf = text.count("\r\n")
    return "\r\n" if crlf and crlf * 2 >= text.count("\n") else "\n"


def find_block(lines: Sequence[str]) -> tuple[int, int] | None:
    """Indexes of our BEGIN and END lines, or None when the file has no block.

    Raises DamagedBlockError for a BEGIN without END, an END without BEGIN, or a second block.
    """
    begin = end = None
    for i, line in enumerate(lines):
        m = _MARKER_RE.match(line_content(line))
        if not m:
            continue
        if m.group(1) == "BEGIN":
            if begin is not None:
                raise DamagedBlockError(
                    f"line {i + 1} starts a second rosnet-tui block (the first starts at line "
                    f"{begin + 1}); remove one of them by hand, then try again")
            begin = i
        else:
            if begin is None:
                raise DamagedBlockError(
                    f"line {i + 1} ends a rosnet-tui block that never began; remove the stray "
                    f"'{END_MARKER}' line by hand, then try again")
            if end is not None:
                raise DamagedBlockError(
                    f"line {i + 1} ends the rosnet-tui block a second time; remove the stray "
                    f"'{END_MARKER}' line by hand, then try again")
            end = i
    if begin is None:
        return None
    if end is None:
        raise DamagedBlockError(
            f"the rosnet-tui block that starts at line {begin + 1} has no '{END_MARKER}' line; "
            "fix the file by hand (add the END line or remove the block), then try again")
    return begin, end


def extract_block(text: str | None) -> list[str] | None:
    """The lines between our markers (no terminators), or None when there is no block."""
    lines = split_lines(text or "")
    span = find_block(lines)
    if span is None:
        return None
    return [line_content(x) for x in lines[span[0] + 1:span[1]]]


def compose_block(text: str | None, body: Sequence[str], *, position: str = "end",
                  replace_lines: Mapping[int, str] | None = None) -> str:
    """*text* with our block set to *body* (lines without terminators); nothing else changes.

    An existing block is replaced where it stands, in its own line endings. A new block goes at
    the top (``position="top"``: first match wins, as in /etc/hosts) or at the end (``"end"``: last
    assignment wins, as in ~/.bashrc), in the file's dominant line ending. *replace_lines* maps
    0-based indexes of lines outside the block to new content (terminator kept): the only way a
    line outside our block changes, used to comment lines out when the user agreed.
    """
    for line in body:
        if "\n" in line or "\r" in line or _MARKER_RE.match(line):
            raise ValueError(f"a block line may not hold a newline or a marker: {line!r}")
    text = text or ""
    lines = split_lines(text)
    span = find_block(lines)
    replace_lines = dict(replace_lines or {})
    for i, new in replace_lines.items():
        if not 0 <= i < len(lines) or (span and span[0] <= i <= span[1]):
            raise ValueError(f"line index {i} is not a line outside the block")
        if "\n" in new or "\r" in new:
            raise ValueError("a replacement line may not hold a newline")
        old = lines[i]
        lines[i] = new + old[len(line_content(old)):]
    if span is not None:
        begin_line, end_line = lines[span[0]], lines[span[1]]
        nl = begin_line[len(line_content(begin_line)):] or detect_newline(text)
        block = [x + nl for x in (BEGIN_MARKER, *body, END_MARKER)]
        if not end_line.endswith("\n"):
            block[-1] = END_MARKER  # the block was the end of a file without a final newline
        return "".join(lines[:span[0]] + block + lines[span[1] + 1:])
    nl = detect_newline(text)
    block = [x + nl for x in (BEGIN_MARKER, *body, END_MARKER)]
    if position == "top":
        return "".join(block + lines)
    if position != "end":
        raise ValueError(f"position must be 'top' or 'end', not {position!r}")
    if lines and not lines[-1].endswith("\n"):
        block[0] = nl + block[0]
    return "".join(lines + block)


@dataclass(frozen=True)
class LineChange:
    """A line outside our block that we offer to change (comment out), and why."""

    index: int      # 0-based line index in the file
    old: str        # the line as it is (no terminator)
    new: str        # what it would become (no terminator)
    why: str        # the reason, shown to the user before asking

    @property
    def lineno(self) -> int:
        return self.index + 1


# --------------------------------------------------------------------------- preview
def read_bytes(path: Path) -> bytes | None:
    """The file's bytes, or None when it does not exist. Other errors: ManagedFileError."""
    try:
        return Path(path).read_bytes()
    except FileNotFoundError:
        return None
    except IsADirectoryError:
        raise ManagedFileError(f"{path} is a folder, not a file") from None
    except PermissionError:
        raise PermissionNeededError(f"this user may not read {path}", [Path(path)]) from None
    except OSError as exc:
        raise ManagedFileError(f"cannot read {path}: {exc.strerror}") from None


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
            return os.access(real, os.W_OK)  # rename if the folder allows it, else in place
        parent = real.parent
        while not parent.exists() and parent != parent.parent:
            parent = parent.parent
        return os.access(parent, os.W_OK | os.X_OK)
    except OSError:
        return False


@dataclass
class WriteOutcome:
    path: Path
    in_place: bool
    deleted: bool = False


def _fsync_dir(folder: Path) -> None:
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


def _pid_alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii", errors="replace") as f:
            return f.read().rsplit(")", 1)[-1].split()[0] not in ("Z", "X")
    except OSError:
        return False


def _remove_stale_temps(folder: Path, name: str) -> None:
    """Remove temp files that writers killed before their rename left behind."""
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return
    for e in entries:
        m = _TMP_RE.match(e.name)
        if m and m.group("name") == name and not _pid_alive(int(m.group("pid"))):
            with contextlib.suppress(OSError):
                os.unlink(e.path)


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    off = 0
    while off < len(data):
        off += os.pwrite(fd, view[off:], off)


def _write_in_place(real: Path, data: bytes) -> None:
    """Rewrite an existing file through its own inode (mount points, hard links, other owners).

    Not atomic: the caller has a backup. Read back to verify; on mismatch put the old bytes back.
    New content shorter than the old is written padded with newlines to the old length first, so
    a crash before the truncation leaves the new content and blank lines, never a tail of old
    bytes after it.
    """
    old = real.read_bytes()
    padded = data + b"\n" * (len(old) - len(data)) if len(data) < len(old) else data
    fd = os.open(real, os.O_WRONLY | os.O_NOFOLLOW)
    try:
        _write_all(fd, padded)
        os.fsync(fd)
        if _before_truncate is not None:
            _before_truncate()
        os.ftruncate(fd, len(data))
        os.fsync(fd)
    finally:
        os.close(fd)
    if real.read_bytes() != data:
        fd = os.open(real, os.O_WRONLY | os.O_NOFOLLOW)
        try:
            _write_all(fd, old)
            os.ftruncate(fd, len(old))
            os.fsync(fd)
        finally:
            os.close(fd)
        raise ManagedFileError(f"{real}: the content read back differs from what was written; "
                               "the previous content was put back")


def _write_renaming(real: Path, data: bytes, mode: int, uid: int | None, gid: int | None,
                    xattr_src: Path | None) -> None:
    folder = real.parent
    tmp = folder / f".{real.name}.rosnet-tui.{os.getpid()}.{secrets.token_hex(4)}.tmp"
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o600)
    try:
        try:
            _write_all(fd, data)
            if uid is not None or gid is not None:
                try:
                    os.fchown(fd, -1 if uid is None else uid, -1 if gid is None else gid)
                except PermissionError:
                    pass  # a normal user's own file: owner is already right
            os.fchmod(fd, mode)
            if xattr_src is not None:
                _copy_xattrs(xattr_src, fd)
            os.fsync(fd)
        finally:
            os.close(fd)
        if _before_rename is not None:
            _before_rename()
        os.replace(tmp, real)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    _fsync_dir(folder)


def write_file(path: Path, data: bytes | None, *, mode: int | None = None,
               uid: int | None = None, gid: int | None = None,
               new_mode: int = 0o644) -> WriteOutcome:
    """Write *data* to *path* safely (None deletes it); keeps mode, owner and xattrs.

    Symlinks are followed (a dotfile linked into a repo stays a link). Rename when possible;
    in place for mount points (or when rename fails with EBUSY/EXDEV), hard links, files owned by
    another user that we may write, and files in folders we may not write.
    """
    real = Path(os.path.realpath(path))
    try:
        st: os.stat_result | None = os.stat(real)
    except FileNotFoundError:
        st = None
    if st is not None and not stat.S_ISREG(st.st_mode):
        raise ManagedFileError(f"{path} is not a regular file")
    if data is None:
        if st is not None:
            os.unlink(real)
            _fsync_dir(real.parent)
        return WriteOutcome(Path(path), False, deleted=True)
    if st is None:
        real.parent.mkdir(parents=True, exist_ok=True)
        _remove_stale_temps(real.parent, real.name)
        _write_renaming(real, data, new_mode if mode is None else mode, uid, gid, None)
        return WriteOutcome(Path(path), False)
    mode = stat.S_IMODE(st.st_mode) if mode is None else mode
    uid = st.st_uid if uid is None else uid
    gid = st.st_gid if gid is None else gid
    euid = os.geteuid()
    in_place = (is_mount_point(real) or st.st_nlink > 1
                or (euid != 0 and st.st_uid != euid)
                or not os.access(real.parent, os.W_OK | os.X_OK))
    if not in_place:
        _remove_stale_temps(real.parent, real.name)
        try:
            _write_renaming(real, data, mode, uid, gid, real)
            return WriteOutcome(Path(path), False)
        except OSError as exc:
            if exc.errno not in (errno.EBUSY, errno.EXDEV):
                raise
    _write_in_place(real, data)
    if stat.S_IMODE(os.stat(real).st_mode) != mode:
        with contextlib.suppress(OSError):
            os.chmod(real, mode)
    return WriteOutcome(Path(path), True)


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
    # Port forwards made on the modem (rosnet_tui.core.upnp.journal): no files, undone by
    # removing them from the modem they were made on.
    mappings: list[dict] = field(default_factory=list)

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


@dataclass
class ApplyResult:
    changed: bool
    entry_id: str | None = None
    files: list[WriteOutcome] = field(default_factory=list)
    backups: list[Path] = field(default_factory=list)

    @property
    def in_place(self) -> bool:
        return any(f.in_place for f in self.files)


def _state_dir(state_dir: Path | None) -> Path:
    if state_dir is None:
        from rosnet_tui.core.settings import default_state_dir

        state_dir = default_state_dir()
    return Path(state_dir).expanduser().absolute()


def _owner_for(state_dir: Path) -> tuple[int, int] | None:
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


def _mkdir(path: Path, owner: tuple[int, int] | None) -> None:
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


def _write_private(path: Path, data: bytes, owner: tuple[int, int] | None) -> None:
    """Write a state file (journal, backup): temp + fsync + rename, never following links."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o600)
    try:
        try:
            _write_all(fd, data)
            if owner:
                with contextlib.suppress(OSError):
                    os.fchown(fd, *owner)
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    _fsync_dir(path.parent)


@contextlib.contextmanager
def _locked(state_dir: Path, owner: tuple[int, int] | None,
            timeout_s: float = LOCK_TIMEOUT_S) -> Iterator[None]:
    """One writer at a time per state dir (bounded wait)."""
    _mkdir(state_dir, owner)
    lock = state_dir / "lock"
    fd = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o600)
    try:
        if owner:
            with contextlib.suppress(OSError):
                os.fchown(fd, *owner)
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if time.monotonic() > deadline:
                    raise ManagedFileError(
                        f"another rosnet-tui is writing (lock {lock} held for {timeout_s:g} s); "
                        "try again when it is done") from None
                time.sleep(0.05)
        yield
    finally:
        os.close(fd)


def journal_entries(state_dir: Path | None = None) -> list[JournalEntry]:
    """Every recorded apply, oldest first (undone ones included, marked)."""
    folder = _state_dir(state_dir) / "journal"
    out = []
    try:
        names = sorted(n for n in os.listdir(folder) if re.fullmatch(r"\d{6,}\.json", n))
    except FileNotFoundError:
        return []
    for n in names:
        try:
            out.append(JournalEntry.from_json(json.loads((folder / n).read_text("utf-8"))))
        except (OSError, ValueError, TypeError, KeyError):
            continue  # a damaged entry is skipped, never trusted
    return out


def _next_id(state_dir: Path) -> str:
    entries = journal_entries(state_dir)
    n = max((int(e.id) for e in entries if e.id.isdigit()), default=0) + 1
    return f"{n:06d}"


def _save_entry(state_dir: Path, entry: JournalEntry, owner: tuple[int, int] | None) -> None:
    folder = state_dir / "journal"
    _mkdir(folder, owner)
    _write_private(folder / f"{entry.id}.json",
                   (json.dumps(entry.to_json(), indent=2) + "\n").encode(), owner)


def _prune(state_dir: Path, keep: int = JOURNAL_KEEP) -> None:
    """Forget the oldest entries (and their backups) beyond the *keep* most recent."""
    import shutil

    for e in journal_entries(state_dir)[:-keep]:
        with contextlib.suppress(OSError):
            shutil.rmtree(state_dir / "backups" / e.id)
            os.unlink(state_dir / "journal" / f"{e.id}.json")


def _now() -> str:
    return datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


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
    sd = _state_dir(state_dir)
    owner = _owner_for(sd)
    with _locked(sd, owner):
        for p in previews:
            _check_fresh(p)
        entry = JournalEntry(_next_id(sd), _now(), label or "; ".join(p.label for p in todo if p.label), [])
        bdir = sd / "backups" / entry.id
        _mkdir(bdir, owner)
        result = ApplyResult(True, entry.id)
        for i, p in enumerate(todo):
            real = Path(os.path.realpath(p.path))
            st = os.stat(real) if p.old is not None else None
            backup = None
            if p.old is not None:
                bpath = bdir / f"{i}-{real.name}"
                _write_private(bpath, p.old, owner)
                backup = str(bpath.relative_to(sd))
                result.backups.append(bpath)
            entry.files.append(JournalFile(
                path=str(Path(p.path).absolute()), real_path=str(real), existed=p.old is not None,
                backup=backup, before=p.digest, after=p.new_digest,
                mode=stat.S_IMODE(st.st_mode) if st else None,
                uid=st.st_uid if st else None, gid=st.st_gid if st else None))
        _save_entry(sd, entry, owner)  # before any write: a crash leaves an undoable record
        done: list[int] = []
        try:
            for i, p in enumerate(todo):
                outcome = write_file(p.path, p.new, new_mode=p.new_mode)
                entry.files[i].in_place = outcome.in_place
                result.files.append(outcome)
                done.append(i)
        except BaseException as exc:
            _roll_back(sd, entry, done)
            entry.undone = _now() + " (rolled back: the apply failed)"
            with contextlib.suppress(Exception):
                _save_entry(sd, entry, owner)
            if isinstance(exc, PermissionError):
                raise PermissionNeededError(f"this user may not write {exc.filename}",
                                            [Path(exc.filename or "")]) from exc
            if isinstance(exc, OSError) and not isinstance(exc, ManagedFileError):
                raise ManagedFileError(f"could not write {exc.filename}: {exc.strerror}; "
                                       "nothing was changed") from exc
            raise
        _save_entry(sd, entry, owner)
        _prune(sd)
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


# Files root may restore from a journal that a normal user owns (sudo): the system files we write.
ROOT_RESTORABLE = ("/etc/hosts",)


def _check_root_safe(sd: Path, entry: JournalEntry) -> None:
    """Root undoing from a user's journal restores only system files rosnet-tui writes."""
    owner = _owner_for(sd)
    if owner is None:
        return
    for f in entry.files:
        try:
            mine = os.stat(f.real_path).st_uid == owner[0]
        except OSError:
            mine = False
        if f.real_path not in ROOT_RESTORABLE and not mine:
            raise ManagedFileError(
                f"as root, undo from a user's journal restores only {', '.join(ROOT_RESTORABLE)}"
                f" and that user's files; not {f.real_path}")


def _restore_one(sd: Path, f: JournalFile) -> None:
    b = _backup_path(sd, f)
    data = b.read_bytes() if b else None
    if data is not None and file_digest(data) != f.before:
        raise ManagedFileError(f"the backup {b} is damaged (digest mismatch); "
                               f"{f.path} was left as it is")
    write_file(Path(f.real_path), data, mode=f.mode, uid=f.uid, gid=f.gid)


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
        return any(p.needs_privilege for p in self.previews)

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
    sd = _state_dir(state_dir)
    entry = last_entry(sd)
    if entry is None:
        raise NothingToUndoError("nothing to undo: every recorded change was undone already "
                                 "(or rosnet-tui never wrote a file here)")
    if entry_id is not None and entry.id != entry_id:
        raise StalePreviewError(f"the last change is now #{entry.id}, not #{entry_id}; "
                                "look at the new preview and try again")
    previews, conflicts = [], []
    for f in entry.files:
        current = read_bytes(Path(f.real_path))
        b = _backup_path(sd, f)
        target = b.read_bytes() if b else None
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
    owner = _owner_for(sd)
    _check_root_safe(sd, plan.entry)
    with _locked(sd, owner):
        current = last_entry(sd)
        if current is None or current.id != plan.entry.id:
            raise StalePreviewError("the journal changed since the undo preview; try again")
        for p in plan.previews:
            _check_fresh(p)
        forwards: list[str] = []
        if plan.entry.mappings:  # forwards on the modem: removed there (bounded), or refused
            from rosnet_tui.core.upnp.journal import undo_mappings

            forwards = undo_mappings(plan.entry, force=force)
        restored = []
        for p, f in zip(plan.previews, plan.entry.files, strict=True):
            if p.changed:
                _restore_one(sd, f)
            if file_digest(read_bytes(Path(f.real_path))) != f.before:
                raise ManagedFileError(f"{f.path}: restored content does not match the backup")
            restored.append(Path(f.path))
        plan.entry.undone = _now()
        _save_entry(sd, plan.entry, owner)
        return UndoResult(plan.entry.id, plan.entry.label, restored, forwards)


def undo_last(state_dir: Path | None = None, *, force: bool = False) -> UndoResult:
    """Undo the last apply in one call (plan + apply)."""
    return apply_undo(plan_undo(state_dir), force=force)
