"""Row 9: a dead link seen in seconds (issue 31), on the two-site lab under ROS 2.

The robot (the master) runs a talker; the laptop (a member) watches its own router's admin space
and the talker's data (tests/lab/ros2_scripts/zwatch.py, timestamps on the clock every namespace
shares). Then the robot's modem loses its uplink silently (it drops everything it forwards, both
ways: no reset, no ICMP; the laptop's router can learn it only from its lease), and we time:

- until the laptop's router drops its session with the master's router (its lease ran out);
- until `rosnet-tui check --step ros`, started on the laptop at the cut, has its verdicts (the
  master's router is reported gone);
- after the uplink comes back: until the laptop's router is linked to the master's again, and
  until the talker's data arrives on the laptop again.

Goal: both the notice and the data again within 15 s. The routers run the configs `ros apply`
writes (rosnet_tui/core/ros/ros2.py: lease, keep-alive, connect retry).
"""

from __future__ import annotations

import re
import sys
import time
from typing import Any

from bench.model import BenchError, Line, Options, RowResult, median

TITLE = "A dead link seen in seconds, and data again after it returns (ROS 2)"
GOAL_S = 15.0
CAP_S = 40.0          # the longest any one wait may take
LONG_CUT_S = 30.0     # every other cut is held this long (the others end once it was noticed)


def _zid(lab: Any, host: str, cap: float = 10.0) -> str:
    """The router's id, from the line it prints once its session is open (it may listen a moment
    before it prints: waited for, bounded)."""
    deadline = time.monotonic() + cap
    while True:
        text = lab.log_path(f"zrouter-{host}").read_text(errors="replace")
        m = re.search(r"^ZROUTER (\S+)", text, re.M)
        if m is not None:
            return m.group(1).lstrip("0")
        if time.monotonic() > deadline:
            raise BenchError(f"the router on {host} printed no id")
        time.sleep(0.05)


def _events(lab: Any, proc: Any) -> list[tuple[str, float, str]]:
    out = []
    for ln in lab.output(proc).splitlines():
        parts = ln.split(" ", 2)
        if parts[0] in ("ROUTERS", "DATA") and len(parts) >= 2:
            out.append((parts[0], float(parts[1]), parts[2] if len(parts) > 2 else ""))
    return out


def _wait_event(lab: Any, proc: Any, after: float, match, cap: float) -> float | None:
    """The time of the first watcher event after *after* that *match*es (None: not within *cap*)."""
    deadline = time.monotonic() + cap
    while time.monotonic() < deadline:
        for kind, t, rest in _events(lab, proc):
            if t >= after and match(kind, rest):
                return t
        if proc.poll() is not None:
            return None
        time.sleep(0.05)
    return None


