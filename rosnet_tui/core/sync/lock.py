"""One sync service per state dir: an flock held while it runs."""

from __future__ import annotations

import contextlib
import fcntl
import os
from pathlib import Path

from rosnet_tui.core.files.managed_text import ManagedFileError
from rosnet_tui.core.files.managed_write import open_folder
from rosnet_tui.core.files.undo_journal import make_private_dir
from rosnet_tui.core.saved.state import state_owner, sync_dir

from .outcome import SyncError


class ServiceLock:
    """One sync service per state dir: an flock held while it runs."""

    def __init__(self, state_dir: Path) -> None:
        self.path = sync_dir(state_dir) / "service.lock"
        self.fd: int | None = None

    def acquire(self) -> None:
        owner = state_owner(self.path.parent.parent)
        try:   # as root: through descriptors, following no link of the user's
            make_private_dir(self.path.parent, owner)
            dfd, _ = open_folder(self.path.parent)
            try:
                fd = os.open(self.path.name, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC,
                             0o600, dir_fd=dfd)
            finally:
                os.close(dfd)
        except (OSError, ManagedFileError) as exc:   # a link refused, for one
            raise SyncError(f"cannot open the lock {self.path}: {exc} (is the service "
                            "running as another user?)") from None
        if owner:
            with contextlib.suppress(OSError):
                os.fchown(fd, *owner)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            try:
                other = os.read(fd, 32).decode(errors="replace").strip()
            except OSError:
                other = "?"
            os.close(fd)
            raise SyncError(f"another rosnet-tui sync is running with this state dir "
                            f"(pid {other or '?'}; lock {self.path})") from None
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        self.fd = fd

    def release(self) -> None:
        if self.fd is not None:
            with contextlib.suppress(OSError):
                os.ftruncate(self.fd, 0)
            os.close(self.fd)
            self.fd = None
