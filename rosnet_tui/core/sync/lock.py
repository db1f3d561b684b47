"""One sync service per state dir: an flock held while it runs."""

from __future__ import annotations

import contextlib
import fcntl
import os
from pathlib import Path

from rosnet_tui.core.files import nofollow
from rosnet_tui.core.files.managed_text import ManagedFileError
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
            fd = nofollow.open_lock(self.path.parent, self.path.name, owner)
        except (OSError, ManagedFileError) as exc:   # a link refused, for one
            raise SyncError(f"cannot open the lock {self.path}: {exc} (is the service "
                            "running as another user?)") from None
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
