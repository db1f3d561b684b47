"""The service's apply side: plan the hosts set and the ROS block from the records, write them
through the safe writer, remember what was learned, run and re-run the affected checks, save
the status. The service's :class:`Applier`; the state it works on is the service's
:class:`~rosnet_tui.core.sync.state.SyncState`."""

from __future__ import annotations

import contextlib
import copy
import logging
import os
import time
from typing import Any

from rosnet_tui.core import managed_file as mf
from rosnet_tui.core import managed_text as mt
from rosnet_tui.core import managed_write as mw
from rosnet_tui.core.bashrc import preview_bashrc
from rosnet_tui.core.firewall import follow_for_sync
from rosnet_tui.core.hosts import (
    PROFILE_TITLES,
    WriterSettingsError,
    find_hosts_conflicts,
    parse_hosts,
)
from rosnet_tui.core.settings import load_settings, save_settings
from rosnet_tui.core.settings_model import SettingsError

from .affected import run_affected_checks
from .plan import Plan, PlanError, check_complete, plan_hosts
from .state import SyncConfig, SyncState
from .status import (
    ALIVE_EVERY_S,
    save_status,
)
from .timing import RECHECK_AFTER_S, VERIFY_EVERY_S

log = logging.getLogger("rosnet_tui.sync")


