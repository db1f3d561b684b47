"""The service's apply side: plan the hosts set and the ROS block from the records, write them
through the safe writer, remember what was learned, run and re-run the affected checks. The
service's :class:`Applier` owns what it planned and wrote, when to write and check again, and
whether something changed since (:meth:`Applier.mark_changed`); it is handed the addresses and
the records in an :class:`ApplyInput`."""

from __future__ import annotations

import contextlib
import copy
import logging
import os
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from rosnet_tui.core.config.settings_model import Settings, SettingsError
from rosnet_tui.core.exposure.firewall import follow_for_sync
from rosnet_tui.core.files import managed_file as mf
from rosnet_tui.core.files import managed_text as mt
from rosnet_tui.core.files import managed_write as mw
from rosnet_tui.core.files.bashrc import preview_bashrc
from rosnet_tui.core.files.hosts import (
    PROFILE_TITLES,
    WriterSettingsError,
    find_hosts_conflicts,
    parse_hosts,
)
from rosnet_tui.core.saved.settings import load_settings, save_settings
from rosnet_tui.core.saved.sync_records import Record

from .affected import run_affected_checks
from .backoff import Backoff
from .plan import Plan, PlanError, check_complete, plan_hosts
from .state import Report, SyncConfig
from .timing import RECHECK_AFTER_S, VERIFY_EVERY_S
from .worker import Worker

log = logging.getLogger("rosnet_tui.sync")


@dataclass(frozen=True)
class ApplyInput:
    """What the applier is handed for one apply: the settings, this component's addresses known
    now, and the last good record of each peer."""
    settings: Settings
    local_ip: str
    public_ip: str
    records: Mapping[str, Record]
    interval_s: float


