"""The service's loop: wait for the next wake-up (netlink, a watched folder, timers, a worker's
result), run a round, stop cleanly. The service's :class:`Loop`, handed its state, its applier
and the service's rounds (:class:`Rounds`)."""

from __future__ import annotations

import contextlib
import logging
import os
import select
import selectors
import signal
import time
from typing import Any, Protocol

from rosnet_tui.core.config.settings_model import Settings
from rosnet_tui.core.upnp.forwards import Renewer

from .applier import Applier
from .folder_watch import StoreWatch
from .lock import ServiceLock
from .outcome import RoundResult
from .state import SyncConfig, SyncState
from .timing import DEBOUNCE_S, FOLDER_SETTLE_S, MAX_WAIT_S, WORKER_STOP_S, read_period
from .watcher import NetlinkMonitor, PublicLookup
from .worker import Worker


class Stoppable(Protocol):
    def stop(self) -> None: ...


log = logging.getLogger("rosnet_tui.sync")


class Rounds(Protocol):
    """What the loop asks of the service: a round, and the public-IP lookup it runs on a thread."""
    forwards: Renewer

    def round(self, *, force_public: bool = False) -> RoundResult: ...

    def lookup_public(self, settings: Settings) -> PublicLookup: ...

    def take_public(self, mono: float, lk: PublicLookup | None) -> None: ...


class Loop:
    """Run and stop: wakes the service for its rounds; reads and changes its :class:`SyncState`."""

    def __init__(self, state: SyncState, config: SyncConfig, applier: Applier,
                 service: Rounds) -> None:
        self.state = state
        self.config = config
        self.applier = applier
        self.service = service
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_w, False)
        os.set_blocking(self._wake_r, False)

    def stop(self) -> None:
        """Ask the loop to stop (safe from a signal handler or another thread)."""
        self.state.stopping = True
        self._wake_loop()

    def _wake_loop(self) -> None:
        with contextlib.suppress(OSError):
            os.write(self._wake_w, b"x")

    def _next_wake(self) -> float:
        st = self.state
        apply_due = st.next_apply if st.dirty else max(st.next_apply, st.next_verify)
        cands = [self.state.next_fetch]
        if not self.state.public_busy:      # under way: its answer wakes the loop
            cands.append(self.state.next_public)
        if self.state.public_answered or not self.state.public_busy:  # else: after the 1st answer
            cands.append(apply_due)
        if self.state.recheck_at is not None:
            cands.append(self.state.recheck_at)
        return min(cands)

    def _start(self, lock: ServiceLock) -> None:
        lock.acquire()
        assert self.state.settings is not None
        self.state.status.update(pid=os.getpid(), started_at=time.time(), stopped_at=None)
        s = self.state.settings
        log.info("sync for %s (%s): %s; public IP every %g s, peers read every %g s; hosts file "
                 "%s%s", s.this.name, s.this.role,
                 self.state.store.describe() if self.state.store else "?",
                 self.state.interval_s, read_period(self.state.interval_s),
                 self.config.paths.hosts_path, f", ROS block in {self.config.paths.bashrc_path}" if self.config.write_bashrc else "")

    def _finish(self, lock: ServiceLock) -> None:
        self.state.status["stopped_at"] = time.time()
        self.applier.save_status(force=True)
        lock.release()

    def run_once(self) -> RoundResult:
        """One full round (the public IP asked now), for cron and tests."""
        lock = ServiceLock(self.config.paths.state_dir)
        self._start(lock)
        try:
            return self.service.round(force_public=True)
        finally:
            self._finish(lock)
            self.close()

    def run(self) -> int:
        """Run until :meth:`stop` (SIGTERM/SIGINT through :func:`install_signal_handlers`)."""
        lock = ServiceLock(self.config.paths.state_dir)
        self._start(lock)
        monitor = NetlinkMonitor.open() if self.config.netlink else None
        if self.config.netlink and monitor is None:
            log.info("no netlink here: local address changes are seen within %g s",
                     read_period(self.state.interval_s))
        sel = selectors.DefaultSelector()
        sel.register(self._wake_r, selectors.EVENT_READ, "wake")
        if monitor is not None:
            sel.register(monitor.fileno(), selectors.EVENT_READ, "netlink")
        folder_watch = StoreWatch(self.config.watch_folder)
        if self.config.run_checks:
            self.state.checks = Worker("checks", self.applier.affected_checks, self._wake_loop)
        self.state.lookups = Worker("public-IP lookup", self.service.lookup_public, self._wake_loop)
        force_public = True
        try:
            while not self.state.stopping:
                try:
                    self._collect()
                    self.service.round(force_public=force_public)
                except Exception:  # a bug must not kill the service: log it, keep going
                    log.exception("unexpected error in a sync round; going on")
                    self.state.error("round", "an unexpected error (see the log); retrying")
                    pause = self.state.backoff["round"].fail()
                    self.state.next_fetch = self.state.next_apply = time.monotonic() + pause
                else:
                    if self.state.backoff["round"].succeed():
                        self.state.clear_error("round")
                force_public = False
                if self.state.stopping:
                    break
                self._follow_folder(folder_watch, sel)
                force_public = self._wait(sel, monitor, folder_watch)
        finally:
            for worker in (self.state.checks, self.state.lookups):
                if worker is not None:
                    worker.close(WORKER_STOP_S)
            self.state.checks = self.state.lookups = None
            self.state.public_busy = False
            folder_watch.close(sel)
            sel.close()
            if monitor is not None:
                monitor.close()
            if self.config.unmap_on_stop:
                self.service.forwards.unmap()
            log.info("sync stopped")
            self._finish(lock)
            self.close()
        return 0

    def _collect(self) -> None:
        """Take what the service's threads finished: public-IP answers, checks' verdicts."""
        if self.state.lookups is not None:
            for started, lookup in self.state.lookups.collect():
                self.service.take_public(started, lookup)
        if self.state.checks is not None:
            for tag, results in self.state.checks.collect():
                self.applier.take_checks(tag, results)

    def _wait(self, sel: selectors.BaseSelector, monitor: NetlinkMonitor | None,
              watch: StoreWatch) -> bool:
        """Sleep until something is due, :meth:`stop`, a network change (True) or a peer's
        record completed in the watched folder. Folder events that change no record (a sync
        tool's temporary files) go on waiting; folder events are taken at most every
        FOLDER_SETTLE_S, so a storm of them costs a bounded number of reads."""
        period = read_period(self.state.interval_s)
        while not self.state.stopping:
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
                    while time.monotonic() < deadline and not self.state.stopping:
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
                        self.state.next_fetch = min(self.state.next_fetch, time.monotonic())
                        return False
            if time.monotonic() >= self._next_wake():
                return False
        return False

    def _follow_folder(self, watch: StoreWatch, sel: selectors.BaseSelector) -> None:
        """Keep the watch on the store's folder (a folder store): started, kept or ended."""
        if self.state.store is None:
            return
        started_or_ended = watch.follow(self.state.store, sel, read_period(self.state.interval_s))
        if started_or_ended or watch.active != self.state.folder_watched:
            # a change may be unseen
            self.state.next_fetch = min(self.state.next_fetch, time.monotonic())
        self.state.folder_watched = watch.active
        if self.state.status.get("folder_watch") != watch.describe():
            self.state.status["folder_watch"] = watch.describe()
            self.state.status_dirty = True

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
