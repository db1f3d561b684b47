"""Row 4 (bytes a slow link must carry) and row 7 (a burst of keys equals the same keys typed
slowly). Run anywhere: loopback only (bench/local_env.py).

Row 4 measures, for xterm-256color and TERM=linux, at 80x24 and 120x40: the first frame, a step
change (first visit, and a revisit), one streamed check result (the router step's 4 results
streaming, divided by 4), the help screen, and the bytes per second while idle on the step, help
and set-up screens (the worst of the three). Each against the issue's target: 8 kB, 4 kB, 4 kB,
600 B, 8 kB and 0 B/s at 80x24, 1.5 times those at 120x40; the bare Textual app's first frame
and line change are given for scale.

Row 7 types key sequences into the wizard under a pty twice, one key at a time (waiting for the
screen to settle after each) and in one write, and compares what they leave: the saved settings,
and the screen itself (rebuilt from the output with pyte when it is installed).
"""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import Any

from bench.local_env import LocalWorld, spawn_app, spawn_bare
from bench.model import BenchError, Line, Options, RowResult
from bench.pty_harness import PtyProcess
from bench.rows_local import (
    ROUTER_CHECKS,
    app_first_frame,
    app_title,
    bare_first_frame,
    first_frame,
)

TERMS = ("xterm-256color", "linux")
SIZES = ((80, 24), (120, 40))
# The targets at 80x24 (bytes; idle in bytes per second); 120x40 may use 1.5 times.
TARGETS = {"first_frame": 8000, "step_first": 4000, "step_again": 4000, "result": 600,
           "help": 8000, "idle": 0}
LARGE_FACTOR = 1.5
MEASURES = (("first_frame", "first frame", "B"), ("step_first", "step change, first visit", "B"),
            ("step_again", "step change, revisit", "B"), ("result", "one streamed result", "B"),
            ("help", "help screen", "B"), ("idle", "idle, worst screen", "B/s"))


def _settle_after(p: PtyProcess, mark: int, opts: Options, shown: str | None) -> tuple[int, float]:
    """Wait for *shown* (or any output) since *mark*, then for quiet: (bytes, last byte time)."""
    if shown is None:
        p.wait_for(lambda t: True, 3, mark)
    elif p.wait_text(shown, 10, mark) is None:
        raise BenchError(f"{shown!r} did not appear: {p.text_since(mark)[-400:]!r}")
    last, _ = p.wait_quiet(opts.quiet_s, timeout=15)
    return p.bytes_since(mark, until=last), last


def _press(p: PtyProcess, keys: str, opts: Options, shown: str | None = None) -> int:
    mark = p.mark
    p.send(keys)
    return _settle_after(p, mark, opts, shown)[0]


def _idle(p: PtyProcess, seconds: float) -> float:
    mark = p.mark
    p.drain(seconds)
    return p.bytes_since(mark) / seconds


def _bytes_session(world: LocalWorld, term: str, size: tuple[int, int], opts: Options
                   ) -> dict[str, Any]:
    world.fresh_state()
    p = spawn_app(world, cols=size[0], rows=size[1], term=term)
    out: dict[str, Any] = {"who": "app", "term": term, "size": f"{size[0]}x{size[1]}"}
    idle_s = max(1.0, opts.idle_s / 2)
    try:
        out["first_frame"] = first_frame(p, app_first_frame, opts, "rosnet-tui")[
            "first_frame_bytes"]
        idles = [_idle(p, idle_s)]
        out["step_first"] = _press(p, "2", opts, app_title("2"))
        out["step_again"] = max(_press(p, "1", opts, app_title("1")),
                                _press(p, "2", opts, app_title("2")))
        mark = p.mark
        p.send("r")
        if p.wait_text("checking", 5, mark) is None:
            raise BenchError(f"r started no checks: {p.text_since(mark)[-400:]!r}")
        got = p.wait_for(lambda t: sum(t.count(w) for w in ("PASS", "WARN", "FAIL", "SKIP"))
                         >= ROUTER_CHECKS, 30, mark)
        if got is None:
            raise BenchError(f"the router checks did not all answer: {p.text_since(mark)[-400:]!r}")
        last, _ = p.wait_quiet(max(1.0, opts.quiet_s * 2), timeout=30)
        out["stream_bytes"] = p.bytes_since(mark, until=last)
        out["result"] = out["stream_bytes"] / ROUTER_CHECKS
        idles.append(_idle(p, idle_s))
        out["help"] = _press(p, "?", opts, "closes this help")
        idles.append(_idle(p, idle_s))
        _press(p, "\x1b", opts)
        _press(p, "s", opts, "This component")
        idles.append(_idle(p, idle_s))
        out["idle"] = max(idles)
        out["idle_each"] = idles
    finally:
        p.close(b"\x11")
    return out


def _bare_session(world: LocalWorld, term: str, size: tuple[int, int], opts: Options
                  ) -> dict[str, Any]:
    world.fresh_state()
    p = spawn_bare(world, cols=size[0], rows=size[1], term=term)
    out: dict[str, Any] = {"who": "bare", "term": term, "size": f"{size[0]}x{size[1]}"}
    try:
        out["first_frame"] = first_frame(p, bare_first_frame, opts, "bare app")[
            "first_frame_bytes"]
        out["step_first"] = out["step_again"] = _press(p, "2", opts, "bare step 2")
        out["idle"] = _idle(p, max(1.0, opts.idle_s / 2))
    finally:
        p.close(b"q")
    return out


