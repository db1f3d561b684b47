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

from rosnet_tui.core.config.paths import Paths
from rosnet_tui.core.config.settings_model import Settings, SettingsError
from rosnet_tui.core.ros.pairing import CertRenewer
from rosnet_tui.core.saved.settings import load_settings
from rosnet_tui.core.upnp.forwards import Renewer

from .applied import applied_path, load_applied, save_applied
from .applier import Applier
from .choose_store import make_store
from .loop import Loop
from .outcome import RoundResult, SyncError
from .records import (
    Candidate,
    RecordError,
    check_record,
    format_time,
    new_record,
    parse_record,
    successor_problem,
)
from .state import SyncConfig, SyncState
from .status import (
    MAX_REFUSED,
    empty_status,
    load_status,
)
from .store import RecordStore, StoreConfigError, StoreError
from .timing import FORCED_GAP_S, HEARTBEAT_S, read_period
from .watcher import LocalAddress, PublicLookup, lookup_public_ip, observe_local

log = logging.getLogger("rosnet_tui.sync")


class SyncService:
    """See the module docstring. Build it, then :meth:`run` (a service) or :meth:`run_once`."""

    def __init__(self, paths: Paths, *, write_bashrc: bool = False, run_checks: bool = True,
                 interval_s: float | None = None, store: RecordStore | None = None,
                 local_source: Callable[[Settings], LocalAddress] = observe_local,
                 public_source: Callable[[Settings], PublicLookup] | None = None,
                 save_learned: bool = True, netlink: bool = True,
                 watch_folder: bool = True, unmap_on_stop: bool = False) -> None:
        self.config = SyncConfig(
            paths=paths, write_bashrc=write_bashrc, run_checks=run_checks,
            interval_override=interval_s, save_learned=save_learned, netlink=netlink, watch_folder=watch_folder, unmap_on_stop=unmap_on_stop)
        self.state = SyncState(status=empty_status(), interval_override=interval_s, store=store,
                               store_fixed=store is not None)
        self.local_source = local_source
        self.public_source = public_source or (
            lambda s: lookup_public_ip(s, self.config.paths.state_dir,
                                       max(1.0, float(s.checks.timeout_s))))
        self.forwards = Renewer(self.config.paths.state_dir, log)  # our forwards' leases (router map)
        self.certs = CertRenewer(log)        # ROS 2 mTLS: the fleet certificate before expiry
        self.applier = Applier(self.state, self.config)
        self.loop = Loop(self.state, self.config, self.applier, self)

        prev = load_status(self.config.paths.state_dir)
        if prev:
            self.state.status["last_change"] = prev.get("last_change")
            self.state.status["last_error"] = prev.get("last_error")
            self.state.status["refused"] = prev.get("refused") or []
            rec = (prev.get("own") or {}).get("record")
            with contextlib.suppress(RecordError, TypeError):
                if rec:
                    self.state.own = parse_record(rec)
                    self.state.status["own"]["record"] = self.state.own.to_json()
        try:
            self._load_settings(initial=True)
        except BaseException:
            self.close()
            raise
        # The record of each peer applied before (this run or an earlier one): a copy that does
        # not follow it (a lower seq) is refused, and it stands until a successor comes.
        self.state.applied = load_applied(self.config.paths.state_dir)
        for p in self.state.settings.peers if self.state.settings else []:
            prev = self.state.applied.get(p.name.lower())
            if prev is not None:
                self.state.peers[p.name] = Candidate(prev, "the record applied before (state dir)")

    # ================================================================== settings and store
    def _load_settings(self, initial: bool = False) -> None:
        try:
            st = os.stat(self.config.paths.config_path)
            key = (st.st_mtime_ns, st.st_size, st.st_ino)
        except OSError as exc:
            if initial:
                raise SyncError(f"no settings file at {self.config.paths.config_path} ({exc.strerror})") \
                    from None
            self.state.error("settings", f"cannot read {self.config.paths.config_path}: {exc.strerror}; "
                                    "keeping the settings read before")
            return
        if key == self.state.settings_key:
            return
        try:
            s = load_settings(self.config.paths.config_path)
            if s is None:
                raise SettingsError("the file is gone", path=self.config.paths.config_path)
            problems = [(k, why) for k, why in s.problems()
                        if k.startswith(("this.", "peer[", "ros.", "sync."))]
            if not s.this.name:
                problems.insert(0, ("this.name", "this component needs a name"))
            if problems:
                raise SettingsError("; ".join(f"{k}: {why}" for k, why in problems),
                                    path=self.config.paths.config_path)
        except SettingsError as exc:
            if initial:
                raise SyncError(f"the settings cannot be used for sync: {exc}") from None
            self.state.error("settings", f"{exc}; keeping the settings read before")
            self.state.settings_key = key
            return
        if self.state.settings is not None:
            log.info("settings changed (%s): reading them again", self.config.paths.config_path)
        self.state.settings_key = key
        self.state.settings = s
        self.state.clear_error("settings")
        self.state.dirty = True
        if not self.state.store_fixed:
            store_key = (s.sync.store, s.sync.folder, s.sync.dns_server, s.sync.zone,
                         s.sync.tsig_key_file, s.checks.timeout_s)
            if store_key != self.state.store_key:
                try:
                    self.state.store = make_store(s)
                except StoreConfigError as exc:
                    if initial:
                        raise SyncError(str(exc)) from None
                    kept = self.state.store.describe() if self.state.store else "no store"
                    self.state.error("store", f"{exc}; keeping {kept}")
                    return
                self.state.store_key = store_key
                self.state.fetched_once = False
        self.state.status.update(name=s.this.name, role=s.this.role,
                           store=self.state.store.describe() if self.state.store else "",
                           store_kind=getattr(self.state.store, "kind", ""),
                           interval_s=self.state.interval_s)
        self.state.status_dirty = True

    # ================================================================== running
    def run(self) -> int:
        """Run until :meth:`stop` (SIGTERM/SIGINT through
        :func:`~rosnet_tui.core.sync.loop.install_signal_handlers`)."""
        return self.loop.run()

    def run_once(self) -> RoundResult:
        """One full round (the public IP asked now), for cron and tests."""
        return self.loop.run_once()

    def stop(self) -> None:
        """Ask the loop to stop (safe from a signal handler or another thread)."""
        self.loop.stop()

    def close(self) -> None:
        self.loop.close()

    # ================================================================== one round
    def round(self, *, force_public: bool = False) -> RoundResult:
        """One pass of observe, read, publish, apply; never raises for network trouble."""
        mono = time.monotonic()
        applied = False
        self._load_settings()
        if self.state.settings is None:
            return RoundResult(False, False, self.state.errors())
        self._observe_local(mono)
        if force_public:
            # at once, but not more often than every FORCED_GAP_S (a flapping link)
            self.state.next_public = min(self.state.next_public,
                                         self.state.last_public_poll + FORCED_GAP_S)
        if time.monotonic() >= self.state.next_public and not self.state.public_busy:
            self.state.last_public_poll = time.monotonic()
            self._poll_public(self.state.last_public_poll)
        if time.monotonic() >= self.state.next_fetch:
            self._fetch(time.monotonic())
        # the first answer of the lookup comes first (not a stale address published, applied)
        first_lookup = self.state.public_busy and not self.state.public_answered
        if self.state.fetched_once and time.monotonic() >= self.state.next_publish \
                and not first_lookup:
            self._publish(time.monotonic())
        mono = time.monotonic()
        if (self.state.dirty or mono >= self.state.next_verify) and mono >= self.state.next_apply \
                and not first_lookup:
            applied = self.applier.apply(mono)
        if self.state.recheck_at is not None and time.monotonic() >= self.state.recheck_at:
            self.applier.recheck()
        self.forwards.tick(self.state.settings, background=self.state.lookups is not None)
        self.certs.tick(self.state.settings, background=self.state.lookups is not None)
        self.applier.save_status()
        errors = self.state.errors()
        return RoundResult(not errors, applied, errors)

    # ------------------------------------------------------------------ our addresses
    def _observe_local(self, mono: float) -> None:
        assert self.state.settings is not None
        try:
            local = self.local_source(self.state.settings)
        except Exception as exc:  # noqa: BLE001 - a broken interface query is a result
            self.state.error("local_ip", f"cannot read this machine's addresses: {exc}")
            return
        self.state.clear_error("local_ip")
        if local != self.state.local:
            if self.state.local is not None:
                log.info("local address changed: %s -> %s", self.state.local.describe(),
                         local.describe())
                # a new route may mean a new public IP: ask now (within the forced gap)
                self.state.next_public = min(self.state.next_public,
                                             self.state.last_public_poll + FORCED_GAP_S)
            else:
                log.info("local address: %s", local.describe())
            if (self.state.local is not None and local.local_ip and self.state.local.local_ip
                    and local.local_ip != self.state.local.local_ip):
                log.warning("this component's local IP changed (%s -> %s): a modem that forwards "
                            "ports to the old address must be changed too (reserve the address in "
                            "the modem's DHCP settings)", self.state.local.local_ip, local.local_ip)
            self.state.local = local
            self.state.dirty = True
            self.state.status_dirty = True
        own = self.state.status["own"]
        own.update(local_ip=local.local_ip, interface=local.interface, gateway=local.gateway)

    def _poll_public(self, mono: float) -> None:
        """Ask for the public IP: on the lookup's thread while the service runs (the answer
        comes back to :meth:`_take_public`), here and now otherwise."""
        assert self.state.settings is not None
        self.state.next_public = math.inf     # a wish for an earlier poll meanwhile lowers it
        if self.state.lookups is not None:
            self.state.public_busy = True
            self.state.lookups.submit(mono, copy.deepcopy(self.state.settings))
            return
        self.take_public(mono, self.lookup_public(self.state.settings))

    def lookup_public(self, settings: Settings) -> PublicLookup:
        try:
            return self.public_source(settings)
        except Exception as exc:  # noqa: BLE001
            return PublicLookup(None, f"the lookup failed: {type(exc).__name__}: {exc}")

    def take_public(self, mono: float, lk: PublicLookup | None) -> None:
        """The answer of the lookup started at *mono*."""
        self.state.public_busy = False
        self.state.public_answered = True
        wished = self.state.next_public       # inf, or an earlier poll asked for meanwhile
        self._public_answer(mono, lk or PublicLookup(None, "the lookup failed (see the log)"))
        self.state.next_public = min(self.state.next_public, wished)

    def _public_answer(self, mono: float, lk: PublicLookup) -> None:
        self.state.status["own"]["public_checked_at"] = time.time()
        if not lk.ip:
            keep = self.state.known_public() or "none known"
            self.state.next_public = self.state.fail(
                "public_ip", f"no public IP: {lk.summary}; keeping the last known ({keep})", mono)
            return
        self.state.backoff["public_ip"].succeed()
        self.state.clear_error("public_ip", f"public IP lookup works again ({lk.ip})")
        self.state.next_public = mono + self.state.interval_s
        if lk.ip != self.state.public_ip:
            if self.state.public_ip:
                log.info("public IP changed: %s -> %s", self.state.public_ip, lk.ip)
            else:
                log.info("public IP: %s", lk.ip)
            self.state.public_ip = lk.ip
            self.state.dirty = True
        self.state.status["own"]["public_ip"] = lk.ip
        self.state.status_dirty = True

    # ------------------------------------------------------------------ the store
    def _fetch(self, mono: float) -> None:
        assert self.state.settings is not None and self.state.store is not None
        names = [p.name for p in self.state.settings.peers]
        try:
            res = self.state.store.fetch(names, self.state.settings.this.name)
        except StoreError as exc:
            self.state.next_fetch = self.state.fail("store", f"cannot read the records: {exc}; "
                                                    "keeping the "
                                                  "last good configuration", mono)
            return
        self.state.backoff["store"].succeed()
        self.state.clear_error("store", f"the store answers again ({self.state.store.describe()})")
        self.state.next_fetch = mono + self._read_period()
        now = time.time()
        for r in res.refused:
            if not self.state.remember(("refused", r.source, r.why)):
                continue
            log.warning("refused the record %s (%s): %s; it is not applied", r.source,
                        r.name or "?", r.why)
            self.state.status["refused"] = (self.state.status["refused"] + [
                {"at": now, "source": r.source, "name": r.name, "why": r.why}])[-MAX_REFUSED:]
            self.state.status_dirty = True
        for note in res.notes:
            self.state.once(("note", note), logging.WARNING, "conflicting copies: %s", note)
        for name, cand in res.records.items():
            self._take_peer(name, cand, now)
        for name in names:
            if name not in res.records and name in self.state.peers:
                self.state.once(("gone", name, self.state.peers[name].record.seq), logging.WARNING,
                           "the store has no valid record of %s any more; keeping the last one "
                                "(%s)", name, self.state.peers[name].record.describe())
        self._take_own(res.own_copies)
        self.state.fetched_once = True

    def _read_period(self) -> float:
        """A watched folder wakes the loop when a record changes: read it every interval_s
        besides (a safety net). The DNS store is polled every interval_s (each read is a query to
        a name server, often a provider's, from every member). A folder that cannot be watched
        is read every read_period() (a local read costs nothing)."""
        if self.state.folder_watched or getattr(self.state.store, "kind", "") == "dns":
            return max(read_period(self.state.interval_s), self.state.interval_s)
        return read_period(self.state.interval_s)

    def _take_peer(self, name: str, cand: Candidate, now: float) -> None:
        old = self.state.peers.get(name)
        rec = cand.record
        peer_status = self.state.status["peers"].setdefault(name, {})
        peer_status["seen_at"] = now
        if old is not None and rec == old.record:
            return
        prev = self.state.applied.get(name.lower()) or (old.record if old is not None else None)
        why = successor_problem(prev, rec)
        if why is not None:
            assert prev is not None
            self.state.once(("older", name, rec.rank, prev.rank), logging.WARNING,
                            "refused the record %s (%s): %s; keeping #%d of %s (if %s really "
                            "started counting again, remove its entry from %s)", cand.source, name,
                            why, prev.seq, format_time(prev.timestamp), name,
                            applied_path(self.config.paths.state_dir))
            return
        self.state.applied[name.lower()] = rec
        try:
            save_applied(self.config.paths.state_dir, self.state.applied)
        except OSError as exc:
            self.state.once(("applied", str(exc)), logging.WARNING,
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
            self.state.dirty = True
        self.state.peers[name] = cand
        peer_status.update(record=rec.to_json(), source=cand.source, record_time=rec.timestamp)
        self.state.status_dirty = True

    def _take_own(self, copies: list[Candidate]) -> None:
        if not copies:
            self.state.own_missing = self.state.own is not None
            return
        self.state.own_missing = False
        best = max(copies, key=lambda c: c.record.rank)
        if self.state.own is None or best.record.rank > self.state.own.rank:
            if self.state.own is not None and not best.record.same_content(self.state.own):
                self.state.once(("foreign-own", best.record.seq), logging.WARNING,
                                "%s holds a newer record of this component's name (#%d) than this "
                                "service wrote (#%d): does another component use the name %s?",
                                best.source, best.record.seq, self.state.own.seq, best.record.name)
            self.state.own = best.record
        elif self.state.own is not None and best.record.rank < self.state.own.rank:
            self.state.own_missing = True  # the store lost our last record: publish it again

    def _desired_own(self) -> tuple[str, str, str] | None:
        assert self.state.settings is not None
        local = ((self.state.local.local_ip if self.state.local else "")
                 or self.state.settings.this.local_ip)
        public = self.state.known_public()
        if not local and not public:
            return None
        return local, public, self.state.settings.this.role

    def _publish(self, mono: float) -> None:
        assert self.state.settings is not None and self.state.store is not None
        want = self._desired_own()
        if want is None:
            self.state.once(("no-address",), logging.WARNING,
                            "no address of this component is known "
                            "yet: nothing to publish")
            return
        local, public, role = want
        name = self.state.settings.this.name
        now = time.time()
        same = (self.state.own is not None and self.state.own.name == name
                and (self.state.own.local_ip, self.state.own.public_ip,
                     self.state.own.role) == want)
        heartbeat = (same and self.state.own is not None
                     and now - self.state.own.timestamp > HEARTBEAT_S)
        if same and not heartbeat and not self.state.own_missing:
            return
        try:
            if self.state.own is not None and self.state.own.name == name:
                rec = self.state.own.next(local_ip=local, public_ip=public, role=role, now=now)
            else:
                # No earlier record of ours anywhere: counting starts again, said by seq_epoch.
                rec = new_record(name, local_ip=local, public_ip=public, role=role,
                                 seq=(self.state.own.seq + 1) if self.state.own else 1, now=now,
                                 seq_epoch=self.state.own.seq_epoch if self.state.own else int(now))
            check_record(rec)
        except RecordError as exc:
            self.state.error("publish", f"this component's own record would be refused by peers: "
                                   f"{exc}; not published")
            self.state.next_publish = mono + self.state.interval_s
            return
        try:
            self.state.store.publish(rec)
        except StoreError as exc:
            self.state.next_publish = self.state.fail(
                "store", f"cannot publish our record: {exc}", mono)
            return
        self.state.clear_error("publish")
        self.state.backoff["store"].succeed()
        self.state.clear_error("store", f"the store answers again ({self.state.store.describe()})")
        why = "heartbeat" if heartbeat else ("the store had lost it" if same else "new content")
        log.info("published %s (%s)", rec.describe(), why)
        self.state.own = rec
        self.state.own_missing = False
        self.state.published_at = now
        self.state.status["own"].update(record=rec.to_json(), published_at=now)
        self.state.status_dirty = True
        remove = getattr(self.state.store, "remove_stale_copies", None)
        if remove is not None:
            with contextlib.suppress(OSError, StoreError):
                gone = remove(name, rec)
                if gone:
                    log.info("removed this component's stale copies: %s", ", ".join(gone))

    # ------------------------------------------------------------------ applying