class Applier:
    """See the module docstring. Times named ``next_*`` and ``recheck_at`` are monotonic.
    *settings_saved* is told the settings it wrote (learned addresses) and the file's key."""

    def __init__(self, report: Report, config: SyncConfig,
                 settings_saved: Callable[[Settings, Any], None]) -> None:
        self.report = report
        self.config = config
        self.settings_saved = settings_saved
        self.changed = True                    # something changed since the last apply
        now = time.monotonic()
        self.next_apply = now
        self.next_verify = now
        self.recheck_at: float | None = None
        self.recheck_left: list[float] = []
        self.last_plan: Plan | None = None
        self.checks: Worker | None = None      # the checks' thread while the loop runs
        self.backoff = Backoff()

    def mark_changed(self) -> None:
        """An address, a record or the settings changed: apply at the next chance."""
        self.changed = True

    def hold(self, until: float) -> None:
        """No apply before *until* (monotonic; after an unexpected error in a round)."""
        self.next_apply = until

    def due(self, mono: float) -> bool:
        return (self.changed or mono >= self.next_verify) and mono >= self.next_apply

    def wake_at(self) -> float:
        """When an apply is due (changed: as soon as allowed; else the next verification)."""
        return self.next_apply if self.changed else max(self.next_apply, self.next_verify)

    def _plan(self, given: ApplyInput) -> Plan:
        return plan_hosts(given.settings, local_ip=given.local_ip, public_ip=given.public_ip,
                          records=dict(given.records))

    def apply(self, mono: float, given: ApplyInput) -> bool:
        """Write the hosts set (and the ROS block) when they differ from the files; True if
        something was written."""
        self.next_verify = mono + VERIFY_EVERY_S
        plan = self._plan(given)
        self.last_plan = plan
        try:
            old = mw.read_bytes(self.config.paths.hosts_path, state_dir=self.config.paths.state_dir)
            text = mt.decode(old) if old is not None else None
            check_complete(plan, text)
            body = plan.body()
            notes = [f"line {c.lineno} '{c.old.strip()}' {c.why}" for c in
                     find_hosts_conflicts(text, plan.settings, plan.profile)]
            previews = [mf.preview_block(self.config.paths.hosts_path, body, position="top",
                                         label=f"hosts: {plan.profile} set", notes=notes,
                                         new_mode=0o644, current=old, use_current=True)]
        except (PlanError, WriterSettingsError, mt.ManagedFileError) as exc:
            self.next_apply = self.report.fail(
                "apply", self.backoff, f"{exc}; the hosts file is left as it is", mono,
                given.interval_s)
            return False
        for n in notes:
            self.report.once(("conflict", n), logging.WARNING, "%s: %s (rosnet-tui hosts apply "
                            "--comment-conflicts fixes it, with your consent)",
                            self.config.paths.hosts_path, n)
        if self.config.write_bashrc and not plan.settings.ros2:
            # (ROS 2: the member's router dials the master by name; the hosts line is all)
            try:
                previews.append(preview_bashrc(plan.settings, self.config.paths.bashrc_path,
                                               state_dir=self.config.paths.state_dir))
            except (WriterSettingsError, mt.ManagedFileError) as exc:
                self.report.once(("bashrc", str(exc)), logging.WARNING,
                                "%s is left as it is: %s", self.config.paths.bashrc_path, exc)
        self._update_peer_status(plan)
        follow_for_sync(plan.settings, [c.address for c in plan.choices], log)  # ROS 1 firewall
        changed = [p for p in previews if p.changed]
        if not changed:
            self.changed = False
            self.backoff.succeed()
            self.report.clear_error("apply")
            return False
        summary = self._summary(plan, text)
        diff = "".join(p.diff() for p in changed)
        log.info("applying: %s\n%s", summary, diff.rstrip("\n"))
        try:
            result = mf.apply_previews(previews, state_dir=self.config.paths.state_dir,
                                       label=f"sync: {summary}")
        except mt.StalePreviewError as exc:
            log.info("%s; trying again", exc)
            self.next_apply = mono + 0.2
            return False
        except mt.PermissionNeededError as exc:
            self.next_apply = self.report.fail(
                "apply", self.backoff,
                f"{exc} (run the sync service as root: rosnet-tui sync install-service)",
                mono, given.interval_s)
            return False
        except mt.ManagedFileError as exc:
            self.next_apply = self.report.fail(
                "apply", self.backoff, f"{exc}; the files are left as they were", mono,
                given.interval_s)
            return False
        self.changed = False
        self.backoff.succeed()
        self.report.clear_error("apply", "writing works again")
        backups = ", ".join(str(b) for b in result.backups) or "none (new file)"
        log.info("wrote %s (journal #%s, backup %s; 'rosnet-tui undo' puts it back)",
                 ", ".join(str(p.path) for p in changed), result.entry_id, backups)
        self.report.set(profile=plan.profile,
                        last_change={"at": time.time(), "summary": summary, "diff": diff,
                                     "journal": result.entry_id, "checks": []})
        self._save_learned(plan, given)
        self.report.save(self.config.paths.state_dir)
        if self.config.run_checks:
            self.recheck_left = list(RECHECK_AFTER_S)
            self.recheck_at = None
            self._run_checks(plan)
        return True

    def _summary(self, plan: Plan, old_text: str | None) -> str:
        try:
            body = mt.extract_block(old_text) or []
        except mt.DamagedBlockError:
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
        self.report.set(dirty=False, profile=plan.profile)
        for c in plan.choices:
            p = self.report.peer(c.name)
            if p.get("address") != c.address or p.get("where") != c.where:
                self.report.update_peer(c.name, address=c.address, where=c.where, why=c.why)

    def _save_learned(self, plan: Plan, given: ApplyInput) -> None:
        """Keep the observed addresses in the settings file too, so `check`, `hosts apply` and
        the wizard agree with the hosts file (comments and layout kept)."""
        if not self.config.save_learned:
            return
        try:
            fresh = load_settings(self.config.paths.config_path)
        except SettingsError as exc:
            self.report.once(("learned", str(exc)), logging.WARNING,
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
            if lp is None or p.name not in given.records:
                continue
            for key in ("local_ip", "public_ip"):
                new = getattr(lp, key)
                if new and getattr(p, key) != new:
                    changes.append(f"{p.name}.{key} {getattr(p, key) or '-'} -> {new}")
                    setattr(p, key, new)
        if not changes:
            return
        try:
            st = os.stat(self.config.paths.config_path)
            # root saving a user's settings hands the new file back on its descriptor (never a
            # chown by path: the user may have swapped the path for a link meanwhile)
            owner = (st.st_uid, st.st_gid) if os.geteuid() == 0 and st.st_uid != 0 else None
            save_settings(fresh, self.config.paths.config_path, owner)
            with contextlib.suppress(OSError):
                st2 = os.stat(self.config.paths.config_path)
                self.settings_saved(fresh, (st2.st_mtime_ns, st2.st_size, st2.st_ino))
        except (SettingsError, OSError) as exc:
            self.report.once(("learned", str(exc)), logging.WARNING,
                             "the settings file was not updated: %s", exc)
            return
        log.info("settings updated (%s): %s", self.config.paths.config_path, "; ".join(changes))

    # ------------------------------------------------------------------ checks
    def _run_checks(self, plan: Plan) -> None:
        """The affected checks for *plan*: on the checks thread while the service runs (records
        are read and applied meanwhile), here and now otherwise (--once, tests)."""
        tag = (self.report.get("last_change") or {}).get("journal")
        if self.checks is not None:
            self.checks.submit(tag, copy.deepcopy(plan))
            return
        self.take_checks(tag, self.affected_checks(plan))

    def affected_checks(self, plan: Plan) -> list[dict[str, Any]]:
        return run_affected_checks(plan.settings, self.config.paths)

    def take_checks(self, tag: Any, results: list[dict[str, Any]] | None) -> None:
        """Keep the verdicts of the checks run for the change *tag* (its journal entry), unless
        a newer change came meanwhile (its own checks follow); then plan the re-checks."""
        change = self.report.get("last_change")
        if results is None:
            return
        if change is not None and change.get("journal") != tag:
            log.debug("the checks of an earlier change ended after a newer change: not kept")
            return
        bad = [r for r in results if r["status"] == "fail"]
        for r in results:
            level = logging.WARNING if r["status"] == "fail" else logging.INFO
            log.log(level, "check %-4s %s: %s", r["status"].upper(), r["id"], r["summary"])
        if change is not None:
            self.report.update_last_change(checks=results, checked_at=time.time())
        else:
            self.report.set()
        if not bad:
            self.recheck_left = []
        self._schedule_recheck()

    def _schedule_recheck(self) -> None:
        changes = self.report.get("last_change") or {}
        failing = any(c["status"] == "fail" for c in changes.get("checks") or [])
        if failing and self.recheck_left:
            self.recheck_at = time.monotonic() + self.recheck_left.pop(0)
        else:
            self.recheck_at = None

    def recheck_if_due(self) -> None:
        if self.recheck_at is None or time.monotonic() < self.recheck_at:
            return
        self.recheck_at = None
        if self.last_plan is None:
            return
        log.info("running the failing checks again")
        self._run_checks(self.last_plan)
