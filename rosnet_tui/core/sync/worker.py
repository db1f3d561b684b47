"""A worker thread of the sync service: slow work (checks, the public-IP lookup) off its loop."""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import Any

log = logging.getLogger("rosnet_tui.sync")


class Worker:
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