def measure_once(w: Any, member: str = "laptop", master: str = "robot",
                 hold_s: float = 0.0) -> dict[str, Any]:
    """One cut and return on the healthy ROS 2 world *w* (tests/lab/ros2.py Ros2World); the
    uplink stays cut until the member's router noticed, and at least *hold_s*."""
    from tests.lab.ros2 import SCRIPTS

    lab = w.lab
    mzid = _zid(lab, master)
    talker = w.node(master, "talker")
    watch = lab.spawn(member, [sys.executable, str(SCRIPTS / "zwatch.py"), "tcp/127.0.0.1:7447",
                               "0/chatter/**", str(4 * CAP_S)])
    w.nodes.append(watch)            # stopped with the world's nodes

    def linked(kind: str, rest: str) -> bool:
        return kind == "ROUTERS" and mzid in [z.lstrip("0") for z in rest.split(",")]

    def unlinked(kind: str, rest: str) -> bool:
        return kind == "ROUTERS" and not linked(kind, rest)

    def data(kind: str, _rest: str) -> bool:
        return kind == "DATA"

    try:
        if _wait_event(lab, watch, 0.0, linked, CAP_S) is None or \
                _wait_event(lab, watch, 0.0, data, CAP_S) is None:
            raise BenchError(f"no data from the talker, or no link, before the cut: "
                             f"{lab.output(watch)[-500:]}")
        t_cut = time.monotonic()
        lab.cut_uplink(master, True)
        check = w.check(member)              # started at the cut; bounded by its own timeout
        t_checked = time.monotonic()
        t_gone = _wait_event(lab, watch, t_cut, unlinked, CAP_S)
        time.sleep(max(0.0, t_cut + hold_s - time.monotonic()))
        t_back = time.monotonic()
        lab.cut_uplink(master, False)
        t_relinked = _wait_event(lab, watch, t_back, linked, CAP_S)
        t_data = _wait_event(lab, watch, t_back, data, CAP_S)
        router = check.get("ros2.router") or {}
        return {"router_notice_s": None if t_gone is None else t_gone - t_cut,
                "check_s": t_checked - t_cut, "check_router_s": router.get("duration_s"),
                "check_router": router.get("status"), "check_summary": router.get("summary"),
                "not_passing": sorted(k for k, c in check.items() if c["status"] != "pass"),
                "cut_s": t_back - t_cut,
                "relinked_s": None if t_relinked is None else t_relinked - t_back,
                "data_again_s": None if t_data is None else t_data - t_back}
    finally:
        lab.cut_uplink(master, False)
        lab.kill(talker, grace=0.5)
        lab.kill(watch, grace=0.5)


def run(lab: Any, opts: Options, log: Any = None) -> RowResult:
    """Row 9 on the built two-site *lab*."""
    from tests.lab.ros2 import Ros2World

    res = RowResult(9, TITLE)
    runs: list[dict[str, Any]] = []
    lab.stop_roscore()
    with Ros2World(lab) as w:
        for i in range(opts.reps):
            if log is not None:
                log(f"row 9: cut {i + 1} of {opts.reps}")
            w.healthy()     # every other cut held 30 s: the router re-dials at its slowest
            runs.append(measure_once(w, hold_s=LONG_CUT_S if i % 2 else 0.0))
    worst = lambda key: (None if any(r[key] is None for r in runs)  # noqa: E731
                         else max(r[key] for r in runs))
    notice = Line(9, "Dead link noticed by the member's router (lease)", "s",
                  [r["router_notice_s"] for r in runs if r["router_notice_s"] is not None], [],
                  goal=f"<= {GOAL_S:g} s")
    wn = worst("router_notice_s")
    notice.met = wn is not None and wn <= GOAL_S
    checks = [r["check_s"] for r in runs]
    failing = all(r["check_router"] == "fail" for r in runs)
    notice.note = (f"the master's modem drops everything, both ways, silently; slowest "
                   f"{_s(wn)}; `check --step ros` started at the cut: every verdict after "
                   f"{_s(median(checks))} (the whole command), ros2.router failing every time: "
                   f"{'yes' if failing else 'NO'}, its verdict "
                   f"{_s(median([r['check_router_s'] for r in runs]))} into its run (no answer "
                   "from the master's router within its timeout)")
    again = Line(9, "Data flowing again after the link returns", "s",
                 [r["data_again_s"] for r in runs if r["data_again_s"] is not None], [],
                 goal=f"<= {GOAL_S:g} s")
    wa = worst("data_again_s")
    again.met = wa is not None and wa <= GOAL_S
    held = sorted({round(r["cut_s"]) for r in runs})
    again.note = (f"a talker on the master, heard on the member; slowest {_s(wa)}; the member's "
                  f"router linked again after {_s(median([r['relinked_s'] for r in runs]))} "
                  f"(median); cuts held {' and '.join(f'{h} s' for h in held)}")
    if not failing:
        notice.status = "error"
    res.lines = [notice, again]
    res.details = {"runs": runs}
    return res


def _s(x: float | None) -> str:
    return "never (within the cap)" if x is None else f"{x:.1f} s"
