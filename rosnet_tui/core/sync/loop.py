"""The service's loop: wait for the next wake-up (netlink, a watched folder, timers, a worker's
result), run a round, stop cleanly. The service's :class:`Loop` owns its wake-ups, its stop and
the worker threads; it asks the service (:class:`Rounds`) for rounds and when they are due, and
hands each worker's results to the part that asked for them."""

from __future__ import annotations

import contextlib
import logging
import os
import select
import selectors
import signal
import time
from typing import Any, Protocol

from rosnet_tui.core.upnp.forwards import Renewer

from .applier import Applier
from .backoff import Backoff
from .folder_watch import StoreWatch
from .lock import ServiceLock
from .outcome import RoundResult
from .publisher import Publisher
from .state import Report, SyncConfig
from .timing import DEBOUNCE_S, FOLDER_SETTLE_S, MAX_WAIT_S, WORKER_STOP_S, read_period
from .watcher import AddressWatch, NetlinkMonitor, PublicLookup
from .worker import Worker


class Stoppable(Protocol):
    def stop(self) -> None: ...


log = logging.getLogger("rosnet_tui.sync")


class Rounds(Protocol):
    """What the loop asks of the service: its parts, a round, when the next is due."""
    forwards: Renewer
    watch: AddressWatch
    publisher: Publisher
    applier: Applier

    @property
    def interval_s(self) -> float: ...

    def round(self, *, force_public: bool = False) -> RoundResult: ...

    def describe(self) -> str: ...

    def next_wake(self) -> float: ...

    def hold(self, until: float) -> None: ...

    def take_public(self, mono: float, lk: PublicLookup | None) -> None: ...


class Loop:
    """Run and stop: wakes the service for its rounds."""

    def __init__(self, config: SyncConfig, report: Report, service: Rounds) -> None:
        self.config = config
        self.report = report
        self.service = service
        self.stopping = False
        self.backoff = Backoff()           # an unexpected error in a round
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_w, False)
        os.set_blocking(self._wake_r, False)

    def stop(self) -> None:
        """Ask the loop to stop (safe from a signal handler or another thread)."""
        self.stopping = True
        self._wake_loop()

    def _wake_loop(self) -> None:
        with contextlib.suppress(OSError):
            os.write(self._wake_w, b"x")

    def _start(self, lock: ServiceLock) -> None:
        lock.acquire()
        self.report.set(pid=os.getpid(), started_at=time.time(), stopped_at=None)
        log.info("%s", self.service.describe())

    def _finish(self, lock: ServiceLock) -> None:
        self.report.set(stopped_at=time.time())
        self.report.save(self.config.paths.state_dir, force=True)
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
                     read_period(self.service.interval_s))
        sel = selectors.DefaultSelector()
        sel.register(self._wake_r, selectors.EVENT_READ, "wake")
        if monitor is not None:
            sel.register(monitor.fileno(), selectors.EVENT_READ, "netlink")
        folder_watch = StoreWatch(self.config.watch_folder)
        applier, watch = self.service.applier, self.service.watch
        if self.config.run_checks:
            applier.checks = Worker("checks", applier.affected_checks, self._wake_loop)
        watch.lookups = Worker("public-IP lookup", watch.lookup, self._wake_loop)
        force_public = True
        try:
            while not self.stopping:
                try:
                    self._collect()
                    self.service.round(force_public=force_public)
                except Exception:  # a bug must not kill the service: log it, keep going
                    log.exception("unexpected error in a sync round; going on")
                    self.report.error("round", "an unexpected error (see the log); retrying")
                    pause = self.backoff.fail()
                    self.service.hold(time.monotonic() + pause)
                else:
                    if self.backoff.succeed():
                        self.report.clear_error("round")
                force_public = False
                if self.stopping:
                    break
                self.service.publisher.follow_folder(folder_watch, sel, self.service.interval_s)
                force_public = self._wait(sel, monitor, folder_watch)
        finally:
            for worker in (applier.checks, watch.lookups):
                if worker is not None:
                    worker.close(WORKER_STOP_S)
            applier.checks = watch.lookups = None
            watch.busy = False
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
        lookups, checks = self.service.watch.lookups, self.service.applier.checks
        if lookups is not None:
            for started, lookup in lookups.collect():
                self.service.take_public(started, lookup)
        if checks is not None:
            for tag, results in checks.collect():
                self.service.applier.take_checks(tag, results)

    def _wait(self, sel: selectors.BaseSelector, monitor: NetlinkMonitor | None,
              watch: StoreWatch) -> bool:
        """Sleep until something is due, :meth:`stop`, a network change (True) or a peer's
        record completed in the watched folder. Folder events that change no record (a sync
        tool's temporary files) go on waiting; folder events are taken at most every
        FOLDER_SETTLE_S, so a storm of them costs a bounded number of reads."""
        period = read_period(self.service.interval_s)
        while not self.stopping:
            timeout = min(MAX_WAIT_S, max(0.02, self.service.next_wake() - time.monotonic()))
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
                    while time.monotonic() < deadline and not self.stopping:
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
                        self.service.publisher.read_soon()
                        return False
            if time.monotonic() >= self.service.next_wake():
                return False
        return False

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