def row4_bytes(world: LocalWorld, opts: Options) -> RowResult:
    res = RowResult(4, "Terminal traffic: bytes a slow link carries (xterm-256color and "
                       "TERM=linux, 80x24 and 120x40)")
    runs: list[dict[str, Any]] = []
    for _ in range(opts.reps):
        for term in TERMS:
            for size in SIZES:
                runs.append(_bytes_session(world, term, size, opts))
                runs.append(_bare_session(world, term, size, opts))
    for term in TERMS:
        for size in SIZES:
            tag = f"{size[0]}x{size[1]} {'linux' if term == 'linux' else 'xterm'}"
            app = [r for r in runs if r["who"] == "app" and r["term"] == term
                   and r["size"] == f"{size[0]}x{size[1]}"]
            bare = [r for r in runs if r["who"] == "bare" and r["term"] == term
                    and r["size"] == f"{size[0]}x{size[1]}"]
            factor = 1.0 if size == (80, 24) else LARGE_FACTOR
            for key, words, unit in MEASURES:
                target = TARGETS[key] * factor
                base = [r[key] for r in bare if key in r]
                ln = Line(4, f"Bytes {tag}: {words}", unit, [r[key] for r in app], base,
                          baseline="bare Textual app" if base else "",
                          goal=(f"<= {target:g} {unit}" if target else "0 B/s"))
                worst = max(ln.app) if ln.app else None
                ln.met = None if worst is None else worst <= target
                if key == "result":
                    ln.note = (f"r on the router step: {ROUTER_CHECKS} results streaming, "
                               "bytes divided by 4")
                elif key == "idle":
                    ln.note = "worst of the step, help and set-up screens"
                elif key == "step_again":
                    ln.note = "worst of going back to step 1 and again to step 2"
                res.lines.append(ln)
    res.details = {"runs": runs}
    return res


# =============================================================================== row 7
SEQUENCES: list[tuple[str, str, list[str], str]] = [
    # (name, screen, keys, the step whose text ends the sequence on screen)
    ("first-run set-up", "setup",
     ["robot1", "\x0e", "sami", "\t", "192.168.1.10", "\t", "198.51.100.2", "\x7f", "3", "\x13"],
     "1"),
    ("steps", "steps", ["2", "r", "3", "\x1b[B", "4", "?", "\x1b", "1", "n"], "2"),
]
TOAST_S = 4.5  # toasts (e.g. "Settings saved") are gone after this


def _screen_of(data: bytes, cols: int, rows: int) -> list[str] | None:
    """The screen the output leaves (port numbers masked: the port checker picks random extra
    ports on every run); None without pyte."""
    try:
        import pyte
    except ImportError:
        return None
    screen = pyte.Screen(cols, rows)
    pyte.Stream(screen).feed(data.decode("utf-8", "replace"))
    return [re.sub(r"\d{4,}|\d+(?=…)", "#", line) for line in screen.display]


def _type_session(world: LocalWorld, keys: list[str], burst: bool, screen_kind: str,
                  done: str, opts: Options) -> dict[str, Any]:
    world.fresh_state()
    config = world.root / "row7.toml"
    config.unlink(missing_ok=True)
    if screen_kind == "steps":
        config.write_text(world.config.read_text())
    p = spawn_app(world, config=config)
    try:
        marker = "This component" if screen_kind == "setup" else app_title("1")
        if p.wait_text(marker, 30) is None:
            raise BenchError(f"no first screen: {p.text_since(0)[-400:]!r}")
        p.wait_quiet(opts.quiet_s, 10)
        mark = p.mark
        if burst:
            p.send("".join(keys))
        else:
            for k in keys:
                m = p.mark
                p.send(k)
                p.wait_for(lambda t: True, 2, m)
                p.wait_quiet(max(0.3, opts.quiet_s), 10)
        p.wait_text(app_title(done), 15, mark)
        p.wait_quiet(max(1.0, opts.quiet_s * 2), 30)
        p.drain(TOAST_S)
        screen = _screen_of(p.raw_since(0), 80, 24)
    finally:
        p.close(b"\x11")
    return {"settings": config.read_text() if config.exists() else None, "screen": screen}


def row7_bursts(world: LocalWorld, opts: Options) -> RowResult:
    res = RowResult(7, "Keys in a burst have the effect of the same keys typed slowly (pty 80x24)")
    for name, kind, keys, done in SEQUENCES:
        same: list[float] = []
        notes: list[str] = []
        for _ in range(opts.reps):
            slow = _type_session(world, keys, False, kind, done, opts)
            fast = _type_session(world, keys, True, kind, done, opts)
            equal = slow == fast
            same.append(1.0 if equal else 0.0)
            if not equal:
                diff = [k for k in slow if slow[k] != fast[k]]
                notes.append(f"differs in {', '.join(diff)}")
        ln = Line(7, f"Burst = slow: {name}", "x", same, [], goal="equal (1)")
        ln.met = all(v == 1.0 for v in same)
        ln.note = ("keys: " + " ".join(repr(k)[1:-1] for k in keys)
                   + ("; compared: saved settings and the screen" if _screen_of(b"", 1, 1)
                      is not None else "; compared: saved settings (pyte not installed)")
                   + (f"; {'; '.join(notes)}" if notes else ""))
        res.lines.append(ln)
    return res


ROWS: dict[int, Callable[[LocalWorld, Options], RowResult]] = {4: row4_bytes, 7: row7_bursts}
