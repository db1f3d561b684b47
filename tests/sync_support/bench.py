"""Benchmark hook (issue 7, "Performance"; issue 17): from the moment the master's public address
changes to the moment a member has followed it (its hosts entry, then its re-run checks), per
store, on the network lab, as a distribution over changes at random moments of the poll cycle.

    from tests.sync_support.bench import measure_change_latency, measure_in_new_lab, summarize
    runs = measure_change_latency(lab, "folder", workdir, changes=10)   # a built lab
    runs = measure_in_new_lab(("folder", "dns"), changes=10)            # builds and destroys one

The robot modem's WAN address is changed (a modem restart) at t=0, after a random pause of up to
one poll interval (so the change falls anywhere in the master's poll cycle); `sync` runs on robot
and laptop with the public IP polled every *interval_s*. Goals: the member's hosts entry within
interval_s + 1 s (folder store, watched) or interval_s + 2 s (DNS store, polled), every time.
"""

from __future__ import annotations

import contextlib
import random
import statistics
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from .bind import bind_server
from .lab_sync import AFFECTED_PASS, SyncRig, checks_of, hosts_entry, prepare_lab, wait_for

STORES = ("folder", "dns")
NEW_IPS = ("203.0.113.77", "203.0.113.78")   # alternated, so every change is a real change
CHANGES = 10                                 # changes measured per store (the issue: >= 10)
# DNS: the master's poll and the member's poll of the zone (both interval_s) add up.
GOAL_OVER_INTERVAL_S = {"folder": 1.0, "dns": 3.0}


def goal_s(store: str, interval_s: float) -> float:
    """The most a change may take to reach the member's hosts file, for *store*."""
    return interval_s + GOAL_OVER_INTERVAL_S[store]


@dataclass
class ChangeLatency:
    store: str
    interval_s: float
    new_ip: str
    phase_s: float | None         # seconds since the master's last public-IP poll, at the change
    published_s: float | None     # the robot published its new record
    hosts_s: float | None         # the laptop's hosts file maps turtlebot to the new address
    checks_s: float | None        # ... and the affected checks have run after that write
    checks: dict[str, str] = field(default_factory=dict)   # their verdicts
    failures: dict[str, str] = field(default_factory=dict)  # summaries of those that failed
    budget_s: float = 0.0         # goal_s(store, interval_s)
    watched: bool | None = None   # the laptop's service watched the shared folder (its status)

    @property
    def within_budget(self) -> bool:
        return self.hosts_s is not None and self.hosts_s <= self.budget_s

    @property
    def member_s(self) -> float | None:
        """From the robot publishing its record to the laptop's hosts entry: the member's part."""
        if self.hosts_s is None or self.published_s is None:
            return None
        return self.hosts_s - self.published_s

    @property
    def checks_pass(self) -> bool:
        return all(self.checks.get(c) == "pass" for c in AFFECTED_PASS)

    def to_json(self) -> dict[str, Any]:
        d = asdict(self)
        d.update(within_budget=self.within_budget, checks_pass=self.checks_pass,
                 member_s=self.member_s)
        return d


def summarize(runs: list[ChangeLatency]) -> dict[str, Any]:
    """Median and maximum (and minimum) of each measured span, over the changes followed."""
    out: dict[str, Any] = {"changes": len(runs),
                           "followed": sum(r.hosts_s is not None for r in runs),
                           "within_budget": sum(r.within_budget for r in runs)}
    for key in ("published_s", "hosts_s", "checks_s", "member_s"):
        xs = [getattr(r, key) for r in runs if getattr(r, key) is not None]
        out[key] = ({"median": statistics.median(xs), "max": max(xs), "min": min(xs)}
                    if xs else None)
    return out


def _one_change(rig: SyncRig, new_ip: str, timeout_s: float, rng: random.Random,
                wait_checks: bool) -> ChangeLatency:
    lab = rig.lab
    time.sleep(rng.uniform(0.0, rig.interval_s))            # anywhere in the poll cycle
    polled = ((rig.status("robot") or {}).get("own") or {}).get("public_checked_at")
    t_wall = time.time()
    t0 = time.monotonic()
    lab.set_robot_wan(new_ip)
    phase = None if not polled else (t_wall - polled) % rig.interval_s
    ok = wait_for(lambda: hosts_entry(lab, "laptop", "turtlebot") == new_ip, timeout_s,
                  step=0.01)
    t_hosts = time.monotonic() - t0 if ok else None
    st = rig.published("robot", new_ip, max(0.1, timeout_s - (time.monotonic() - t0)))
    published_at = ((st or {}).get("own") or {}).get("published_at")
    t_pub = published_at - t_wall if published_at else None
    t_checks, checks, failures = None, {}, {}
    if wait_checks and ok:
        st = rig.followed(new_ip, max(0.1, timeout_s - (time.monotonic() - t0)), since=t_wall)
        if st is not None:
            # checked_at is wall-clock time: the moment the checks' verdicts were recorded
            t_checks = st["last_change"]["checked_at"] - t_wall
        checks = checks_of(st)
        failures = {c["id"]: c["summary"] for c in ((st or {}).get("last_change") or {}).get(
            "checks") or [] if c["status"] == "fail"}
    watch = ((rig.status("laptop") or {}).get("folder_watch") or {}).get("watching")
    return ChangeLatency(rig.store, rig.interval_s, new_ip, phase, t_pub, t_hosts, t_checks,
                         checks, failures, goal_s(rig.store, rig.interval_s), watch)


def measure_change_latency(lab, store: str, workdir: Path, *, interval_s: float = 2.0,
                           changes: int = CHANGES, timeout_s: float = 60.0,
                           wait_checks: bool = True, seed: int | None = None,
                           ) -> list[ChangeLatency]:
    """Run `sync` on robot and laptop with *store* ("folder" or "dns"), change the robot's
    public address *changes* times, each at a random moment, and measure each change (seconds
    from the change). With *wait_checks* each change also waits for the laptop's re-run checks
    (their time is measured) before the next one; without, changes come faster than checks.

    Leaves the lab healthy (default addresses and files) and stops what it started.
    """
    if store not in STORES:
        raise ValueError(f"store must be one of {STORES}")
    rng = random.Random(seed)
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
        for i in range(changes):
            results.append(_one_change(rig, NEW_IPS[i % len(NEW_IPS)], timeout_s, rng,
                                       wait_checks))
    return results


def measure_in_new_lab(stores: tuple[str, ...] = STORES, *, interval_s: float = 2.0,
                       changes: int = CHANGES, timeout_s: float = 60.0) -> list[ChangeLatency]:
    """Build a lab, measure each store, destroy the lab (needs root; see tests/lab)."""
    from tests.lab import Lab

    out: list[ChangeLatency] = []
    with Lab() as lab, tempfile.TemporaryDirectory(prefix="rosnet-sync-bench-") as tmp:
        try:
            for store in stores:
                out += measure_change_latency(lab, store, Path(tmp) / store,
                                              interval_s=interval_s, changes=changes,
                                              timeout_s=timeout_s)
        finally:
            lab.stop_roscore()
    return out


if __name__ == "__main__":  # python -m tests.sync_support.bench
    import json

    runs = measure_in_new_lab()
    for r in runs:
        print(json.dumps(r.to_json()))
    for store in STORES:
        print(store, json.dumps(summarize([r for r in runs if r.store == store])))
