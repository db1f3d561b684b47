"""The sync service: publish this component's record, follow the peers' records, keep the hosts
set and ROS_MASTER_URI right, re-run the affected checks.

One round (:meth:`SyncService.round`): reload the settings if they changed, look at the local
address (every round; netlink wakes the loop at once on a change), poll the public IP when due,
read the store, publish our record when its content changed, and when anything changed apply the
new hosts set (and the ROS block) through the safe writer, then run the affected checks.

Failures never undo a good configuration: an unreachable store, no internet or a refused write
keeps the last good state, backs off (bounded) and is logged once, with the recovery logged too.
"""

from __future__ import annotations

import contextlib
import copy
import fcntl
import logging
import os
import selectors
import signal
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rosnet_tui.core import managed_file as mf
from rosnet_tui.core.bashrc import master_uri, preview_bashrc
from rosnet_tui.core.hosts import (
    DEFAULT_HOSTS_PATH,
    PROFILE_TITLES,
    WriterSettingsError,
    find_hosts_conflicts,
)
from rosnet_tui.core.settings import Settings, SettingsError, load_settings, save_settings

from .backoff import Backoff, backoff_cap
from .plan import Plan, PlanError, check_complete, plan_hosts
from .records import (
    Candidate,
    Record,
    RecordError,
    check_record,
    format_time,
    new_record,
    parse_record,
)
from .status import (
    ALIVE_EVERY_S,
    MAX_REFUSED,
    empty_status,
    load_status,
    save_status,
    state_owner,
    sync_dir,
)
from .store import RecordStore, StoreConfigError, StoreError, make_store
from .watcher import LocalAddress, NetlinkMonitor, PublicLookup, lookup_public_ip, observe_local

AFFECTED_CHECKS = ("linux.hosts", "linux.resolve", "linux.ssh", "ros.master")
VERIFY_EVERY_S = 30.0        # look at the hosts file again even when nothing changed
HEARTBEAT_S = 3600.0         # republish an unchanged record this often (its age then says alive)
RECHECK_AFTER_S = (5.0, 15.0, 45.0)   # re-run failing checks after a change, then give up
DEBOUNCE_S = 0.3             # netlink: wait for the burst of messages of one change to end
FORCED_GAP_S = 2.0           # a network change asks for the public IP at most this often
MAX_WAIT_S = 5.0

log = logging.getLogger("rosnet_tui.sync")


class SyncError(Exception):
    """The service cannot start (settings, store configuration, another instance)."""


def read_period(interval_s: float) -> float:
    """How often peers' records are read: a quarter of the poll interval, 0.25 .. 1 s."""
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


