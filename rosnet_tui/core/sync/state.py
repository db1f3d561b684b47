"""What the sync service is given (:class:`SyncConfig`) and what it says (:class:`Report`).

Each part of the service keeps its own state (the watcher its addresses, the publisher the
records, the applier what it wrote, the loop its wake-ups); none writes another's. What they
say goes through the :class:`Report`: the status document ``rosnet-tui sync status`` shows
(each part writes its own entries through the methods below, never the document itself), an
error per part (kept in the status, logged when it changes) and messages logged once.
"""

from __future__ import annotations

import copy
import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rosnet_tui.core.config.paths import Paths

from .backoff import Backoff, backoff_cap
from .status import ALIVE_EVERY_S, empty_status, save_status

log = logging.getLogger("rosnet_tui.sync")


@dataclass(frozen=True)
class SyncConfig:
    """The service's files and switches, fixed for its life."""
    paths: Paths
    write_bashrc: bool = False       # keep the ROS block of paths.bashrc_path in step (ROS 1)
    run_checks: bool = True
    interval_override: float | None = None
    save_learned: bool = True
    netlink: bool = True
    watch_folder: bool = True
    unmap_on_stop: bool = False      # remove our forwards on the modem when stopped


class Report:
    """The service's status document and messages; see the module docstring."""

    def __init__(self) -> None:
        self._status: dict[str, Any] = empty_status()
        self._said: set[Any] = set()      # messages logged once
        self._dirty = True                # the document changed since it was saved
        self._alive_saved = 0.0

    # ------------------------------------------------------------------ the document
    def get(self, key: str) -> Any:
        """A copy of the status entry *key* (the document itself is written only here)."""
        return copy.deepcopy(self._status.get(key))

    def set(self, *, dirty: bool = True, **entries: Any) -> None:
        """Set top-level entries (name, role, pid, profile, last_change, folder_watch, ...)."""
        self._status.update(entries)
        self._dirty = self._dirty or dirty

    def update_own(self, *, dirty: bool = True, **fields: Any) -> None:
        """This component's entry (``own``)."""
        self._status["own"].update(fields)
        self._dirty = self._dirty or dirty

    def peer(self, name: str) -> dict[str, Any]:
        """A copy of the entry of peer *name* ({} when none)."""
        return dict(self._status["peers"].get(name) or {})

    def update_peer(self, name: str, *, dirty: bool = True, **fields: Any) -> None:
        self._status["peers"].setdefault(name, {}).update(fields)
        self._dirty = self._dirty or dirty

    def update_last_change(self, **fields: Any) -> None:
        """Add to the entry of the last change written (nothing when none)."""
        if self._status.get("last_change") is not None:
            self._status["last_change"].update(fields)
        self._dirty = True

    def add_refused(self, entry: dict[str, Any], keep: int) -> None:
        self._status["refused"] = (self._status["refused"] + [entry])[-keep:]
        self._dirty = True

    def save(self, state_dir: Path, force: bool = False) -> None:
        """Write the document when it changed (or now and then: the service is alive)."""
        now = time.time()
        if not (force or self._dirty or now - self._alive_saved > ALIVE_EVERY_S):
            return
        self._status["alive_at"] = now
        try:
            save_status(state_dir, self._status)
        except OSError as exc:
            self.once(("status", str(exc)), logging.WARNING, "cannot save the status: %s", exc)
            return
        self._dirty = False
        self._alive_saved = now

    # ------------------------------------------------------------------ messages
    def remember(self, key: Any) -> bool:
        """True the first time *key* is seen (bounded memory for a service that runs for ever)."""
        if key in self._said:
            return False
        if len(self._said) > 2000:
            self._said.clear()
        self._said.add(key)
        return True

    def once(self, key: Any, level: int, msg: str, *args: Any) -> None:
        if not self.remember(key):
            return
        log.log(level, msg, *args)

    def error(self, part: str, message: str, retry_in: float | None = None) -> None:
        errors = self._status["errors"]
        prev = errors.get(part)
        if prev is None or prev.get("message") != message:
            more = f" (next try in {retry_in:.0f} s)" if retry_in else ""
            log.warning("%s: %s%s", part, message, more)
            errors[part] = {"since": prev["since"] if prev else time.time(), "message": message}
            self._status["last_error"] = {"at": time.time(), "part": part, "message": message}
        else:
            log.debug("%s still failing: %s", part, message)
        errors[part]["retry_in_s"] = retry_in
        self._dirty = True

    def clear_error(self, part: str, recovered_msg: str | None = None) -> None:
        if self._status["errors"].pop(part, None) is not None:
            log.info("%s: %s", part, recovered_msg or "works again")
            self._dirty = True

    def fail(self, part: str, backoff: Backoff, message: str, mono: float,
             interval_s: float) -> float:
        """Count a failure of *part* on its *backoff*: the monotonic time of its next try."""
        backoff.cap_s = backoff_cap(interval_s)
        delay = backoff.fail()
        self.error(part, message, delay)
        return mono + delay

    def errors(self) -> dict[str, str]:
        return {k: v["message"] for k, v in self._status["errors"].items()}

