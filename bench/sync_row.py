"""Row 6: from the master's public address changing to a member's hosts entry and checks updated,
per record store (folder; DNS with BIND in the lab), on the network lab.

The sync service's helper provides the measurement: ``measure_change_latency`` in
tests/sync_support/bench.py (`rosnet-tui sync` on robot and laptop, the robot's modem restarted
with a new public address at t=0). When that module is missing this row says "not available yet"
and the bench still succeeds.
"""

from __future__ import annotations

import importlib
import importlib.util
from pathlib import Path
from typing import Any

from bench.model import Line, Options, RowResult, median

TITLE = "Address sync: master address change to member updated"
MODULE = "tests.sync_support.bench"
INTERVAL_S = 2.0            # the public-IP poll interval the services run with (the tests' value)


def available() -> tuple[bool, str]:
    """Whether the sync service's measuring function is there, and if not, why."""
    try:
        spec = importlib.util.find_spec(MODULE)
    except ImportError:
        spec = None
    if spec is None:
        return False, ("the sync service has no measuring function yet "
                       "(tests/sync_support/bench.py is missing)")
    try:
        mod = importlib.import_module(MODULE)
    except Exception as exc:  # e.g. a dependency of the sync tests is missing
        return False, f"{MODULE} cannot be imported: {type(exc).__name__}: {exc}"
    if not callable(getattr(mod, "measure_change_latency", None)):
        return False, f"{MODULE} has no measure_change_latency() yet"
    return True, ""


def _store_ready(store: str) -> tuple[bool, str]:
    if store != "dns":
        return True, ""
    try:
        from tests.sync_support.bind import bind_available
    except Exception as exc:
        return False, f"the DNS store needs tests/sync_support/bind.py: {exc}"
    return bind_available()


def run(lab: Any, opts: Options, state: Path) -> RowResult:
    res = RowResult(6, TITLE)
    ready, why = available()
    if not ready:
        res.status, res.reason = "not available yet", why
        return res
    mod = importlib.import_module(MODULE)
    stores = tuple(getattr(mod, "STORES", ("folder", "dns")))
    timeout = 30.0 if opts.quick else 60.0
    budget = INTERVAL_S + 2.0
    details: dict[str, Any] = {"interval_s": INTERVAL_S, "stores": {}}
    for store in stores:
        ln = Line(6, f"Sync, {store} store: change to member updated", "s",
                  goal=f"<= {budget:g} s (poll {INTERVAL_S:g} s + 2 s)")
        ok, why = _store_ready(store)
        if ok and opts.quick and store != stores[0]:
            ok, why = False, "--quick measures the first store only"
        if not ok:
            ln.status, ln.note = "skipped", f"skipped: {why}"
            res.lines.append(ln)
            details["stores"][store] = {"skipped": why}
            continue
        try:
            runs = mod.measure_change_latency(lab, store, state / f"sync-{store}",
                                              interval_s=INTERVAL_S, repeats=opts.reps,
                                              timeout_s=timeout)
        finally:
            lab.reset()
        got = [r.to_json() for r in runs]
        details["stores"][store] = got
        ln.app = [r["checks_s"] for r in got if r["checks_s"] is not None]
        missed = len(got) - len(ln.app)
        ln.met = bool(got) and all(r["within_budget"] and r["checks_pass"] for r in got)
        hosts = median([r["hosts_s"] for r in got if r["hosts_s"] is not None])
        pub = median([r["published_s"] for r in got if r["published_s"] is not None])
        parts = ["to the member's hosts entry and its re-run checks (linux.ssh, ros.master...); "
                 "no baseline: the tutorial's scripts act only when a shell opens"]
        if pub is not None:
            parts.append(f"robot's record published at {pub:.2f} s")
        if hosts is not None:
            parts.append(f"laptop's hosts entry at {hosts:.2f} s")
        if missed:
            parts.append(f"{missed} of {len(got)} changes not followed within {timeout:g} s")
        failed = sorted({k for r in got for k in r.get("failures", {})})
        if failed:
            parts.append(f"checks failed after the change: {', '.join(failed)}")
        ln.note = "; ".join(parts)
        res.lines.append(ln)
    res.details = details
    return res
