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

import logging
import os
import time
from collections.abc import Callable
from typing import Any

from rosnet_tui.core.config.paths import Paths
from rosnet_tui.core.config.settings_model import Settings, SettingsError
from rosnet_tui.core.ros.pairing import CertRenewer
from rosnet_tui.core.saved.settings import load_settings
from rosnet_tui.core.upnp.forwards import Renewer

from .applier import Applier, ApplyInput
from .loop import Loop
from .outcome import RoundResult, SyncError
from .publisher import Publisher
from .signing import key_path
from .state import Report, SyncConfig
from .status import load_status
from .store import RecordStore
from .timing import read_period
from .watcher import AddressWatch, LocalAddress, PublicLookup, lookup_public_ip, observe_local

log = logging.getLogger("rosnet_tui.sync")


class SyncService:
    """See the module docstring. Build it, then :meth:`run` (a service) or :meth:`run_once`.

    Its parts each own their state: the service the settings; :attr:`watch` this component's
    addresses (:class:`~.watcher.AddressWatch`); :attr:`publisher` the store and the records
    (:class:`~.publisher.Publisher`); :attr:`applier` what was written and checked
    (:class:`~.applier.Applier`); :attr:`loop` the wake-ups (:class:`~.loop.Loop`);
    :attr:`report` the status document and the messages (:class:`~.state.Report`). A round hands
    each what it needs from the others."""

    def __init__(self, paths: Paths, *, write_bashrc: bool = False, run_checks: bool = True,
                 interval_s: float | None = None, store: RecordStore | None = None,
                 local_source: Callable[[Settings], LocalAddress] = observe_local,
                 public_source: Callable[[Settings], PublicLookup] | None = None,
                 save_learned: bool = True, netlink: bool = True,
                 watch_folder: bool = True, unmap_on_stop: bool = False) -> None:
        self.config = SyncConfig(
            paths=paths, write_bashrc=write_bashrc, run_checks=run_checks,
            interval_override=interval_s, save_learned=save_learned, netlink=netlink,
            watch_folder=watch_folder, unmap_on_stop=unmap_on_stop)
        self.settings: Settings | None = None
        self.settings_key: Any = None
        self.report = Report()
        self.watch = AddressWatch(self.report, local_source, public_source or (
            lambda s: lookup_public_ip(s, self.config.paths.state_dir,
                                       max(1.0, float(s.checks.timeout_s)))))
        self.publisher = Publisher(self.report, paths.state_dir, store,
                                   key_path(paths.config_path))
        self.forwards = Renewer(self.config.paths.state_dir, log)  # our forwards' leases (router map)
        self.certs = CertRenewer(log)        # ROS 2 mTLS: the fleet certificate before expiry
        self.applier = Applier(self.report, self.config, self._settings_saved)
        self.loop = Loop(self.config, self.report, self)

        prev = load_status(self.config.paths.state_dir)
        record = None
        if prev:
            self.report.set(last_change=prev.get("last_change"),
                            last_error=prev.get("last_error"), refused=prev.get("refused") or [])
            record = (prev.get("own") or {}).get("record")
        try:
            self._load_settings(initial=True)
        except BaseException:
            self.close()
            raise
        self.publisher.restore(record, self.settings)

    # ================================================================== settings
    @property
    def interval_s(self) -> float:
        if self.config.interval_override is not None:
            return float(self.config.interval_override)
        return float(self.settings.sync.interval_s) if self.settings else 60.0

    def _settings_saved(self, settings: Settings, key: Any) -> None:
        """The applier wrote the learned addresses into the settings file: they are the
        settings now (not read again as a change)."""
        self.settings_key = key
        self.settings = settings

    def _load_settings(self, initial: bool = False) -> None:
        path = self.config.paths.config_path
        try:
            st = os.stat(path)
            key = (st.st_mtime_ns, st.st_size, st.st_ino)
        except OSError as exc:
            if initial:
                raise SyncError(f"no settings file at {path} ({exc.strerror})") from None
            self.report.error("settings", f"cannot read {path}: {exc.strerror}; "
                                          "keeping the settings read before")
            return
        if key == self.settings_key:
            return
        try:
            s = load_settings(path)
            if s is None:
                raise SettingsError("the file is gone", path=path)
            problems = [(k, why) for k, why in s.problems()
                        if k.startswith(("this.", "peer[", "ros.", "sync."))]
            if not s.this.name:
                problems.insert(0, ("this.name", "this component needs a name"))
            if problems:
                raise SettingsError("; ".join(f"{k}: {why}" for k, why in problems), path=path)
        except SettingsError as exc:
            if initial:
                raise SyncError(f"the settings cannot be used for sync: {exc}") from None
            self.report.error("settings", f"{exc}; keeping the settings read before")
            self.settings_key = key
            return
        if self.settings is not None:
            log.info("settings changed (%s): reading them again", path)
        self.settings_key = key
        self.settings = s
        self.report.clear_error("settings")
        self.applier.mark_changed()
        if not self.publisher.follow_settings(s, initial):
            return
        self.report.set(name=s.this.name, role=s.this.role,
                        store=self.publisher.describe_store(),
                        store_kind=self.publisher.store_kind, interval_s=self.interval_s)

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

    # ================================================================== what the loop asks
    def describe(self) -> str:
        """The service in a line, for the log at start."""
        assert self.settings is not None
        s = self.settings
        bashrc = f", ROS block in {self.config.paths.bashrc_path}" if self.config.write_bashrc \
            else ""
        return (f"sync for {s.this.name} ({s.this.role}): {self.publisher.describe_store() or '?'}"
                f"; public IP every {self.interval_s:g} s, peers read every "
                f"{read_period(self.interval_s):g} s; hosts file {self.config.paths.hosts_path}"
                f"{bashrc}")

    def next_wake(self) -> float:
        """The monotonic time something is due."""
        cands = [self.publisher.next_fetch]
        public = self.watch.wake_at()
        if public is not None:
            cands.append(public)
        if not self.watch.first_answer_pending:     # else: after the first answer
            cands.append(self.applier.wake_at())
        if self.applier.recheck_at is not None:
            cands.append(self.applier.recheck_at)
        return min(cands)

    def hold(self, until: float) -> None:
        """No read and no apply before *until* (after an unexpected error in a round)."""
        self.publisher.hold(until)
        self.applier.hold(until)

    def take_public(self, mono: float, lk: PublicLookup | None) -> None:
        """The answer of the public-IP lookup started at *mono* (on the lookup's thread)."""
        if self.watch.take_public(mono, lk, self.known_public(), self.interval_s):
            self.applier.mark_changed()

    def known_public(self) -> str:
        """This component's public IP: looked up, else in our record, else in the settings."""
        return (self.watch.public_ip or self.publisher.own_public()
                or (self.settings.this.public_ip if self.settings else ""))

    # ================================================================== one round
    def round(self, *, force_public: bool = False) -> RoundResult:
        """One pass of observe, read, publish, apply; never raises for network trouble."""
        self._load_settings()
        s = self.settings
        if s is None:
            return RoundResult(False, False, self.report.errors())
        applied = False
        changed = self.watch.observe_local(s)
        if force_public:
            self.watch.ask_soon()
        changed = self.watch.poll_if_due(s, self.known_public(), self.interval_s) or changed
        changed = self.publisher.fetch_if_due(s, self.interval_s) or changed
        if changed:
            self.applier.mark_changed()
        # the first answer of the lookup comes first (not a stale address published, applied)
        if not self.watch.first_answer_pending:
            local = self.watch.local
            self.publisher.publish_if_due(
                s, (local.local_ip if local else "") or s.this.local_ip, self.known_public(),
                self.interval_s)
            mono = time.monotonic()
            if self.applier.due(mono):
                applied = self.applier.apply(mono, ApplyInput(
                    s, local.local_ip if local else "", self.known_public(),
                    self.publisher.records(), self.interval_s))
        self.applier.recheck_if_due()
        background = self.watch.lookups is not None
        self.forwards.tick(self.settings, background=background)
        self.certs.tick(self.settings, background=background)
        self.report.save(self.config.paths.state_dir)
        errors = self.report.errors()
        return RoundResult(not errors, applied, errors)
