"""The service's helpers that are not its logic: the one-instance lock, the worker threads, and
the checks a change affects (through the one door to run checks)."""

from __future__ import annotations

import contextlib
import copy
import fcntl
import logging
import os
import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rosnet_tui.core.bashrc import master_uri
from rosnet_tui.core.hosts import (
    WriterSettingsError,
)
from rosnet_tui.core.settings import Settings

from .status import (
    state_owner,
    sync_dir,
)

log = logging.getLogger("rosnet_tui.sync")

AFFECTED_CHECKS = ("linux.hosts", "linux.resolve", "linux.ssh", "ros.master")
VERIFY_EVERY_S = 30.0        # look at the hosts file again even when nothing changed
HEARTBEAT_S = 3600.0         # republish an unchanged record this often (its age then says alive)
DEBOUNCE_S = 0.3             # netlink: wait for the burst of messages of one change to end
FORCED_GAP_S = 2.0           # a network change asks for the public IP at most this often
MAX_WAIT_S = 5.0
WORKER_STOP_S = 2.0          # stopping waits this long at most for a check or lookup under way
FOLDER_SETTLE_S = 0.05       # a watched folder: its events are taken at most this often

log = logging.getLogger("rosnet_tui.sync")


class SyncError(Exception):
    """The service cannot start (settings, store configuration, another instance)."""


def read_period(interval_s: float) -> float:
    """How often peers' records are read: a quarter of the poll interval, 0.25 .. 1 s (a
    watched folder is read when a record changes, and every interval_s besides)."""
    return min(1.0, max(0.25, float(interval_s) / 4))


@dataclass
class RoundResult:
    ok: bool
    applied: bool
    errors: dict[str, str]




class _ServiceLock:
    """One sync service per state dir: an flock held while it runs."""

    def __init__(self, state_dir: Path) -> None:
        self.path = sync_dir(state_dir) / "service.lock"
        self.fd: int | None = None

    def acquire(self) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
        try:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o600)
        except OSError as exc:
            raise SyncError(f"cannot open the lock {self.path}: {exc.strerror} (is the service "
                            "running as another user?)") from None
        owner = state_owner(self.path.parent.parent)
        if owner:
            with contextlib.suppress(OSError):
                os.fchown(fd, *owner)
                os.chown(self.path.parent, *owner)
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


class _Worker:
    """Slow work of the service on its own thread while the service runs (the affected checks;
    the public-IP lookup), so reading records and writing the hosts file never wait on it: a
    peer that does not answer holds ssh and ros.master for their whole timeouts, a silent
    what-is-my-IP service the lookup. One job at a time; a newer job replaces one not started
    yet; results come back through :meth:`collect` (None: the job failed, logged), and *wake*
    rouses the loop."""

    def __init__(self, name: str, job: Callable[[Any], Any], wake: Callable[[], None]) -> None:
        self.name = name
        self._job = job
        self._wake = wake
        self._cond = threading.Condition()
        self._pending: tuple[Any, Any] | None = None
        self._done: list[tuple[Any, Any]] = []
        self._closed = False
        self._thread: threading.Thread | None = None

    def submit(self, tag: Any, arg: Any) -> None:
        with self._cond:
            if self._closed:
                return
            self._pending = (tag, arg)
            if self._thread is None:
                self._thread = threading.Thread(target=self._work, daemon=True,
                                                name=f"rosnet-sync-{self.name}")
                self._thread.start()
            self._cond.notify()

    def _work(self) -> None:
        while True:
            with self._cond:
                while self._pending is None and not self._closed:
                    self._cond.wait(1.0)
                if self._closed or self._pending is None:
                    return
                tag, arg = self._pending
                self._pending = None
            try:
                result = self._job(arg)
            except Exception:  # a bug must not end the thread: logged, the result is None
                log.exception("unexpected error in the %s of the sync service", self.name)
                result = None
            with self._cond:           # closed: the loop is gone (and its wake pipe with it)
                if self._closed:
                    return
                self._done.append((tag, result))
                self._wake()

    def collect(self) -> list[tuple[Any, Any]]:
        with self._cond:
            done, self._done = self._done, []
        return done

    def close(self, timeout_s: float) -> None:
        """No more jobs; wait (bounded) for one under way. Its result is dropped."""
        with self._cond:
            self._closed = True
            self._pending = None
            self._cond.notify_all()
        if self._thread is not None:
            self._thread.join(timeout_s)


# --------------------------------------------------------------------------- the checks
def run_affected_checks(settings: Settings, *, hosts_path: Path, bashrc_path: Path | None,
                        state_dir: Path, ids: tuple[str, ...] = AFFECTED_CHECKS,
                        ) -> list[dict[str, Any]]:
    """Run the checks a hosts/ROS change affects (concurrently, each under its timeout):
    [{"id", "status", "summary"}] in *ids* order."""
    from rosnet_tui.core.checks.runner import RunOptions, run_now, select

    if settings.ros2:  # the ROS 2 counterparts of the ROS 1 checks a new address affects
        ids = tuple(dict.fromkeys("ros2.router" if i.startswith("ros.") else i for i in ids))
    specs = select(ids=ids)
    env = dict(os.environ)
    with contextlib.suppress(WriterSettingsError):
        env["ROS_MASTER_URI"] = master_uri(settings)
    for v in ("ROS_IP", "ROS_HOSTNAME"):
        env.pop(v, None)
    opts = RunOptions(hosts_path=hosts_path, state_dir=state_dir, env=env, upnp=False,
                      bashrc_path=bashrc_path)
    got = run_now(copy.deepcopy(settings), specs, opts)
    return [{"id": r.id, "status": r.status.value, "summary": r.summary} for r in got]
