"""The service's store side: read the peers' records, publish ours. The service's
:class:`Publisher` owns the store, this component's record and the last good record of each
peer; it hands the applier :meth:`Publisher.records` and says when a peer's record changed."""

from __future__ import annotations

import contextlib
import logging
import selectors
import time
from pathlib import Path
from typing import Any

from rosnet_tui.core.config.settings_model import Settings
from rosnet_tui.core.printable import printable
from rosnet_tui.core.saved.sync_applied import applied_path, load_applied, save_applied
from rosnet_tui.core.saved.sync_records import (
    Candidate,
    Record,
    RecordError,
    check_record,
    format_time,
    new_record,
    parse_record,
    successor_problem,
)

from .backoff import Backoff
from .choose_store import make_store
from .folder_watch import StoreWatch
from .outcome import SyncError
from .signing import load_or_make_key, pinned_keys, sign_record, signature_problem
from .state import Report
from .status import MAX_REFUSED
from .store import RecordStore, StoreConfigError, StoreError
from .timing import HEARTBEAT_S, read_period

log = logging.getLogger("rosnet_tui.sync")


class Publisher:
    """See the module docstring. Times named ``next_*`` are monotonic."""

    def __init__(self, report: Report, state_dir: Path, store: RecordStore | None,
                 key_file: Path) -> None:
        self.report = report
        self.state_dir = state_dir
        self.key_file = key_file                 # this component's sync key (signing.py)
        self._key: Any = None
        self.store = store
        self.store_fixed = store is not None     # handed in: the settings do not choose it
        self.store_key: Any = None
        self.folder_watched = False              # the loop watches the store's folder now
        self.own: Record | None = None           # our current record (published or found)
        self.own_missing = False
        self.published_at = 0.0
        self.peers: dict[str, Candidate] = {}    # the last good record of each
        self.applied: dict[str, Record] = {}     # each peer's record applied
        self.fetched_once = False
        now = time.monotonic()
        self.next_fetch = now
        self.next_publish = now
        self.backoff = Backoff()

    # ------------------------------------------------------------------ start
    def restore(self, record: Any, s: Settings | None) -> None:
        """Our record saved in the status before (*record*, JSON), and the record of each peer
        applied before (this run or an earlier one): a copy that does not follow it (a lower
        seq) is refused, and it stands until a successor comes (when signed by the key pinned
        for that peer now)."""
        with contextlib.suppress(RecordError, TypeError):
            if record:
                self.own = parse_record(record)
                self.report.update_own(record=self.own.to_json())
        self.applied = load_applied(self.state_dir)
        keys = pinned_keys(s, None) if s is not None else {}
        for name in [p.name for p in s.peers] if s is not None else []:
            prev = self.applied.get(name.lower())
            if prev is not None and signature_problem(prev, keys.get(name.lower())) is None:
                self.peers[name] = Candidate(prev, "the record applied before (state dir)")

    def key(self) -> Any:
        """This component's sync key (made on first use). Raises SyncError."""
        if self._key is None:
            try:
                self._key = load_or_make_key(self.key_file)
            except (OSError, ValueError) as exc:
                raise SyncError(f"cannot use the sync key {self.key_file}: {exc}") from None
        return self._key

    def follow_settings(self, s: Settings, initial: bool) -> bool:
        """The store the settings name, made again when its settings changed (unless handed
        in); False when it cannot be made (the one before is kept). Raises SyncError instead
        when *initial*."""
        if self.store_fixed:
            return True
        store_key = (s.sync.store, s.sync.folder, s.sync.dns_server, s.sync.zone,
                     s.sync.tsig_key_file, s.checks.timeout_s)
        if store_key == self.store_key:
            return True
        try:
            self.store = make_store(s)
        except StoreConfigError as exc:
            if initial:
                raise SyncError(str(exc)) from None
            kept = self.store.describe() if self.store else "no store"
            self.report.error("store", f"{exc}; keeping {kept}")
            return False
        self.store_key = store_key
        self.fetched_once = False
        return True

    def describe_store(self) -> str:
        return self.store.describe() if self.store else ""

    @property
    def store_kind(self) -> str:
        return getattr(self.store, "kind", "")

    # ------------------------------------------------------------------ what the others read
    def records(self) -> dict[str, Record]:
        """The last good record of each peer, by name."""
        return {n: c.record for n, c in self.peers.items()}

    def own_public(self) -> str:
        return self.own.public_ip if self.own else ""

    def read_soon(self) -> None:
        """Read the store at the next round (a change may be unseen)."""
        self.next_fetch = min(self.next_fetch, time.monotonic())

    def hold(self, until: float) -> None:
        """No read before *until* (monotonic; after an unexpected error in a round)."""
        self.next_fetch = until

    # ------------------------------------------------------------------ reading
    def fetch_if_due(self, s: Settings, interval_s: float) -> bool:
        """Read the store when due; True when a peer's record changed in content."""
        mono = time.monotonic()
        if mono < self.next_fetch:
            return False
        assert self.store is not None
        names = [p.name for p in s.peers]
        try:
            keys = pinned_keys(s, self.key())
        except SyncError as exc:
            self.report.error("publish", str(exc))
            keys = pinned_keys(s, None)
        try:
            res = self.store.fetch(names, s.this.name, keys)
        except StoreError as exc:
            self.next_fetch = self.report.fail(
                "store", self.backoff, f"cannot read the records: {exc}; keeping the last good "
                "configuration", mono, interval_s)
            return False
        self.backoff.succeed()
        self.report.clear_error("store", f"the store answers again ({self.store.describe()})")
        self.next_fetch = mono + self._read_period(interval_s)
        now = time.time()
        for r in res.refused:
            if not self.report.remember(("refused", r.source, r.why)):
                continue
            log.warning("refused the record %s (%s): %s; it is not applied", r.source,
                        r.name or "?", r.why)
            self.report.add_refused({"at": now, "source": r.source, "name": r.name, "why": r.why},
                                    MAX_REFUSED)
        for note in res.notes:
            self.report.once(("note", note), logging.WARNING, "conflicting copies: %s",
                             printable(note))
        changed = False
        for name, cand in res.records.items():
            changed = self._take_peer(name, cand, now) or changed
        for name in names:
            if name not in res.records and name in self.peers:
                self.report.once(("gone", name, self.peers[name].record.seq), logging.WARNING,
                                 "the store has no valid record of %s any more; keeping the last "
                                 "one (%s)", name, self.peers[name].record.describe())
        self._take_own(res.own_copies)
        self.fetched_once = True
        return changed

    def _read_period(self, interval_s: float) -> float:
        """A watched folder wakes the loop when a record changes: read it every interval_s
        besides (a safety net). The DNS store is polled every interval_s (each read is a query to
        a name server, often a provider's, from every member). A folder that cannot be watched
        is read every read_period() (a local read costs nothing)."""
        if self.folder_watched or self.store_kind == "dns":
            return max(read_period(interval_s), interval_s)
        return read_period(interval_s)

    def _take_peer(self, name: str, cand: Candidate, now: float) -> bool:
        old = self.peers.get(name)
        rec = cand.record
        self.report.update_peer(name, dirty=False, seen_at=now)
        if old is not None and rec == old.record:
            return False
        prev = self.applied.get(name.lower()) or (old.record if old is not None else None)
        why = successor_problem(prev, rec)
        if why is not None:
            assert prev is not None
            if self.report.remember(("refused", cand.source, why)):
                self.report.add_refused({"at": now, "source": cand.source, "name": name,
                                         "why": why}, MAX_REFUSED)
            self.report.once(("older", name, rec.rank, prev.rank), logging.WARNING,
                             "refused the record %s (%s): %s; keeping #%d of %s (if %s really "
                             "started counting again, remove its entry from %s)", cand.source,
                             name, why, prev.seq, format_time(prev.timestamp), name,
                             applied_path(self.state_dir))
            return False
        self.applied[name.lower()] = rec
        try:
            save_applied(self.state_dir, self.applied)
        except OSError as exc:
            self.report.once(("applied", str(exc)), logging.WARNING,
                             "cannot keep the applied records in the state dir: %s", exc)
        if old is None:
            log.info("record of %s: %s (from %s)", name, rec.describe(), cand.source)
        elif old.record.same_content(rec):
            log.debug("record of %s refreshed: #%d", name, rec.seq)
        else:
            log.info("record of %s changed: %s (from %s; was local %s, public %s)", name,
                     rec.describe(), cand.source, old.record.local_ip or "?",
                     old.record.public_ip or "?")
        changed = old is None or not old.record.same_content(rec)
        if changed:
            self.report.update_peer(name, dirty=False, changed_at=now)
        self.peers[name] = cand
        self.report.update_peer(name, record=rec.to_json(), source=cand.source,
                                record_time=rec.timestamp)
        return changed

    def _take_own(self, copies: list[Candidate]) -> None:
        if not copies:
            self.own_missing = self.own is not None
            return
        self.own_missing = False
        best = max(copies, key=lambda c: c.record.rank)
        if self.own is None or best.record.rank > self.own.rank:
            if self.own is not None and not best.record.same_content(self.own):
                self.report.once(("foreign-own", best.record.seq), logging.WARNING,
                                 "%s holds a newer record of this component's name (#%d) than "
                                 "this service wrote (#%d): does another component use the name "
                                 "%s?", best.source, best.record.seq, self.own.seq,
                                 best.record.name)
            self.own = best.record
        elif self.own is not None and best.record.rank < self.own.rank:
            self.own_missing = True  # the store lost our last record: publish it again

    # ------------------------------------------------------------------ publishing
    def publish_if_due(self, s: Settings, local: str, public: str, interval_s: float) -> None:
        """Publish our record (*local*, *public*: the addresses known now) when due and its
        content changed, the heartbeat is due or the store lost it."""
        if not self.fetched_once or time.monotonic() < self.next_publish:
            return
        mono = time.monotonic()
        assert self.store is not None
        if not local and not public:
            self.report.once(("no-address",), logging.WARNING,
                             "no address of this component is known yet: nothing to publish")
            return
        want = (local, public, s.this.role)
        role = s.this.role
        name = s.this.name
        now = time.time()
        same = (self.own is not None and self.own.name == name
                and (self.own.local_ip, self.own.public_ip, self.own.role) == want)
        heartbeat = same and self.own is not None and now - self.own.timestamp > HEARTBEAT_S
        if same and not heartbeat and not self.own_missing:
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
            rec = sign_record(rec, self.key())
        except SyncError as exc:
            self.report.error("publish", f"{exc}; not published")
            self.next_publish = mono + interval_s
            return
        except RecordError as exc:
            self.report.error("publish", f"this component's own record would be refused by "
                                         f"peers: {exc}; not published")
            self.next_publish = mono + interval_s
            return
        try:
            self.store.publish(rec)
        except StoreError as exc:
            self.next_publish = self.report.fail(
                "store", self.backoff, f"cannot publish our record: {exc}", mono, interval_s)
            return
        self.report.clear_error("publish")
        self.backoff.succeed()
        self.report.clear_error("store", f"the store answers again ({self.store.describe()})")
        why = "heartbeat" if heartbeat else ("the store had lost it" if same else "new content")
        log.info("published %s (%s)", rec.describe(), why)
        self.own = rec
        self.own_missing = False
        self.published_at = now
        self.report.update_own(record=rec.to_json(), published_at=now)
        remove = getattr(self.store, "remove_stale_copies", None)
        if remove is not None:
            with contextlib.suppress(OSError, StoreError):
                gone = remove(name, rec)
                if gone:
                    log.info("removed this component's stale copies: %s", ", ".join(gone))

    # ------------------------------------------------------------------ the watched folder
    def follow_folder(self, watch: StoreWatch, sel: selectors.BaseSelector,
                      interval_s: float) -> None:
        """Keep the watch on the store's folder (a folder store): started, kept or ended."""
        if self.store is None:
            return
        started_or_ended = watch.follow(self.store, sel, read_period(interval_s))
        if started_or_ended or watch.active != self.folder_watched:
            self.read_soon()      # a change may be unseen
        self.folder_watched = watch.active
        if self.report.get("folder_watch") != watch.describe():
            self.report.set(folder_watch=watch.describe())