class Applier:
    """Plan, write, check; reads and changes the service's :class:`SyncState`."""

    def __init__(self, state: SyncState, config: SyncConfig) -> None:
        self.state = state
        self.config = config

    def _plan(self) -> Plan:
        assert self.state.settings is not None
        st = self.state
        return plan_hosts(st.settings, local_ip=st.local.local_ip if st.local else "",
                          public_ip=st.known_public(),
                          records={n: c.record for n, c in st.peers.items()})

    def apply(self, mono: float) -> bool:
        """Write the hosts set (and the ROS block) when they differ from the files; True if
        something was written."""
        self.state.next_verify = mono + VERIFY_EVERY_S
        plan = self._plan()
        self.state.last_plan = plan
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
            self.state.next_apply = self.state.fail(
                "apply", f"{exc}; the hosts file is left as it is", mono)
            return False
        for n in notes:
            self.state.once(("conflict", n), logging.WARNING, "%s: %s (rosnet-tui hosts apply "
                            "--comment-conflicts fixes it, with your consent)",
                            self.config.paths.hosts_path, n)
        if self.config.write_bashrc and not plan.settings.ros2:
            # (ROS 2: the member's router dials the master by name; the hosts line is all)
            try:
                previews.append(preview_bashrc(plan.settings, self.config.paths.bashrc_path,
                                               state_dir=self.config.paths.state_dir))
            except (WriterSettingsError, mt.ManagedFileError) as exc:
                self.state.once(("bashrc", str(exc)), logging.WARNING,
                                "%s is left as it is: %s", self.config.paths.bashrc_path, exc)
        self._update_peer_status(plan)
        follow_for_sync(plan.settings, [c.address for c in plan.choices], log)  # ROS 1 firewall
        changed = [p for p in previews if p.changed]
        if not changed:
            self.state.dirty = False
            self.state.backoff["apply"].succeed()
            self.state.clear_error("apply")
            return False
        summary = self._summary(plan, text)
        diff = "".join(p.diff() for p in changed)
        log.info("applying: %s\n%s", summary, diff.rstrip("\n"))
        try:
            result = mf.apply_previews(previews, state_dir=self.config.paths.state_dir,
                                       label=f"sync: {summary}")
        except mt.StalePreviewError as exc:
            log.info("%s; trying again", exc)
            self.state.next_apply = mono + 0.2
            return False
        except mt.PermissionNeededError as exc:
            self.state.next_apply = self.state.fail(
                "apply", f"{exc} (run the sync service as root: rosnet-tui sync install-service)",
                mono)
            return False
        except mt.ManagedFileError as exc:
            self.state.next_apply = self.state.fail(
                "apply", f"{exc}; the files are left as they were", mono)
            return False
        self.state.dirty = False
        self.state.backoff["apply"].succeed()
        self.state.clear_error("apply", "writing works again")
        backups = ", ".join(str(b) for b in result.backups) or "none (new file)"
        log.info("wrote %s (journal #%s, backup %s; 'rosnet-tui undo' puts it back)",
                 ", ".join(str(p.path) for p in changed), result.entry_id, backups)
        self.state.status["profile"] = plan.profile
        self.state.status["last_change"] = {"at": time.time(), "summary": summary, "diff": diff,
                                      "journal": result.entry_id, "checks": []}
        self.state.status_dirty = True
        self._save_learned(plan)
        self.save_status()
        if self.config.run_checks:
            self.state.recheck_left = list(RECHECK_AFTER_S)
            self.state.recheck_at = None
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
        self.state.status["profile"] = plan.profile
        for c in plan.choices:
            p = self.state.status["peers"].setdefault(c.name, {})
            if p.get("address") != c.address or p.get("where") != c.where:
                p.update(address=c.address, where=c.where, why=c.why)
                self.state.status_dirty = True

    def _save_learned(self, plan: Plan) -> None:
        """Keep the observed addresses in the settings file too, so `check`, `hosts apply` and
        the wizard agree with the hosts file (comments and layout kept)."""
        if not self.config.save_learned:
            return
        try:
            fresh = load_settings(self.config.paths.config_path)
        except SettingsError as exc:
            self.state.once(("learned", str(exc)), logging.WARNING,
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
            if lp is None or p.name not in self.state.peers:
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
            save_settings(fresh, self.config.paths.config_path)
            if os.geteuid() == 0 and (st.st_uid, st.st_gid) != (0, 0):
                with contextlib.suppress(OSError):
                    os.chown(self.config.paths.config_path, st.st_uid, st.st_gid)
            with contextlib.suppress(OSError):
                st2 = os.stat(self.config.paths.config_path)
                self.state.settings_key = (st2.st_mtime_ns, st2.st_size, st2.st_ino)
                self.state.settings = fresh
        except (SettingsError, OSError) as exc:
            self.state.once(("learned", str(exc)), logging.WARNING,
                            "the settings file was not updated: %s", exc)
            return
        log.info("settings updated (%s): %s", self.config.paths.config_path, "; ".join(changes))

    # ------------------------------------------------------------------ checks
    def _run_checks(self, plan: Plan) -> None:
        """The affected checks for *plan*: on the checks thread while the service runs (records
        are read and applied meanwhile), here and now otherwise (--once, tests)."""
        tag = (self.state.status.get("last_change") or {}).get("journal")
        if self.state.checks is not None:
            self.state.checks.submit(tag, copy.deepcopy(plan))
            return
        self.take_checks(tag, self.affected_checks(plan))

    def affected_checks(self, plan: Plan) -> list[dict[str, Any]]:
        return run_affected_checks(plan.settings, self.config.paths)

    def take_checks(self, tag: Any, results: list[dict[str, Any]] | None) -> None:
        """Keep the verdicts of the checks run for the change *tag* (its journal entry), unless
        a newer change came meanwhile (its own checks follow); then plan the re-checks."""
        change = self.state.status.get("last_change")
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
            change["checks"] = results
            change["checked_at"] = time.time()
        if not bad:
            self.state.recheck_left = []
        self.state.status_dirty = True
        self._schedule_recheck()

    def _schedule_recheck(self) -> None:
        changes = self.state.status.get("last_change") or {}
        failing = any(c["status"] == "fail" for c in changes.get("checks") or [])
        if failing and self.state.recheck_left:
            self.state.recheck_at = time.monotonic() + self.state.recheck_left.pop(0)
        else:
            self.state.recheck_at = None

    def recheck(self) -> None:
        self.state.recheck_at = None
        if self.state.last_plan is None:
            return
        log.info("running the failing checks again")
        self._run_checks(self.state.last_plan)

    # ------------------------------------------------------------------ status
    def save_status(self, force: bool = False) -> None:
        now = time.time()
        if not (force or self.state.status_dirty or now - self.state.alive_saved > ALIVE_EVERY_S):
            return
        self.state.status["alive_at"] = now
        try:
            save_status(self.config.paths.state_dir, self.state.status)
        except OSError as exc:
            self.state.once(("status", str(exc)), logging.WARNING,
                            "cannot save the status: %s", exc)
            return
        self.state.status_dirty = False
        self.state.alive_saved = now
