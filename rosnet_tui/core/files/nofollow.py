"""Root in a user's folders: through file descriptors, never following a link the user could make.

Root (sudo, the system unit of the sync service) writes into a user's state dir and, when asked,
that user's ``~/.bashrc``. A path there is the user's to change at any moment: a folder swapped
for a link between root's check and root's write would make root write, create or hand over
something of root's. So root reaches such a folder from ``/`` one component at a time with
``openat(O_NOFOLLOW | O_DIRECTORY)`` and then works only relative to the folder's descriptor:
it creates files there exclusively and without following links, renames within that folder,
changes the owner of what it created on the file's descriptor (``fchown``), and never chowns or
chmods anything by path.

A link is followed only when root's own: the link is root's and sits in a folder that only root
may change (``/var/run -> /run``, a distribution's ``/home -> /var/home``). Any other link on the
way is refused (:class:`LinkRefusedError`): a ``~/.bashrc`` linked elsewhere is not written by
root (the user writes it: ``rosnet-tui ros apply``).
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import stat
import time
from pathlib import Path

from rosnet_tui.core.files.managed_text import ManagedFileError

_DIR_FLAGS = os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW | os.O_CLOEXEC
MAX_LINKS = 40          # as the kernel: a loop of links ends here


class LinkRefusedError(ManagedFileError, OSError):
    """A link on the way that root does not follow (it is not root's own). An OSError too, so
    that what handles a folder it cannot write handles this the same way."""


def _kept(parent: os.stat_result, entry: os.stat_result) -> bool:
    """Whether only root may replace *entry* in the folder *parent*: a folder of root's that
    nobody else may write, or a sticky one (/tmp) and the entry root's."""
    return parent.st_uid == 0 and (not parent.st_mode & 0o022
                                   or bool(parent.st_mode & stat.S_ISVTX and entry.st_uid == 0))


def _trusted_link(dir_fd: int, name: str) -> bool:
    """A link root may follow: root's own, that only root may replace."""
    try:
        lst = os.stat(name, dir_fd=dir_fd, follow_symlinks=False)
        return lst.st_uid == 0 and _kept(os.fstat(dir_fd), lst)
    except OSError:
        return False


def _only_roots(dir_fd: int) -> bool:
    st = os.fstat(dir_fd)
    return st.st_uid == 0 and not st.st_mode & 0o022


def walk(path: Path, *, create_mode: int | None = None,
         owner: tuple[int, int] | None = None) -> tuple[int, bool]:
    """(descriptor of the folder *path*, whether only root may change it: only root may replace
    each folder on the way, and only root may write the folder itself).

    Reached from ``/`` component by component without following a link that is not root's
    own (:class:`LinkRefusedError`). With *create_mode*, missing folders are made with it, and
    handed to *owner* (on their descriptor) when given; folders that exist keep their owner.
    Raises OSError (FileNotFoundError, NotADirectoryError) as os.open does."""
    todo = list(Path(os.path.abspath(path)).parts[1:])
    here = "/"
    fd = os.open("/", _DIR_FLAGS)
    roots_only = True
    links = 0
    try:
        while todo:
            name = todo.pop(0)
            if name in ("", "."):
                continue
            if name == "..":
                raise LinkRefusedError(f"{path}: '..' in a path root walks is refused")
            try:
                nfd = os.open(name, _DIR_FLAGS, dir_fd=fd)
            except FileNotFoundError:
                if create_mode is None:
                    raise
                with contextlib.suppress(FileExistsError):
                    os.mkdir(name, create_mode, dir_fd=fd)
                    nfd = os.open(name, _DIR_FLAGS, dir_fd=fd)
                    if owner is not None:
                        os.fchown(nfd, *owner)
                    os.fchmod(nfd, create_mode)
                    roots_only = roots_only and _kept(os.fstat(fd), os.fstat(nfd))
                    os.close(fd)
                    fd, here = nfd, os.path.join(here, name)
                    continue
                nfd = os.open(name, _DIR_FLAGS, dir_fd=fd)   # made meanwhile: as found
            except OSError as exc:
                st = _lstat(fd, name)
                if st is None or not stat.S_ISLNK(st.st_mode):
                    raise
                if not _trusted_link(fd, name):
                    raise LinkRefusedError(
                        f"{os.path.join(here, name)} is a link root does not follow (it is "
                        f"not root's own); nothing was written through it") from exc
                links += 1
                if links > MAX_LINKS:
                    raise LinkRefusedError(f"{path}: too many links on the way") from exc
                target = os.readlink(name, dir_fd=fd)
                base = "/" if os.path.isabs(target) else here
                todo = list(Path(os.path.normpath(os.path.join(base, target))).parts[1:]) + todo
                os.close(fd)
                fd, here = os.open("/", _DIR_FLAGS), "/"
                roots_only = True
                continue
            roots_only = roots_only and _kept(os.fstat(fd), os.fstat(nfd))
            os.close(fd)
            fd, here = nfd, os.path.join(here, name)
        return fd, roots_only and _only_roots(fd)
    except BaseException:
        os.close(fd)
        raise


def _lstat(dir_fd: int, name: str) -> os.stat_result | None:
    try:
        return os.stat(name, dir_fd=dir_fd, follow_symlinks=False)
    except OSError:
        return None


def make_dir(path: Path, mode: int = 0o700, owner: tuple[int, int] | None = None) -> None:
    """Make the folder *path* (and the missing ones above it) without following a link that is
    not root's; the folders made are handed to *owner*."""
    fd, _ = walk(path, create_mode=mode, owner=owner)
    os.close(fd)


def resolve(path: Path) -> tuple[Path, bool]:
    """Where writing *path* lands, links followed only when root's own (else
    :class:`LinkRefusedError`), and whether only root may change the folder it is in."""
    p = Path(os.path.abspath(path))
    for _ in range(MAX_LINKS):
        try:
            fd, roots_only = walk(p.parent)
        except FileNotFoundError:
            if p.parent == p.parent.parent:
                raise
            parent, roots_only = resolve(p.parent)   # a file in folders still to be made
            return parent / p.name, roots_only
        try:
            st = _lstat(fd, p.name)
            if st is None or not stat.S_ISLNK(st.st_mode):
                return p, roots_only
            if not _trusted_link(fd, p.name):
                raise LinkRefusedError(f"{p} is a link root does not follow (it is not root's "
                                       "own); nothing was written through it")
            p = Path(os.path.normpath(os.path.join(p.parent, os.readlink(p.name, dir_fd=fd))))
        finally:
            os.close(fd)
    raise LinkRefusedError(f"{path}: too many links on the way")


def open_folder(folder: Path) -> tuple[int, bool]:
    """(descriptor of *folder*, whether only root may change it). Root reaches it without
    following a link that is not root's own (:func:`walk`); a user's process as the path
    says (its links are that user's own)."""
    if os.geteuid() == 0:
        return walk(folder)
    return os.open(folder, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC), True


def open_lock(folder: Path, name: str, owner: tuple[int, int] | None = None) -> int:
    """A descriptor of the lock file *name* in *folder* (made 0600 when missing, never through
    a link; handed to *owner* on its descriptor). The caller closes it."""
    dfd, _ = open_folder(folder)
    try:
        fd = os.open(name, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o600,
                     dir_fd=dfd)
    finally:
        os.close(dfd)
    if owner:
        with contextlib.suppress(OSError):
            os.fchown(fd, *owner)
    return fd


def flock_within(fd: int, wait_s: float, step_s: float = 0.02) -> bool:
    """Take an exclusive flock on *fd*, trying for at most *wait_s* seconds; whether it was
    taken."""
    deadline = time.monotonic() + wait_s
    while True:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return True
        except BlockingIOError:
            if time.monotonic() >= deadline:
                return False
            time.sleep(step_s)
