"""The sync service: publish this component's record, follow the peers' records, keep the hosts
set and ROS_MASTER_URI right, re-run the affected checks.

One round (:meth:`SyncService.round`): reload the settings if they changed, look at the local
address (every round; netlink wakes the loop at once on a change), poll the public IP when due,
read the store, publish our record when its content changed, and when anything changed apply the
new hosts set (and the ROS block) through the safe writer, then run the affected checks.

While the service runs, a watched shared folder wakes the loop as soon as a peer's record is
complete (:mod:`.folder_watch`), and the public-IP lookup and the checks run on threads of their
own, so neither a slow what-is-my-IP service nor a peer that does not answer delays a record.

Failures never undo a good configuration: an unreachable store, no internet or a refused write
keeps the last good state, backs off (bounded) and is logged once, with the recovery logged too.
"""

from __future__ import annotations

import contextlib
import copy
import logging
import math
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from rosnet_tui.core.hosts import (
    DEFAULT_HOSTS_PATH,
)
from rosnet_tui.core.pairing import CertRenewer
from rosnet_tui.core.settings import Settings, SettingsError, load_settings
from rosnet_tui.core.upnp.forwards import Renewer

from .applied import applied_path, load_applied, save_applied
from .backoff import Backoff, backoff_cap
from .plan import Plan
from .records import (
    Candidate,
    Record,
    RecordError,
    check_record,
    format_time,
    new_record,
    parse_record,
    successor_problem,
)
from .service_apply import RECHECK_AFTER_S, ApplyMixin  # noqa: F401
from .service_loop import LoopMixin, install_signal_handlers  # noqa: F401
from .status import (
    MAX_REFUSED,
    empty_status,
    load_status,
)
from .store import RecordStore, StoreConfigError, StoreError, make_store
from .watcher import LocalAddress, PublicLookup, lookup_public_ip, observe_local
from .workers import (  # noqa: F401 (re-exported)
    AFFECTED_CHECKS,
    DEBOUNCE_S,
    FOLDER_SETTLE_S,
    FORCED_GAP_S,
    HEARTBEAT_S,
    MAX_WAIT_S,
    VERIFY_EVERY_S,
    WORKER_STOP_S,
    RoundResult,
    SyncError,
    _ServiceLock,
    _Worker,
    read_period,
    run_affected_checks,
)

log = logging.getLogger("rosnet_tui.sync")


