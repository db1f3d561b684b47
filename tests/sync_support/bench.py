"""Benchmark hook (issue 7, "Performance"): from the moment the master's public address changes
to the moment a member's hosts entry and checks are updated, per store, on the network lab.

    from tests.sync_support.bench import measure_change_latency, measure_in_new_lab
    result = measure_change_latency(lab, "folder", workdir)        # a built lab
    results = measure_in_new_lab(("folder", "dns"), repeats=3)      # builds and destroys a lab

The target: within the poll interval plus 2 s. The robot modem's WAN address is changed (a modem
restart) at t=0; `sync` runs on robot and laptop with the public IP polled every *interval_s*.
"""

from __future__ import annotations

import contextlib
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from .bind import bind_server
from .lab_sync import AFFECTED_PASS, SyncRig, checks_of, hosts_entry, prepare_lab, wait_for

STORES = ("folder", "dns")
NEW_IPS = ("203.0.113.77", "203.0.113.78")   # alternated, so every repeat is a real change


@dataclass
class ChangeLatency:
    store: str
    interval_s: float
    new_ip: str
    published_s: float | None     # the robot published its new record
    hosts_s: float | None         # the laptop's hosts file maps turtlebot to the new address
    checks_s: float | None        # ... and the affected checks have run after that write
    checks: dict[str, str] = field(default_factory=dict)   # their verdicts
    failures: dict[str, str] = field(default_factory=dict)  # summaries of those that failed
    budget_s: float = 0.0         # interval_s + 2 (the target)

    @property
    def within_budget(self) -> bool:
        return self.checks_s is not None and self.checks_s <= self.budget_s

    @property
    def checks_pass(self) -> bool:
        return all(self.checks.get(c) == "pass" for c in AFFECTED_PASS)

    def to_json(self) -> dict[str, Any]:
        d = asdict(self)
        d.update(within_budget=self.within_budget, checks_pass=self.checks_pass)
        return d


def _one_change(rig: SyncRig, new_ip: str, timeout_s: float) -> ChangeLatency:
    lab = rig.lab
    t_wall = time.time()
    t0 = time.monotonic()
    lab.set_robot_wan(new_ip)
    published = rig.published("robot", new_ip, timeout_s)
    t_pub = time.monotonic() - t0 if published else None
    left = max(0.1, timeout_s - (time.monotonic() - t0))
    ok = wait_for(lambda: hosts_entry(lab, "laptop", "turtlebot") == new_ip, left, step=0.01)
    t_hosts = time.monotonic() - t0 if ok else None
    left = max(0.1, timeout_s - (time.monotonic() - t0))
    st = rig.followed(new_ip, left, since=t_wall)
    t_checks = None
    if st is not None:
        # checked_at is wall-clock time: the moment the checks' verdicts were recorded
        t_checks = st["last_change"]["checked_at"] - t_wall
    failures = {c["id"]: c["summary"] for c in ((st or {}).get("last_change") or {}).get(
        "checks") or [] if c["status"] == "fail"}
    return ChangeLatency(rig.store, rig.interval_s, new_ip, t_pub, t_hosts, t_checks,
                         checks_of(st), failures, rig.interval_s + 2.0)


def measure_change_latency(lab, store: str, workdir: Path, *, interval_s: float = 2.0,
                           repeats: int = 1, timeout_s: float = 60.0) -> list[ChangeLatency]:
    """Run `sync` on robot and laptop with *store* ("folder" or "dns"), change the robot's
    public address *repeats* times and measure each change (seconds from the change).

    Leaves the lab healthy (default addresses and files) and stops what it started.
    """
    if store not in STORES:
        raise ValueError(f"store must be one of {STORES}")
    workdir = Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    prepare_lab(lab)
    results: list[ChangeLatency] = []
    with contextlib.ExitStack() as stack:
        bind = None
        folder = None
        if store == "dns":
            bind = stack.enter_context(bind_server(lab, workdir / "bind"))
        else:
            folder = workdir / "shared"
            folder.mkdir(exist_ok=True)
        rig = SyncRig(lab, workdir, store, folder=folder, bind=bind, interval_s=interval_s)
        stack.callback(lab.reset)
        stack.callback(rig.stop)
        rig.start()
        current = lab.public_ip("robot")
        if not rig.published("robot", current, timeout_s) or not wait_for(
                lambda: hosts_entry(lab, "laptop", "turtlebot") == current, timeout_s):
            raise RuntimeError(f"sync did not settle on the {store} store:\n"
                               f"robot:\n{rig.log('robot')[-3000:]}\n"
                               f"laptop:\n{rig.log('laptop')[-3000:]}")
        rig.wait_status("laptop", lambda st: st["last_change"].get("checked_at"), timeout_s)
        for i in range(repeats):
            results.append(_one_change(rig, NEW_IPS[i % len(NEW_IPS)], timeout_s))
    return results


def measure_in_new_lab(stores: tuple[str, ...] = STORES, *, interval_s: float = 2.0,
                       repeats: int = 1, timeout_s: float = 60.0) -> list[ChangeLatency]:
    """Build a lab, measure each store, destroy the lab (needs root; see tests/lab)."""
    from tests.lab import Lab

    out: list[ChangeLatency] = []
    with Lab() as lab, tempfile.TemporaryDirectory(prefix="rosnet-sync-bench-") as tmp:
        try:
            for store in stores:
                out += measure_change_latency(lab, store, Path(tmp) / store,
                                              interval_s=interval_s, repeats=repeats,
                                              timeout_s=timeout_s)
        finally:
            lab.stop_roscore()
    return out


if __name__ == "__main__":  # python -m tests.sync_support.bench
    import json

    for r in measure_in_new_lab(repeats=3):
        print(json.dumps(r.to_json()))
