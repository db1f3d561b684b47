"""Rows 1 and 5 (bench/local_rows.py runs them with rows 4 and 7): the wizard under a pty
against a bare Textual app. Run anywhere.

Every program runs in a loopback-only world (bench/local_env.py): nothing leaves 127.0.0.0/8.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from bench.bare_app import LINE as BARE_LINE
from bench.local_env import LocalWorld, spawn_app, spawn_bare
from bench.model import BenchError, Line, Options, RowResult, goal_ratio, median
from bench.pty_harness import PtyProcess

STEP_KEYS = ("1", "2", "3", "4")
ROUTER_CHECKS = 4           # router.local_ip, port_free, listener, port_open
START_TIMEOUT = 30.0        # a program that shows nothing within this is an error


def app_title(key: str) -> str:
    """Text that is on the screen only while that step is shown: the first words of its
    expected outcome (from the core's step data, so a change of the UI's wording does not
    break the bench; five words always fit on the pane's first line at 80 columns)."""
    from rosnet_tui.core.wizard.steps import STEPS

    return " ".join(STEPS[int(key) - 1].expected.split()[:5])


def app_first_frame(text: str) -> bool:
    return app_title("1") in text


def bare_first_frame(text: str) -> bool:
    return BARE_LINE in text


def _tail(p: PtyProcess, n: int = 600) -> str:
    return p.text_since(0)[-n:].replace("\r", "")


def first_frame(p: PtyProcess, done: Callable[[str], bool], opts: Options, who: str
                ) -> dict[str, Any]:
    """Wait for the first complete frame: the marker text is on screen and the output has been
    quiet for opts.quiet_s. The frame's time is that of its last byte."""
    seen = p.wait_for(done, START_TIMEOUT)
    if seen is None:
        raise BenchError(f"{who}: no first frame within {START_TIMEOUT:g} s "
                         f"(exit code {p.proc.poll()}); last output: {_tail(p)!r}")
    last, quiet = p.wait_quiet(opts.quiet_s, timeout=10)
    return {"first_frame_s": last - p.t_start, "marker_s": seen - p.t_start,
            "first_frame_bytes": p.bytes_since(0, until=last), "went_quiet": quiet,
            "vmhwm_kb": p.status_kb("VmHWM")}


# =============================================================================== row 1
def row1_startup(world: LocalWorld, opts: Options) -> RowResult:
    res = RowResult(1, "Start-up: launch to first complete frame, and peak RSS (pty 80x24)")
    app_t, base_t, app_m, base_m = [], [], [], []
    runs: list[dict[str, Any]] = []
    for i in range(opts.reps):
        # Alternate which goes first, so drifts of the machine hit both alike.
        order = ("app", "bare") if i % 2 == 0 else ("bare", "app")
        for who in order:
            world.fresh_state()
            p = spawn_app(world) if who == "app" else spawn_bare(world)
            try:
                m = first_frame(p, app_first_frame if who == "app" else bare_first_frame, opts,
                                "rosnet-tui" if who == "app" else "bare app")
            finally:
                p.close(b"q")
            runs.append({"who": who, **m})
            (app_t if who == "app" else base_t).append(m["first_frame_s"])
            if m["vmhwm_kb"]:
                (app_m if who == "app" else base_m).append(m["vmhwm_kb"] / 1024)
    t = Line(1, "Start-up: launch to first frame", "s", app_t, base_t,
             baseline="a bare Textual app showing one static line", goal="<= 1.3x")
    goal_ratio(t, 1.3)
    m = Line(1, "Start-up: peak RSS", "MB", app_m, base_m,
             baseline="bare Textual app", goal="<= 1.25x")
    goal_ratio(m, 1.25)
    m.note = "VmHWM of the process at its first frame"
    t.note = (f"first frame = last byte before {opts.quiet_s:g} s of quiet; marker text seen at "
              f"{median([r['marker_s'] for r in runs if r['who'] == 'app']):.2f} s (app), "
              f"{median([r['marker_s'] for r in runs if r['who'] == 'bare']):.2f} s (bare)")
    res.lines = [t, m]
    res.details = {"runs": runs}
    return res


# =============================================================================== row 4
def _press_and_settle(p: PtyProcess, key: str, shown: str, opts: Options, who: str
                      ) -> dict[str, Any]:
    mark = p.mark
    sent = p.send(key)
    seen = p.wait_text(shown, 5, mark)
    if seen is None:
        raise BenchError(f"{who}: pressing {key!r} did not show {shown!r} within 5 s; "
                         f"output since: {p.text_since(mark)[-400:]!r}")
    last, _ = p.wait_quiet(opts.quiet_s, timeout=10)
    return {"latency_s": seen - sent, "settled_s": last - sent,
            "bytes": p.bytes_since(mark, until=last)}


# =============================================================================== row 5
KEY_SEQUENCE = ["3", "4", "1", "2", "3", "4", "1", "2"]


def _latency_session(world: LocalWorld, who: str, opts: Options) -> dict[str, Any]:
    world.fresh_state()
    if who == "app":
        p = spawn_app(world, config=world.config_slow)
    else:
        p = spawn_bare(world)
    presses: list[dict[str, Any]] = []
    try:
        first_frame(p, app_first_frame if who == "app" else bare_first_frame, opts, who)
        shown = {k: (app_title(k) if who == "app" else f"bare step {k}") for k in STEP_KEYS}
        _press_and_settle(p, "2", shown["2"], opts, who)
        visited = {"1", "2"}
        mark = p.mark
        t_r = p.send("r")
        if who == "app" and p.wait_text("checking...", 5, mark) is None:
            raise BenchError(f"app: 'r' started no checks: {p.text_since(mark)[-400:]!r}")
        for key in KEY_SEQUENCE[:4] if opts.quick else KEY_SEQUENCE:
            mark = p.mark
            sent = p.send(key)
            seen = p.wait_text(shown[key], 5, mark)
            if seen is None:
                raise BenchError(f"{who}: {key!r} did not show {shown[key]!r} within 5 s")
            presses.append({"key": key, "latency_s": seen - sent, "first_visit": key not in visited,
                            "since_r_s": sent - t_r})
            visited.add(key)
            p.wait_quiet(0.1, timeout=2)  # let the frame finish, like a person reading it
    finally:
        p.close(b"q")
    return {"who": who, "presses": presses}


def row5_latency(world: LocalWorld, opts: Options) -> RowResult:
    res = RowResult(5, "Responsiveness: key press to the new step on screen, while checks run")
    runs = [_latency_session(world, who, opts)
            for i in range(opts.reps) for who in (("app", "bare") if i % 2 == 0 else ("bare", "app"))]
    app = [p for r in runs if r["who"] == "app" for p in r["presses"]]
    bare = [p for r in runs if r["who"] == "bare" for p in r["presses"]]
    ln = Line(5, "Key press to new step shown", "ms",
              [p["latency_s"] * 1000 for p in app], [p["latency_s"] * 1000 for p in bare],
              baseline="bare Textual app changing its line", goal="< 100 ms")
    med = ln.app_median
    ln.met = None if med is None else med < 100
    first = [p["latency_s"] * 1000 for p in app if p["first_visit"]]
    again = [p["latency_s"] * 1000 for p in app if not p["first_visit"]]
    latest = max(p["since_r_s"] for p in app) if app else 0
    ln.note = (f"app max {max(p['latency_s'] for p in app) * 1000:.0f} ms; first visit of a "
               f"step {median(first) or 0:.0f} ms, revisit {median(again) or 0:.0f} ms; "
               f"router.port_open waits on a silent server meanwhile (last key "
               f"{latest:.1f} s after r, its budget 8.1 s)")
    res.lines = [ln]
    res.details = {"runs": runs}
    return res