class SyncService:
    """See the module docstring. Build it, then :meth:`run` (a service) or :meth:`run_once`."""

    def __init__(self, config_path: Path, *, state_dir: Path,
                 hosts_path: Path = DEFAULT_HOSTS_PATH, bashrc_path: Path | None = None,
                 run_checks: bool = True, interval_s: float | None = None,
                 store: RecordStore | None = None,
                 local_source: Callable[[Settings], LocalAddress] = observe_local,
                 public_source: Callable[[Settings], PublicLookup] | None = None,
                 save_learned: bool = True, netlink: bool = True,
                 unmap_on_stop: bool = False) -> None:
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
        self.unmap_on_stop = unmap_on_stop      # remove our forwards on the modem when stopped
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
        self.next_renew = now                   # our forwards' leases on the modem
        self.recheck_at: float | None = None
        self._recheck_left: list[float] = []
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
        if time.monotonic() >= self.next_public:
            self._last_public_poll = time.monotonic()
            self._poll_public(self._last_public_poll)
        if time.monotonic() >= self.next_fetch:
            self._fetch(time.monotonic())
        if self._fetched_once and time.monotonic() >= self.next_publish:
            self._publish(time.monotonic())
        mono = time.monotonic()
        if (self.dirty or mono >= self.next_verify) and mono >= self.next_apply:
            applied = self._apply(mono)
        if self.recheck_at is not None and time.monotonic() >= self.recheck_at:
            self._recheck()
        if time.monotonic() >= self.next_renew:
            self._renew_forwards()
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
        assert self.settings is not None
        try:
            lk = self.public_source(self.settings)
        except Exception as exc:  # noqa: BLE001
            lk = PublicLookup(None, f"the lookup failed: {type(exc).__name__}: {exc}")
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
        self.next_fetch = mono + read_period(self.interval_s)
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

    def _take_peer(self, name: str, cand: Candidate, now: float) -> None:
        old = self.peers.get(name)
        rec = cand.record
        peer_status = self.status["peers"].setdefault(name, {})
        peer_status["seen_at"] = now
        if old is not None and rec == old.record:
            return
        if old is not None and rec.rank < old.record.rank and rec.rank[1] <= old.record.rank[1]:
            self._once(("older", name, rec.seq), logging.WARNING,
                       "%s: the store holds an older record (#%d, %s) than the one already seen "
                       "(#%d); keeping the newer", cand.source, rec.seq,
                       format_time(rec.timestamp), old.record.seq)
            return
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
                rec = new_record(name, local_ip=local, public_ip=public, role=role,
                                 seq=(self.own.seq + 1) if self.own else 1, now=now)
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
    def _plan(self) -> Plan:
        assert self.settings is not None
        return plan_hosts(self.settings, local_ip=self.local.local_ip if self.local else "",
                          public_ip=self._known_public(),
                          records={n: c.record for n, c in self.peers.items()})

    def _apply(self, mono: float) -> bool:
        """Write the hosts set (and the ROS block) when they differ from the files; True if
        something was written."""
        self.next_verify = mono + VERIFY_EVERY_S
        plan = self._plan()
        self._last_plan = plan
        try:
            old = mf.read_bytes(self.hosts_path)
            text = mf.decode(old) if old is not None else None
            check_complete(plan, text)
            body = plan.body()
            notes = [f"line {c.lineno} '{c.old.strip()}' {c.why}" for c in
                     find_hosts_conflicts(text, plan.settings, plan.profile)]
            previews = [mf.preview_block(self.hosts_path, body, position="top",
                                         label=f"hosts: {plan.profile} set", notes=notes,
                                         new_mode=0o644, current=old, use_current=True)]
        except (PlanError, WriterSettingsError, mf.ManagedFileError) as exc:
            self.next_apply = self._fail("apply", f"{exc}; the hosts file is left as it is", mono)
            return False
        for n in notes:
            self._once(("conflict", n), logging.WARNING, "%s: %s (rosnet-tui hosts apply "
                       "--comment-conflicts fixes it, with your consent)", self.hosts_path, n)
        if self.bashrc_path is not None and not plan.settings.ros2:
            # (ROS 2: the member's router dials the master by name; the hosts line is all)
            try:
                previews.append(preview_bashrc(plan.settings, self.bashrc_path))
            except (WriterSettingsError, mf.ManagedFileError) as exc:
                self._once(("bashrc", str(exc)), logging.WARNING,
                           "%s is left as it is: %s", self.bashrc_path, exc)
        self._update_peer_status(plan)
        changed = [p for p in previews if p.changed]
        if not changed:
            self.dirty = False
            self.backoff["apply"].succeed()
            self._clear_error("apply")
            return False
        summary = self._summary(plan, text)
        diff = "".join(p.diff() for p in changed)
        log.info("applying: %s\n%s", summary, diff.rstrip("\n"))
        try:
            result = mf.apply_previews(previews, state_dir=self.state_dir, label=f"sync: {summary}")
        except mf.StalePreviewError as exc:
            log.info("%s; trying again", exc)
            self.next_apply = mono + 0.2
            return False
        except mf.PermissionNeededError as exc:
            self.next_apply = self._fail("apply", f"{exc} (run the sync service as root: "
                                                  "rosnet-tui sync install-service)", mono)
            return False
        except mf.ManagedFileError as exc:
            self.next_apply = self._fail("apply", f"{exc}; the files are left as they were", mono)
            return False
        self.dirty = False
        self.backoff["apply"].succeed()
        self._clear_error("apply", "writing works again")
        backups = ", ".join(str(b) for b in result.backups) or "none (new file)"
        log.info("wrote %s (journal #%s, backup %s; 'rosnet-tui undo' puts it back)",
                 ", ".join(str(p.path) for p in changed), result.entry_id, backups)
        self.status["profile"] = plan.profile
        self.status["last_change"] = {"at": time.time(), "summary": summary, "diff": diff,
                                      "journal": result.entry_id, "checks": []}
        self._status_dirty = True
        self._save_learned(plan)
        self._save_status()
        if self.do_checks:
            self._run_checks(plan)
            self._recheck_left = list(RECHECK_AFTER_S)
            self._schedule_recheck()
        return True

    def _summary(self, plan: Plan, old_text: str | None) -> str:
        from rosnet_tui.core.checks.linux import parse_hosts

        try:
            body = mf.extract_block(old_text) or []
        except mf.DamagedBlockError:
            body = []
        before: dict[str, str] = {}
        for _, ip, names in parse_hosts("\n".join(body)):
            for n in names:
                before.setdefault(n.lower(), ip)
        parts = []
        for e in plan.entries:
            was = before.get(e.name.lower())
            if was is None:
                parts.append(f"{e.name} -> {e.ip} (new)")
            elif was != e.ip:
                parts.append(f"{e.name} {was} -> {e.ip}")
        if not parts:
            parts.append("the block rewritten (same addresses)")
        return f"{'; '.join(parts)} [{PROFILE_TITLES[plan.profile].split(' (')[0]} set]"

    def _update_peer_status(self, plan: Plan) -> None:
        self.status["profile"] = plan.profile
        for c in plan.choices:
            p = self.status["peers"].setdefault(c.name, {})
            if p.get("address") != c.address or p.get("where") != c.where:
                p.update(address=c.address, where=c.where, why=c.why)
                self._status_dirty = True

    def _save_learned(self, plan: Plan) -> None:
        """Keep the observed addresses in the settings file too, so `check`, `hosts apply` and
        the wizard agree with the hosts file (comments and layout kept)."""
        if not self.save_learned:
            return
        try:
            fresh = load_settings(self.config_path)
        except SettingsError as exc:
            self._once(("learned", str(exc)), logging.WARNING,
                       "the settings file was not updated: %s", exc)
            return
        if fresh is None:
            return
        learned = plan.learned
        changes = []
        for key in ("local_ip", "public_ip", "profile"):
            new = getattr(learned.this, key)
            if new and getattr(fresh.this, key) != new:
                changes.append(f"this.{key} {getattr(fresh.this, key) or '-'} -> {new}")
                setattr(fresh.this, key, new)
        for p in fresh.peers:
            lp = next((x for x in learned.peers if x.name == p.name), None)
            if lp is None or p.name not in self.peers:
                continue
            for key in ("local_ip", "public_ip"):
                new = getattr(lp, key)
                if new and getattr(p, key) != new:
                    changes.append(f"{p.name}.{key} {getattr(p, key) or '-'} -> {new}")
                    setattr(p, key, new)
        if not changes:
            return
        try:
            st = os.stat(self.config_path)
            save_settings(fresh, self.config_path)
            if os.geteuid() == 0 and (st.st_uid, st.st_gid) != (0, 0):
                with contextlib.suppress(OSError):
                    os.chown(self.config_path, st.st_uid, st.st_gid)
            with contextlib.suppress(OSError):
                st2 = os.stat(self.config_path)
                self._settings_key = (st2.st_mtime_ns, st2.st_size, st2.st_ino)
                self.settings = fresh
        except (SettingsError, OSError) as exc:
            self._once(("learned", str(exc)), logging.WARNING,
                       "the settings file was not updated: %s", exc)
            return
        log.info("settings updated (%s): %s", self.config_path, "; ".join(changes))

    # ------------------------------------------------------------------ checks
    def _run_checks(self, plan: Plan) -> None:
        results = run_affected_checks(plan.settings, hosts_path=self.hosts_path,
                                      bashrc_path=self.bashrc_path, state_dir=self.state_dir)
        bad = [r for r in results if r["status"] == "fail"]
        for r in results:
            level = logging.WARNING if r["status"] == "fail" else logging.INFO
            log.log(level, "check %-4s %s: %s", r["status"].upper(), r["id"], r["summary"])
        if self.status.get("last_change") is not None:
            self.status["last_change"]["checks"] = results
            self.status["last_change"]["checked_at"] = time.time()
        if not bad:
            self._recheck_left = []
        self._status_dirty = True

    def _schedule_recheck(self) -> None:
        changes = self.status.get("last_change") or {}
        failing = any(c["status"] == "fail" for c in changes.get("checks") or [])
        if failing and self._recheck_left:
            self.recheck_at = time.monotonic() + self._recheck_left.pop(0)
        else:
            self.recheck_at = None

    def _recheck(self) -> None:
        self.recheck_at = None
        if self._last_plan is None:
            return
        log.info("running the failing checks again")
        self._run_checks(self._last_plan)
        self._schedule_recheck()

    # ------------------------------------------------------------------ status
    def _save_status(self, force: bool = False) -> None:
        now = time.time()
        if not (force or self._status_dirty or now - self._alive_saved > ALIVE_EVERY_S):
            return
        self.status["alive_at"] = now
        try:
            save_status(self.state_dir, self.status)
        except OSError as exc:
            self._once(("status", str(exc)), logging.WARNING, "cannot save the status: %s", exc)
            return
        self._status_dirty = False
        self._alive_saved = now

    # ================================================================== forwards on the modem
    def _renew_forwards(self) -> None:
        """Renew the leases of the forwards `rosnet-tui router map` made (bounded, quiet when
        there are none: the journal says so without asking the modem)."""
        from rosnet_tui.core.upnp.forwards import renew_due

        try:
            said, next_in = renew_due(self.settings, state_dir=self.state_dir)
        except Exception as exc:  # noqa: BLE001 - the modem's trouble must not stop the sync
            said, next_in = [f"renewing the forwards failed: {exc}"], 300.0
        for line in said:
            log.info("modem: %s", line)
        self.next_renew = time.monotonic() + (next_in if next_in is not None else 600.0)

    def _unmap_forwards(self) -> None:
        from rosnet_tui.core.upnp.forwards import unmap_ours

        try:
            for line in unmap_ours(state_dir=self.state_dir, timeout=5.0):
                log.info("modem: %s", line)
        except Exception as exc:  # noqa: BLE001
            log.warning("modem: the forwards were not removed: %s", exc)

    # ================================================================== running
    def stop(self) -> None:
        """Ask the loop to stop (safe from a signal handler or another thread)."""
        self._stop = True
        with contextlib.suppress(OSError):
            os.write(self._wake_w, b"x")

    def _next_wake(self) -> float:
        apply_due = self.next_apply if self.dirty else max(self.next_apply, self.next_verify)
        cands = [self.next_public, self.next_fetch, apply_due]
        if self.recheck_at is not None:
            cands.append(self.recheck_at)
        return min(cands)

    def _start(self, lock: _ServiceLock) -> None:
        lock.acquire()
        assert self.settings is not None
        self.status.update(pid=os.getpid(), started_at=time.time(), stopped_at=None)
        s = self.settings
        log.info("sync for %s (%s): %s; public IP every %g s, peers read every %g s; hosts file "
                 "%s%s", s.this.name, s.this.role, self.store.describe() if self.store else "?",
                 self.interval_s, read_period(self.interval_s), self.hosts_path,
                 f", ROS block in {self.bashrc_path}" if self.bashrc_path else "")

    def _finish(self, lock: _ServiceLock) -> None:
        self.status["stopped_at"] = time.time()
        self._save_status(force=True)
        lock.release()

    def run_once(self) -> RoundResult:
        """One full round (the public IP asked now), for cron and tests."""
        lock = _ServiceLock(self.state_dir)
        self._start(lock)
        try:
            return self.round(force_public=True)
        finally:
            self._finish(lock)
            self.close()

    def run(self) -> int:
        """Run until :meth:`stop` (SIGTERM/SIGINT through :func:`install_signal_handlers`)."""
        lock = _ServiceLock(self.state_dir)
        self._start(lock)
        monitor = NetlinkMonitor.open() if self.use_netlink else None
        if self.use_netlink and monitor is None:
            log.info("no netlink here: local address changes are seen within %g s",
                     read_period(self.interval_s))
        sel = selectors.DefaultSelector()
        sel.register(self._wake_r, selectors.EVENT_READ, "wake")
        if monitor is not None:
            sel.register(monitor.fileno(), selectors.EVENT_READ, "netlink")
        force_public = True
        try:
            while not self._stop:
                try:
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
                timeout = min(MAX_WAIT_S, max(0.02, self._next_wake() - time.monotonic()))
                for key, _ in sel.select(timeout):
                    if key.data == "wake":
                        with contextlib.suppress(OSError):
                            os.read(self._wake_r, 64)
                    elif monitor is not None and monitor.drain():
                        deadline = time.monotonic() + DEBOUNCE_S
                        while time.monotonic() < deadline and not self._stop:
                            if sel.select(max(0.0, deadline - time.monotonic())):
                                monitor.drain()
                        log.info("the kernel reports a link, address or route change")
                        force_public = True
        finally:
            sel.close()
            if monitor is not None:
                monitor.close()
            if self.unmap_on_stop:
                self._unmap_forwards()
            log.info("sync stopped")
            self._finish(lock)
            self.close()
        return 0

    def close(self) -> None:
        for fd in (self._wake_r, self._wake_w):
            with contextlib.suppress(OSError):
                os.close(fd)
        self._wake_r = self._wake_w = -1


def install_signal_handlers(service: SyncService) -> None:
    """SIGTERM and SIGINT (Ctrl-C) stop the service cleanly after the current step."""
    def handler(signum: int, frame: Any) -> None:
        log.info("stopping (%s)", signal.Signals(signum).name)
        service.stop()

    signal.signal(signal.SIGTERM, handler)
    signal.signal(signal.SIGINT, handler)


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