class SyncService(ApplyMixin, LoopMixin):
    """See the module docstring. Build it, then :meth:`run` (a service) or :meth:`run_once`."""

    def __init__(self, config_path: Path, *, state_dir: Path,
                 hosts_path: Path = DEFAULT_HOSTS_PATH, bashrc_path: Path | None = None,
                 run_checks: bool = True, interval_s: float | None = None,
                 store: RecordStore | None = None,
                 local_source: Callable[[Settings], LocalAddress] = observe_local,
                 public_source: Callable[[Settings], PublicLookup] | None = None,
                 save_learned: bool = True, netlink: bool = True,
                 watch_folder: bool = True, unmap_on_stop: bool = False) -> None:
        self.config_path = Path(config_path)
        self.state_dir = Path(state_dir)
        self.hosts_path = Path(hosts_path)
        self.bashrc_path = Path(bashrc_path) if bashrc_path is not None else None
        self.do_checks = run_checks
        self.interval_override = interval_s
        self.local_source = local_source
        self.public_source = public_source or (
            lambda s: lookup_public_ip(s, self.state_dir, max(1.0, float(s.checks.timeout_s))))
        self.save_learned = save_learned
        self.use_netlink = netlink
        self.use_folder_watch = watch_folder
        self.unmap_on_stop = unmap_on_stop       # remove our forwards on the modem when stopped
        self.forwards = Renewer(self.state_dir, log)  # our forwards' leases (router map)
        self.certs = CertRenewer(log)        # ROS 2 mTLS: the fleet certificate before expiry
        self._folder_watched = False             # the loop watches the store's folder now
        self._store_fixed = store is not None
        self.store: RecordStore | None = store
        self._store_key: Any = None

        self.settings: Settings | None = None
        self._settings_key: Any = None
        self.local: LocalAddress | None = None
        self.public_ip = ""
        self.own: Record | None = None           # our current record (published or found)
        self.peers: dict[str, Candidate] = {}    # the last good record of each peer
        self._fetched_once = False
        self._own_missing = False
        self._published_at = 0.0
        self.dirty = True

        now = time.monotonic()
        self.next_public = now
        self._last_public_poll = -FORCED_GAP_S
        self.next_fetch = now
        self.next_publish = now
        self.next_apply = now
        self.next_verify = now
        self.recheck_at: float | None = None
        self._recheck_left: list[float] = []
        self._checks: _Worker | None = None         # the checks' thread while run() runs
        self._lookups: _Worker | None = None        # the public-IP lookup's thread, likewise
        self._public_busy = False                   # a lookup is under way on that thread
        self._public_answered = False               # a lookup has answered (or failed) once
        self._last_plan: Plan | None = None
        self.backoff = {k: Backoff() for k in ("settings", "public_ip", "store", "apply",
                                               "round")}
        self._said: set[Any] = set()             # messages logged once
        self._stop = False
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_w, False)
        os.set_blocking(self._wake_r, False)
        self._status_dirty = True
        self._alive_saved = 0.0

        prev = load_status(self.state_dir)
        self.status = empty_status()
        if prev:
            self.status["last_change"] = prev.get("last_change")
            self.status["last_error"] = prev.get("last_error")
            self.status["refused"] = prev.get("refused") or []
            rec = (prev.get("own") or {}).get("record")
            with contextlib.suppress(RecordError, TypeError):
                if rec:
                    self.own = parse_record(rec)
                    self.status["own"]["record"] = self.own.to_json()
        try:
            self._load_settings(initial=True)
        except BaseException:
            self.close()
            raise
        # The record of each peer applied before (this run or an earlier one): a copy that does
        # not follow it (a lower seq) is refused, and it stands until a successor comes.
        self._applied = load_applied(self.state_dir)
        for p in self.settings.peers if self.settings else []:
            prev = self._applied.get(p.name.lower())
            if prev is not None:
                self.peers[p.name] = Candidate(prev, "the record applied before (state dir)")

    # ================================================================== settings and store
    @property
    def interval_s(self) -> float:
        if self.interval_override is not None:
            return float(self.interval_override)
        return float(self.settings.sync.interval_s) if self.settings else 60.0

    def _load_settings(self, initial: bool = False) -> None:
        try:
            st = os.stat(self.config_path)
            key = (st.st_mtime_ns, st.st_size, st.st_ino)
        except OSError as exc:
            if initial:
                raise SyncError(f"no settings file at {self.config_path} ({exc.strerror})") \
                    from None
            self._error("settings", f"cannot read {self.config_path}: {exc.strerror}; "
                                    "keeping the settings read before")
            return
        if key == self._settings_key:
            return
        try:
            s = load_settings(self.config_path)
            if s is None:
                raise SettingsError("the file is gone", path=self.config_path)
            problems = [(k, why) for k, why in s.problems()
                        if k.startswith(("this.", "peer[", "ros.", "sync."))]
            if not s.this.name:
                problems.insert(0, ("this.name", "this component needs a name"))
            if problems:
                raise SettingsError("; ".join(f"{k}: {why}" for k, why in problems),
                                    path=self.config_path)
        except SettingsError as exc:
            if initial:
                raise SyncError(f"the settings cannot be used for sync: {exc}") from None
            self._error("settings", f"{exc}; keeping the settings read before")
            self._settings_key = key
            return
        if self.settings is not None:
            log.info("settings changed (%s): reading them again", self.config_path)
        self._settings_key = key
        self.settings = s
        self._clear_error("settings")
        self.dirty = True
        if not self._store_fixed:
            store_key = (s.sync.store, s.sync.folder, s.sync.dns_server, s.sync.zone,
                         s.sync.tsig_key_file, s.checks.timeout_s)
            if store_key != self._store_key:
                try:
                    self.store = make_store(s)
                except StoreConfigError as exc:
                    if initial:
                        raise SyncError(str(exc)) from None
                    self._error("store", f"{exc}; keeping {self.store.describe() if self.store else 'no store'}")
                    return
                self._store_key = store_key
                self._fetched_once = False
        self.status.update(name=s.this.name, role=s.this.role,
                           store=self.store.describe() if self.store else "",
                           store_kind=getattr(self.store, "kind", ""), interval_s=self.interval_s)
        self._status_dirty = True

    # ================================================================== errors and messages
    def _remember(self, key: Any) -> bool:
        """True the first time *key* is seen (bounded memory for a service that runs for ever)."""
        if key in self._said:
            return False
        if len(self._said) > 2000:
            self._said.clear()
        self._said.add(key)
        return True

    def _once(self, key: Any, level: int, msg: str, *args: Any) -> None:
        if not self._remember(key):
            return
        log.log(level, msg, *args)

    def _error(self, part: str, message: str, retry_in: float | None = None) -> None:
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
        self._status_dirty = True

    def _clear_error(self, part: str, recovered_msg: str | None = None) -> None:
        if self.status["errors"].pop(part, None) is not None:
            log.info("%s: %s", part, recovered_msg or "works again")
            self._status_dirty = True

    def _fail(self, part: str, message: str, mono: float) -> float:
        self.backoff[part].cap_s = backoff_cap(self.interval_s)
        delay = self.backoff[part].fail()
        self._error(part, message, delay)
        return mono + delay

    # ================================================================== one round
    def round(self, *, force_public: bool = False) -> RoundResult:
        """One pass of observe, read, publish, apply; never raises for network trouble."""
        mono = time.monotonic()
        applied = False
        self._load_settings()
        if self.settings is None:
            return RoundResult(False, False, {k: v["message"] for k, v in self.status["errors"].items()})
        self._observe_local(mono)
        if force_public:
            # at once, but not more often than every FORCED_GAP_S (a flapping link)
            self.next_public = min(self.next_public, self._last_public_poll + FORCED_GAP_S)
        if time.monotonic() >= self.next_public and not self._public_busy:
            self._last_public_poll = time.monotonic()
            self._poll_public(self._last_public_poll)
        if time.monotonic() >= self.next_fetch:
            self._fetch(time.monotonic())
        # the first answer of the lookup comes first (not a stale address published, applied)
        first_lookup = self._public_busy and not self._public_answered
        if self._fetched_once and time.monotonic() >= self.next_publish and not first_lookup:
            self._publish(time.monotonic())
        mono = time.monotonic()
        if (self.dirty or mono >= self.next_verify) and mono >= self.next_apply \
                and not first_lookup:
            applied = self._apply(mono)
        if self.recheck_at is not None and time.monotonic() >= self.recheck_at:
            self._recheck()
        self.forwards.tick(self.settings, background=self._lookups is not None)
        self.certs.tick(self.settings, background=self._lookups is not None)
        self._save_status()
        errors = {k: v["message"] for k, v in self.status["errors"].items()}
        return RoundResult(not errors, applied, errors)

    # ------------------------------------------------------------------ our addresses
    def _observe_local(self, mono: float) -> None:
        assert self.settings is not None
        try:
            local = self.local_source(self.settings)
        except Exception as exc:  # noqa: BLE001 - a broken interface query is a result
            self._error("local_ip", f"cannot read this machine's addresses: {exc}")
            return
        self._clear_error("local_ip")
        if local != self.local:
            if self.local is not None:
                log.info("local address changed: %s -> %s", self.local.describe(), local.describe())
                # a new route may mean a new public IP: ask now (within the forced gap)
                self.next_public = min(self.next_public, self._last_public_poll + FORCED_GAP_S)
            else:
                log.info("local address: %s", local.describe())
            if (self.local is not None and local.local_ip and self.local.local_ip
                    and local.local_ip != self.local.local_ip):
                log.warning("this component's local IP changed (%s -> %s): a modem that forwards "
                            "ports to the old address must be changed too (reserve the address in "
                            "the modem's DHCP settings)", self.local.local_ip, local.local_ip)
            self.local = local
            self.dirty = True
            self._status_dirty = True
        own = self.status["own"]
        own.update(local_ip=local.local_ip, interface=local.interface, gateway=local.gateway)

    def _poll_public(self, mono: float) -> None:
        """Ask for the public IP: on the lookup's thread while the service runs (the answer
        comes back to :meth:`_take_public`), here and now otherwise."""
        assert self.settings is not None
        self.next_public = math.inf     # a wish for an earlier poll meanwhile lowers it
        if self._lookups is not None:
            self._public_busy = True
            self._lookups.submit(mono, copy.deepcopy(self.settings))
            return
        self._take_public(mono, self._lookup_public(self.settings))

    def _lookup_public(self, settings: Settings) -> PublicLookup:
        try:
            return self.public_source(settings)
        except Exception as exc:  # noqa: BLE001
            return PublicLookup(None, f"the lookup failed: {type(exc).__name__}: {exc}")

    def _take_public(self, mono: float, lk: PublicLookup | None) -> None:
        """The answer of the lookup started at *mono*."""
        self._public_busy = False
        self._public_answered = True
        wished = self.next_public       # inf, or an earlier poll asked for meanwhile
        self._public_answer(mono, lk or PublicLookup(None, "the lookup failed (see the log)"))
        self.next_public = min(self.next_public, wished)

    def _public_answer(self, mono: float, lk: PublicLookup) -> None:
        self.status["own"]["public_checked_at"] = time.time()
        if not lk.ip:
            keep = self._known_public() or "none known"
            self.next_public = self._fail(
                "public_ip", f"no public IP: {lk.summary}; keeping the last known ({keep})", mono)
            return
        self.backoff["public_ip"].succeed()
        self._clear_error("public_ip", f"public IP lookup works again ({lk.ip})")
        self.next_public = mono + self.interval_s
        if lk.ip != self.public_ip:
            if self.public_ip:
                log.info("public IP changed: %s -> %s", self.public_ip, lk.ip)
            else:
                log.info("public IP: %s", lk.ip)
            self.public_ip = lk.ip
            self.dirty = True
        self.status["own"]["public_ip"] = lk.ip
        self._status_dirty = True

    def _known_public(self) -> str:
        if self.public_ip:
            return self.public_ip
        if self.own and self.own.public_ip:
            return self.own.public_ip
        return self.settings.this.public_ip if self.settings else ""

    # ------------------------------------------------------------------ the store
    def _fetch(self, mono: float) -> None:
        assert self.settings is not None and self.store is not None
        names = [p.name for p in self.settings.peers]
        try:
            res = self.store.fetch(names, self.settings.this.name)
        except StoreError as exc:
            self.next_fetch = self._fail("store", f"cannot read the records: {exc}; keeping the "
                                                  "last good configuration", mono)
            return
        self.backoff["store"].succeed()
        self._clear_error("store", f"the store answers again ({self.store.describe()})")
        self.next_fetch = mono + self._read_period()
        now = time.time()
        for r in res.refused:
            if not self._remember(("refused", r.source, r.why)):
                continue
            log.warning("refused the record %s (%s): %s; it is not applied", r.source,
                        r.name or "?", r.why)
            self.status["refused"] = (self.status["refused"] + [
                {"at": now, "source": r.source, "name": r.name, "why": r.why}])[-MAX_REFUSED:]
            self._status_dirty = True
        for note in res.notes:
            self._once(("note", note), logging.WARNING, "conflicting copies: %s", note)
        for name, cand in res.records.items():
            self._take_peer(name, cand, now)
        for name in names:
            if name not in res.records and name in self.peers:
                self._once(("gone", name, self.peers[name].record.seq), logging.WARNING,
                           "the store has no valid record of %s any more; keeping the last one "
                           "(%s)", name, self.peers[name].record.describe())
        self._take_own(res.own_copies)
        self._fetched_once = True

    def _read_period(self) -> float:
        """A watched folder wakes the loop when a record changes: read it every interval_s
        besides (a safety net). The DNS store is polled every interval_s (each read is a query to
        a name server, often a provider's, from every member). A folder that cannot be watched
        is read every read_period() (a local read costs nothing)."""
        if self._folder_watched or getattr(self.store, "kind", "") == "dns":
            return max(read_period(self.interval_s), self.interval_s)
        return read_period(self.interval_s)

    def _take_peer(self, name: str, cand: Candidate, now: float) -> None:
        old = self.peers.get(name)
        rec = cand.record
        peer_status = self.status["peers"].setdefault(name, {})
        peer_status["seen_at"] = now
        if old is not None and rec == old.record:
            return
        prev = self._applied.get(name.lower()) or (old.record if old is not None else None)
        why = successor_problem(prev, rec)
        if why is not None:
            assert prev is not None
            self._once(("older", name, rec.rank, prev.rank), logging.WARNING,
                       "refused the record %s (%s): %s; keeping #%d of %s (if %s really "
                       "started counting again, remove its entry from %s)", cand.source, name,
                       why, prev.seq, format_time(prev.timestamp), name,
                       applied_path(self.state_dir))
            return
        self._applied[name.lower()] = rec
        try:
            save_applied(self.state_dir, self._applied)
        except OSError as exc:
            self._once(("applied", str(exc)), logging.WARNING,
                       "cannot keep the applied records in the state dir: %s", exc)
        if old is None:
            log.info("record of %s: %s (from %s)", name, rec.describe(), cand.source)
        elif old.record.same_content(rec):
            log.debug("record of %s refreshed: #%d", name, rec.seq)
        else:
            log.info("record of %s changed: %s (from %s; was local %s, public %s)", name,
                     rec.describe(), cand.source, old.record.local_ip or "?",
                     old.record.public_ip or "?")
        if old is None or not old.record.same_content(rec):
            peer_status["changed_at"] = now
            self.dirty = True
        self.peers[name] = cand
        peer_status.update(record=rec.to_json(), source=cand.source, record_time=rec.timestamp)
        self._status_dirty = True

    def _take_own(self, copies: list[Candidate]) -> None:
        if not copies:
            self._own_missing = self.own is not None
            return
        self._own_missing = False
        best = max(copies, key=lambda c: c.record.rank)
        if self.own is None or best.record.rank > self.own.rank:
            if self.own is not None and not best.record.same_content(self.own):
                self._once(("foreign-own", best.record.seq), logging.WARNING,
                           "%s holds a newer record of this component's name (#%d) than this "
                           "service wrote (#%d): does another component use the name %s?",
                           best.source, best.record.seq, self.own.seq, best.record.name)
            self.own = best.record
        elif self.own is not None and best.record.rank < self.own.rank:
            self._own_missing = True  # the store lost our last record: publish it again

    def _desired_own(self) -> tuple[str, str, str] | None:
        assert self.settings is not None
        local = (self.local.local_ip if self.local else "") or self.settings.this.local_ip
        public = self._known_public()
        if not local and not public:
            return None
        return local, public, self.settings.this.role

    def _publish(self, mono: float) -> None:
        assert self.settings is not None and self.store is not None
        want = self._desired_own()
        if want is None:
            self._once(("no-address",), logging.WARNING, "no address of this component is known "
                       "yet: nothing to publish")
            return
        local, public, role = want
        name = self.settings.this.name
        now = time.time()
        same = (self.own is not None and self.own.name == name
                and (self.own.local_ip, self.own.public_ip, self.own.role) == want)
        heartbeat = same and self.own is not None and now - self.own.timestamp > HEARTBEAT_S
        if same and not heartbeat and not self._own_missing:
            return
        try:
            if self.own is not None and self.own.name == name:
                rec = self.own.next(local_ip=local, public_ip=public, role=role, now=now)
            else:
                # No earlier record of ours anywhere: counting starts again, said by seq_epoch.
                rec = new_record(name, local_ip=local, public_ip=public, role=role,
                                 seq=(self.own.seq + 1) if self.own else 1, now=now,
                                 seq_epoch=self.own.seq_epoch if self.own else int(now))
            check_record(rec)
        except RecordError as exc:
            self._error("publish", f"this component's own record would be refused by peers: "
                                   f"{exc}; not published")
            self.next_publish = mono + self.interval_s
            return
        try:
            self.store.publish(rec)
        except StoreError as exc:
            self.next_publish = self._fail("store", f"cannot publish our record: {exc}", mono)
            return
        self._clear_error("publish")
        self.backoff["store"].succeed()
        self._clear_error("store", f"the store answers again ({self.store.describe()})")
        why = "heartbeat" if heartbeat else ("the store had lost it" if same else "new content")
        log.info("published %s (%s)", rec.describe(), why)
        self.own = rec
        self._own_missing = False
        self._published_at = now
        self.status["own"].update(record=rec.to_json(), published_at=now)
        self._status_dirty = True
        remove = getattr(self.store, "remove_stale_copies", None)
        if remove is not None:
            with contextlib.suppress(OSError, StoreError):
                gone = remove(name, rec)
                if gone:
                    log.info("removed this component's stale copies: %s", ", ".join(gone))

    # ------------------------------------------------------------------ applying
