"""Row 8: the fleet grows. On the N-site lab (tests/lab/fleet.py, nine sites: a master and eight
members), the master's full verification (`rosnet-tui check`, every step, both directions) with
1, 2, 4 and 8 members in its settings, under ROS 1 and ROS 2, as a ratio to 1 member; and the
address-sync fan-out: all eight members follow a change of the master's public address
(bench/fleet_sync.py).

The same built fleet serves every measurement; only the master's settings file says how many of
the members it verifies (the first N). Every command runs through ``fleet.run`` (bounded); the
fleet is destroyed at the end, whatever happens.
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import tempfile
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

from bench.compiled import compiled_copy, run_compiled
from bench.model import BenchError, Line, Options, RowResult, goal_ratio, median

TITLE = "The fleet grows: the master's verification with 1 to 8 members, and the sync fan-out"
SIZES = (1, 2, 4, 8)
SITES = 9
CHECK_TIMEOUT = 120.0


def write_master_config(fleet: Any, settings: Any, members: int, path: Path) -> Path:
    """*settings* (the master's) with only its first *members* peers, written to *path*."""
    from rosnet_tui.core.saved.settings import atomic_write_text, render_settings

    atomic_write_text(path, render_settings(replace(settings, peers=settings.peers[:members])),
                      mode=0o644)
    return path


def machine_busy_s() -> float:
    """CPU seconds the whole machine has been busy (all cores; /proc/stat, idle and iowait
    left out)."""
    with open("/proc/stat") as f:
        v = [int(x) for x in f.readline().split()[1:]]
    return (sum(v[:8]) - v[3] - v[4]) / os.sysconf("SC_CLK_TCK")


def _children_cpu_s() -> float:
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def master_check(fleet: Any, config: Path, env: dict[str, str], package: Path | None
                 ) -> dict[str, Any]:
    """`rosnet-tui check --json -q` (every step) on the master: wall time and verdicts."""
    if package is not None:
        env = run_compiled(env, package)
    busy0, own0 = machine_busy_s(), _children_cpu_s()
    t0 = time.monotonic()
    r = fleet.rosnet(fleet.master, "check", "--json", "-q", "--config", str(config), env=env,
                     timeout=CHECK_TIMEOUT)
    wall = time.monotonic() - t0
    # rosnet-tui is the only child of this process that ends during the run (the fleet's
    # daemons run on; the peers' programs are sshd's children): its CPU time, and the whole
    # machine's (every site of the lab shares this machine's cores).
    own, busy = _children_cpu_s() - own0, machine_busy_s() - busy0
    try:
        checks = json.loads(r.stdout)["checks"]
    except (ValueError, KeyError) as exc:
        raise BenchError(f"rosnet-tui check on the master gave no JSON (exit {r.returncode}): "
                         f"{r.stderr[-500:]}") from exc
    slowest = max(checks, key=lambda c: c["duration_s"])
    # All good: nothing fails or warns (under ROS 2 the members forward SSH only, so the checks
    # of ports a ROS 1 member would open skip).
    return {"wall_s": wall, "exit": r.returncode, "cpu_s": own, "machine_busy_s": busy,
            "all_pass": r.returncode == 0 and all(c["status"] in ("pass", "skip")
                                                  for c in checks),
            "not_pass": {c["id"]: f"{c['status']}: {c['summary']}" for c in checks
                         if c["status"] != "pass"},
            "evidence": {c["id"]: c.get("evidence") for c in checks
                         if c["status"] in ("fail", "warn")},
            "statuses": {c["id"]: c["status"] for c in checks},
            "durations": {c["id"]: c["duration_s"] for c in checks},
            "slowest": f"{slowest['id']} {slowest['duration_s']:.2f} s"}


def measure_sizes(fleet: Any, settings: Any, env: dict[str, str], opts: Options, state: Path,
                  package: Path | None, tag: str,
                  before: Callable[[Path], None] | None = None) -> dict[int, list[dict[str, Any]]]:
    """Every size once per repetition, the order alternating (no size always first);
    *before(config)* runs ahead of each (untimed)."""
    configs = {n: write_master_config(fleet, settings, n, state / f"{tag}-{n}.toml")
               for n in SIZES}
    env = dict(env, XDG_STATE_HOME=str(state / f"{tag}-state"))
    runs: dict[int, list[dict[str, Any]]] = {n: [] for n in SIZES}

    def one(n: int) -> dict[str, Any]:
        if before is not None:
            before(configs[n])
        return master_check(fleet, configs[n], env, package)

    one(SIZES[0])    # a warm-up run, not counted
    for i in range(opts.reps):
        for n in (SIZES if i % 2 == 0 else tuple(reversed(SIZES))):
            runs[n].append(one(n))
    return runs


def size_lines(runs: dict[int, list[dict[str, Any]]], ros: str) -> list[Line]:
    base = [r["wall_s"] for r in runs[SIZES[0]]]
    lines = []
    for n in SIZES[1:]:
        ln = Line(8, f"{ros}: the master's full verification, {n} members (wall time)", "s",
                  [r["wall_s"] for r in runs[n]], base,
                  baseline="the same with 1 member", goal="<= 1.3x" if n == SIZES[-1] else "")
        if n == SIZES[-1]:
            goal_ratio(ln, 1.3)
        ok = all(r["all_pass"] for r in runs[n])
        ln.note = (f"{len(runs[n][0]['statuses']) if runs[n] else 0} checks, nothing failed "
                   f"or warned: {'yes' if ok else 'NO'}; slowest check (median run) "
                   f"{_median_run(runs[n])['slowest'] if runs[n] else '-'}; "
                   + _cpu_note(runs[n]))
        if n == SIZES[1]:
            ln.note += (f"; 1 member: {median(base):.2f} s, slowest "
                        f"{_median_run(runs[SIZES[0]])['slowest']}, " + _cpu_note(runs[SIZES[0]]))
        bad = sorted({f"{k} ({r['not_pass'][k]})" for m in (n, SIZES[0]) for r in runs[m]
                      for k, v in r["statuses"].items() if v in ("fail", "warn")})
        if bad:   # a verdict that is not good: said, and the row's exit code says so
            ln.status = "error"
            ln.note += f"; not all good in {sum(not r['all_pass'] for r in runs[n])} of " \
                       f"{len(runs[n])} runs: {bad}"
        lines.append(ln)
    return lines


def _cpu_note(runs: list[dict[str, Any]]) -> str:
    wall = median([r["wall_s"] for r in runs]) or 0.0
    return (f"rosnet-tui's own CPU {median([r['cpu_s'] for r in runs]):.2f} s, the machine busy "
            f"{median([r['machine_busy_s'] for r in runs]):.2f} of "
            f"{wall * (os.cpu_count() or 1):.2f} core-seconds")


def _median_run(runs: list[dict[str, Any]]) -> dict[str, Any]:
    return sorted(runs, key=lambda r: r["wall_s"])[len(runs) // 2]


def run_fleet_row(opts: Options, log: Callable[[str], None]) -> list[RowResult]:
    res = RowResult(8, TITLE)
    try:
        from tests.lab import LabUnavailable, lab_available
        from tests.lab.firewall import apply_firewall, remove_firewall
        from tests.lab.fleet import Fleet
        from tests.lab.fleet_ros2 import FleetRos2
    except Exception as exc:  # e.g. the lab's own dependencies are missing
        res.status, res.reason = "skipped", f"the network lab cannot be imported: {exc}"
        return [res]
    ok, why = lab_available()
    if not ok:
        res.status, res.reason = "skipped", why
        return [res]
    if shutil.which("roscore") is None:
        res.status, res.reason = "skipped", "roscore is not installed (Debian package ros-core)"
        return [res]
    t0 = time.monotonic()
    fleet = Fleet(SITES)
    state = Path(tempfile.mkdtemp(prefix="rosnet-bench-fleet-"))
    details: dict[str, Any] = {}
    try:
        package = compiled_copy(state / "package")
        log(f"row 8: building a fleet of {SITES} sites")
        try:
            fleet.build()
        except LabUnavailable as exc:
            res.status, res.reason = "skipped", str(exc)
            return [res]
        details["build_s"] = fleet.build_s
        log("row 8: ROS 1")
        fleet.reset()
        fleet.start_roscore()
        try:
            # ROS 1 as the product sets it up: the master's peers-only firewall loaded for the
            # members its settings name (so linux.firewall and security.outsider pass too).
            ros1 = measure_sizes(fleet, fleet.settings(fleet.master),
                                 fleet.ros_env(fleet.master), opts, state, package, "ros1",
                                 before=lambda c: apply_firewall(fleet, fleet.master, c))
        finally:
            remove_firewall(fleet, fleet.master)
            fleet.stop_roscore()
            fleet.reset()
        res.lines += size_lines(ros1, "ROS 1")
        details["ros1"] = {str(n): v for n, v in ros1.items()}
        log("row 8: ROS 2")
        with FleetRos2(fleet) as w:
            ros2 = measure_sizes(fleet, w.settings(fleet.master), w.env(fleet.master), opts,
                                 state, package, "ros2")
        res.lines += size_lines(ros2, "ROS 2")
        details["ros2"] = {str(n): v for n, v in ros2.items()}
        log("row 8: sync fan-out")
        from bench import fleet_sync

        lines, sync_details = fleet_sync.run(fleet, opts, state / "sync")
        res.lines += lines
        details["sync"] = sync_details
    except Exception as exc:
        res.status, res.reason = "error", f"{type(exc).__name__}: {exc}"
    finally:
        fleet.destroy()
        shutil.rmtree(state, ignore_errors=True)
    res.details = details
    res.seconds = time.monotonic() - t0
    return [res]
