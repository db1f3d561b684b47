"""Row 8's sync fan-out: `rosnet-tui sync` on the master and on all eight members of the nine-site
fleet (folder store, the members watching the shared folder), the master's modem given a new
public address at a random moment of the poll cycle, and the time until *every* member's hosts
file names the master by it. Goal: the slowest member within the sync goal (`interval_s` + 1 s).

The services are the sync tests' (tests/sync_support/lab_sync.py: settings with a [sync] table,
the same argv and environment); only the lab is the fleet.
"""

from __future__ import annotations

import contextlib
import random
import time
from pathlib import Path
from typing import Any

from bench.model import Line, Options, median

INTERVAL_S = 2.0
NEW_IPS = ("203.0.113.77", "203.0.113.78")   # alternated: every change is a real change
GOAL_OVER_INTERVAL_S = 1.0                   # the folder store's goal: interval_s + 1 s


def _changes(opts: Options) -> int:
    return 3 if opts.quick else max(5, opts.reps)


def fan_out(fleet: Any, workdir: Path, *, changes: int, interval_s: float = INTERVAL_S,
            timeout_s: float = 30.0, seed: int | None = None) -> list[dict[str, Any]]:
    """Per change: {member: seconds until its hosts entry for the master was the new address
    (None: not within *timeout_s*)}, and the change's phase in the master's poll cycle."""
    from rosnet_tui.core.sync.status import load_status
    from tests.sync_support.lab_sync import (
        hosts_entry,
        sync_argv,
        sync_env,
        wait_for,
        write_sync_config,
    )

    rng = random.Random(seed)
    workdir.mkdir(parents=True, exist_ok=True)
    folder = workdir / "shared"
    folder.mkdir(exist_ok=True)
    master, members = fleet.master, fleet.members
    out: list[dict[str, Any]] = []
    with contextlib.ExitStack() as stack:
        stack.callback(fleet.reset)
        fleet.reset()
        fleet.start_roscore()
        stack.callback(fleet.stop_roscore)
        states = {h: workdir / f"state-{h}" for h in fleet.COMPUTERS}
        procs = {}
        for h in fleet.COMPUTERS:
            cfg = write_sync_config(fleet, h, workdir / f"{h}.toml", store="folder",
                                    folder=folder, interval_s=interval_s)
            procs[h] = fleet.spawn(h, sync_argv(cfg, states[h], "--bashrc",
                                                str(fleet.bashrc_path(h))),
                                   env=sync_env(fleet, h))
            stack.callback(fleet.kill, procs[h])
        current = fleet.public_ip(master)

        def published(ip: str) -> bool:
            st = load_status(states[master]) or {}
            return ((st.get("own") or {}).get("record") or {}).get("public_ip") == ip

        def all_follow(ip: str) -> bool:
            return all(hosts_entry(fleet, m, master) == ip for m in members)

        if not wait_for(lambda: published(current), timeout_s) or not wait_for(
                lambda: all_follow(current), timeout_s):
            raise RuntimeError("sync did not settle on the fleet:\n" + "\n".join(
                f"{h}:\n{fleet.output(procs[h])[-1500:]}" for h in (master, members[-1])))
        time.sleep(interval_s)      # the members' first checks are over
        for i in range(changes):
            ip = NEW_IPS[i % len(NEW_IPS)]
            time.sleep(rng.uniform(0.0, interval_s))     # anywhere in the poll cycle
            t0 = time.monotonic()
            fleet.set_public_ip(master, ip)
            got: dict[str, float | None] = dict.fromkeys(members)
            deadline = t0 + timeout_s
            while time.monotonic() < deadline and any(v is None for v in got.values()):
                for m in members:
                    if got[m] is None and hosts_entry(fleet, m, master) == ip:
                        got[m] = time.monotonic() - t0
                time.sleep(0.01)
            out.append({"new_ip": ip, "members": got})
            time.sleep(interval_s)   # let the members' re-run checks finish before the next
    return out


def run(fleet: Any, opts: Options, workdir: Path) -> tuple[list[Line], dict[str, Any]]:
    n = _changes(opts)
    budget = INTERVAL_S + GOAL_OVER_INTERVAL_S
    runs = fan_out(fleet, workdir, changes=n)
    slowest = [max((v for v in r["members"].values() if v is not None), default=None)
               for r in runs]
    missed = sum(v is None for r in runs for v in r["members"].values())
    every = [v for r in runs for v in r["members"].values() if v is not None]
    ln = Line(8, f"Sync fan-out, folder store: all {len(fleet.members)} members updated, "
                 f"slowest member, median of {n} changes", "s",
              [s for s in slowest if s is not None], [],
              goal=f"<= {budget:g} s (poll {INTERVAL_S:g} s + {GOAL_OVER_INTERVAL_S:g} s)")
    ln.met = not missed and bool(slowest) and max(slowest) <= budget
    ln.note = (f"the master's public address changed {n} times at random moments of its "
               f"{INTERVAL_S:g} s poll cycle; slowest member max "
               f"{max(s for s in slowest if s is not None):.2f} s" if every else "no member followed")
    if every:
        ln.note += (f", any member median {median(every):.2f} s (min {min(every):.2f} s); "
                    "each member watches the shared folder (inotify)")
    if missed:
        ln.note += f"; {missed} member update(s) not seen within 30 s"
    return [ln], {"interval_s": INTERVAL_S, "changes": runs}
