"""The service's loop: wait for the next wake-up (netlink, a watched folder, timers, a worker's
result), run a round, stop cleanly. A mixin of :class:`~rosnet_tui.core.sync.service.SyncService`."""

from __future__ import annotations

import contextlib
import logging
import os
import select
import selectors
import signal
import time
from typing import Any, Protocol

from .folder_watch import StoreWatch
from .lock import ServiceLock
from .outcome import RoundResult
from .timing import DEBOUNCE_S, FOLDER_SETTLE_S, MAX_WAIT_S, WORKER_STOP_S, read_period
from .watcher import NetlinkMonitor
from .worker import Worker


class Stoppable(Protocol):
    def stop(self) -> None: ...


log = logging.getLogger("rosnet_tui.sync")


class LoopMixin:
    """Run and stop (the state lives in SyncService)."""

    def stop(self) -> None:
        """Ask the loop to stop (safe from a signal handler or another thread)."""
        self._stop = True
        self._wake_loop()

    def _wake_loop(self) -> None:
        with contextlib.suppress(OSError):
            os.write(self._wake_w, b"x")

    def _next_wake(self) -> float:
        apply_due = self.next_apply if self.dirty else max(self.next_apply, self.next_verify)
        cands = [self.next_fetch]
        if not self._public_busy:      # under way: its answer wakes the loop
            cands.append(self.next_public)
        if self._public_answered or not self._public_busy:   # else: after the first answer
            cands.append(apply_due)
        if self.recheck_at is not None:
            cands.append(self.recheck_at)
        return min(cands)

    def _start(self, lock: ServiceLock) -> None:
        lock.acquire()
        assert self.settings is not None
        self.status.update(pid=os.getpid(), started_at=time.time(), stopped_at=None)
        s = self.settings
        log.info("sync for %s (%s): %s; public IP every %g s, peers read every %g s; hosts file "
                 "%s%s", s.this.name, s.this.role, self.store.describe() if self.store else "?",
                 self.interval_s, read_period(self.interval_s), self.hosts_path,
                 f", ROS block in {self.bashrc_path}" if self.bashrc_path else "")

    def _finish(self, lock: ServiceLock) -> None:
        self.status["stopped_at"] = time.time()
        self._save_status(force=True)
        lock.release()

    def run_once(self) -> RoundResult:
        """One full round (the public IP asked now), for cron and tests."""
        lock = ServiceLock(self.state_dir)
        self._start(lock)
        try:
            return self.round(force_public=True)
        finally:
            self._finish(lock)
            self.close()

    def run(self) -> int:
        """Run until :meth:`stop` (SIGTERM/SIGINT through :func:`install_signal_handlers`)."""
        lock = ServiceLock(self.state_dir)
        self._start(lock)
        monitor = NetlinkMonitor.open() if self.use_netlink else None
        if self.use_netlink and monitor is None:
            log.info("no netlink here: local address changes are seen within %g s",
                     read_period(self.interval_s))
        sel = selectors.DefaultSelector()
        sel.register(self._wake_r, selectors.EVENT_READ, "wake")
        if monitor is not None:
            sel.register(monitor.fileno(), selectors.EVENT_READ, "netlink")
        folder_watch = StoreWatch(self.use_folder_watch)
        if self.do_checks:
            self._checks = Worker("checks", self._affected_checks, self._wake_loop)
        self._lookups = Worker("public-IP lookup", self._lookup_public, self._wake_loop)
        force_public = True
        try:
            while not self._stop:
                try:
                    self._collect()
                    self.round(force_public=force_public)
                except Exception:  # a bug must not kill the service: log it, keep going
                    log.exception("unexpected error in a sync round; going on")
                    self._error("round", "an unexpected error (see the log); retrying")
                    pause = self.backoff["round"].fail()
                    self.next_fetch = self.next_apply = time.monotonic() + pause
                else:
                    if self.backoff["round"].succeed():
                        self._clear_error("round")
                force_public = False
                if self._stop:
                    break
                self._follow_folder(folder_watch, sel)
                force_public = self._wait(sel, monitor, folder_watch)
        finally:
            for worker in (self._checks, self._lookups):
                if worker is not None:
                    worker.close(WORKER_STOP_S)
            self._checks = self._lookups = None
            self._public_busy = False
            folder_watch.close(sel)
            sel.close()
            if monitor is not None:
                monitor.close()
            if self.unmap_on_stop:
                self.forwards.unmap()
            log.info("sync stopped")
            self._finish(lock)
            self.close()
        return 0

    def _collect(self) -> None:
        """Take what the service's threads finished: public-IP answers, checks' verdicts."""
        if self._lookups is not None:
            for started, lookup in self._lookups.collect():
                self._take_public(started, lookup)
        if self._checks is not None:
            for tag, results in self._checks.collect():
                self._take_checks(tag, results)

    def _wait(self, sel: selectors.BaseSelector, monitor: NetlinkMonitor | None,
              watch: StoreWatch) -> bool:
        """Sleep until something is due, :meth:`stop`, a network change (True) or a peer's
        record completed in the watched folder. Folder events that change no record (a sync
        tool's temporary files) go on waiting; folder events are taken at most every
        FOLDER_SETTLE_S, so a storm of them costs a bounded number of reads."""
        period = read_period(self.interval_s)
        while not self._stop:
            timeout = min(MAX_WAIT_S, max(0.02, self._next_wake() - time.monotonic()))
            ready = sel.select(timeout)
            if not ready:
                return False
            for key, _ in ready:
                if key.data == "wake":
                    with contextlib.suppress(OSError):
                        os.read(self._wake_r, 64)
                    return False
                if key.data == "netlink" and monitor is not None and monitor.drain():
                    deadline = time.monotonic() + DEBOUNCE_S
                    while time.monotonic() < deadline and not self._stop:
                        # netlink only: other ready descriptors would make this spin
                        if select.select([monitor.fileno()], [], [],
                                         max(0.0, deadline - time.monotonic()))[0]:
                            monitor.drain()
                    log.info("the kernel reports a link, address or route change")
                    return True
                if key.data == StoreWatch.SELECTOR_KEY:
                    changed = watch.drain(sel, period)
                    # the rest of the burst (a sync tool completes several files) comes in
                    # meanwhile; only stop() cuts this pause short
                    select.select([self._wake_r], [], [], FOLDER_SETTLE_S)
                    changed = watch.drain(sel, period) or changed
                    if changed:
                        self.next_fetch = min(self.next_fetch, time.monotonic())
                        return False
            if time.monotonic() >= self._next_wake():
                return False
        return False

    def _follow_folder(self, watch: StoreWatch, sel: selectors.BaseSelector) -> None:
        """Keep the watch on the store's folder (a folder store): started, kept or ended."""
        if self.store is None:
            return
        started_or_ended = watch.follow(self.store, sel, read_period(self.interval_s))
        if started_or_ended or watch.active != self._folder_watched:
            self.next_fetch = min(self.next_fetch, time.monotonic())  # a change may be unseen
        self._folder_watched = watch.active
        if self.status.get("folder_watch") != watch.describe():
            self.status["folder_watch"] = watch.describe()
            self._status_dirty = True

    def close(self) -> None:
        for fd in (self._wake_r, self._wake_w):
            with contextlib.suppress(OSError):
                os.close(fd)
        self._wake_r = self._wake_w = -1




def install_signal_handlers(service: Stoppable) -> None:
    """SIGTERM and SIGINT (Ctrl-C) stop the service cleanly after the current step."""
    def handler(signum: int, frame: Any) -> None:
        log.info("stopping (%s)", signal.Signals(signum).name)
        service.stop()

    signal.signal(signal.SIGTERM, handler)
    signal.signal(signal.SIGINT, handler)
