"""What the sync service is given (:class:`SyncConfig`) and what it knows while it runs
(:class:`SyncState`): one value each, shared by the service, its applier and its loop.

The state also keeps the service's messages: an error per part (kept in the status, logged when
it changes), messages logged once, and the back-off of each part.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Any

from rosnet_tui.core.config.paths import Paths
from rosnet_tui.core.config.settings_model import Settings

from .backoff import Backoff, backoff_cap
from .plan import Plan
from .records import Candidate, Record
from .store import RecordStore
from .timing import FORCED_GAP_S
from .watcher import LocalAddress
from .worker import Worker

log = logging.getLogger("rosnet_tui.sync")

BACKOFF_PARTS = ("settings", "public_ip", "store", "apply", "round")


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


@dataclass
class SyncState:
    """See the module docstring. Times named ``next_*`` and ``recheck_at`` are monotonic."""
    status: dict[str, Any]
    interval_override: float | None = None
    settings: Settings | None = None
    settings_key: Any = None
    store: RecordStore | None = None
    store_fixed: bool = False                 # handed in: the settings do not choose it
    store_key: Any = None
    folder_watched: bool = False              # the loop watches the store's folder now
    local: LocalAddress | None = None
    public_ip: str = ""
    own: Record | None = None                 # our current record (published or found)
    peers: dict[str, Candidate] = field(default_factory=dict)  # the last good record of each
    applied: dict[str, Record] = field(default_factory=dict)   # each peer's record applied
    fetched_once: bool = False
    own_missing: bool = False
    published_at: float = 0.0
    dirty: bool = True
    next_public: float = 0.0
    last_public_poll: float = -FORCED_GAP_S
    next_fetch: float = 0.0
    next_publish: float = 0.0
    next_apply: float = 0.0
    next_verify: float = 0.0
    recheck_at: float | None = None
    recheck_left: list[float] = field(default_factory=list)
    checks: Worker | None = None              # the checks' thread while the loop runs
    lookups: Worker | None = None             # the public-IP lookup's thread, likewise
    public_busy: bool = False                 # a lookup is under way on that thread
    public_answered: bool = False             # a lookup has answered (or failed) once
    last_plan: Plan | None = None
    backoff: dict[str, Backoff] = field(
        default_factory=lambda: {k: Backoff() for k in BACKOFF_PARTS})
    said: set[Any] = field(default_factory=set)   # messages logged once
    status_dirty: bool = True
    alive_saved: float = 0.0
    stopping: bool = False

    def __post_init__(self) -> None:
        now = time.monotonic()
        self.next_public = self.next_fetch = self.next_publish = now
        self.next_apply = self.next_verify = now

    @property
    def interval_s(self) -> float:
        if self.interval_override is not None:
            return float(self.interval_override)
        return float(self.settings.sync.interval_s) if self.settings else 60.0

    def known_public(self) -> str:
        if self.public_ip:
            return self.public_ip
        if self.own and self.own.public_ip:
            return self.own.public_ip
        return self.settings.this.public_ip if self.settings else ""

    # ------------------------------------------------------------------ messages
    def remember(self, key: Any) -> bool:
        """True the first time *key* is seen (bounded memory for a service that runs for ever)."""
        if key in self.said:
            return False
        if len(self.said) > 2000:
            self.said.clear()
        self.said.add(key)
        return True

    def once(self, key: Any, level: int, msg: str, *args: Any) -> None:
        if not self.remember(key):
            return
        log.log(level, msg, *args)

    def error(self, part: str, message: str, retry_in: float | None = None) -> None:
        errors = self.status["errors"]
        prev = errors.get(part)
        if prev is None or prev.get("message") != message:
            more = f" (next try in {retry_in:.0f} s)" if retry_in else ""
            log.warning("%s: %s%s", part, message, more)
            errors[part] = {"since": prev["since"] if prev else time.time(), "message": message}
            self.status["last_error"] = {"at": time.time(), "part": part, "message": message}
        else:
            log.debug("%s still failing: %s", part, message)
        errors[part]["retry_in_s"] = retry_in
        self.status_dirty = True

    def clear_error(self, part: str, recovered_msg: str | None = None) -> None:
        if self.status["errors"].pop(part, None) is not None:
            log.info("%s: %s", part, recovered_msg or "works again")
            self.status_dirty = True

    def fail(self, part: str, message: str, mono: float) -> float:
        """Count a failure of *part*: the monotonic time of its next try."""
        self.backoff[part].cap_s = backoff_cap(self.interval_s)
        delay = self.backoff[part].fail()
        self.error(part, message, delay)
        return mono + delay

    def errors(self) -> dict[str, str]:
        return {k: v["message"] for k, v in self.status["errors"].items()}
