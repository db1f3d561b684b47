"""Rows 1, 4, 5 and 7 run together in one loopback world (bench/rows_local.py: start-up and
responsiveness; bench/rows_bytes.py: terminal traffic and bursts of keys)."""

from __future__ import annotations

import time
from collections.abc import Callable

from bench.local_env import local_world
from bench.model import Options, RowResult
from bench.rows_bytes import row4_bytes, row7_bursts
from bench.rows_local import row1_startup, row5_latency


def run_local_rows(rows: list[int], opts: Options, log: Callable[[str], None]) -> list[RowResult]:
    """Rows 1, 4, 5, 7 in one loopback world."""
    out: list[RowResult] = []
    funcs = {1: row1_startup, 4: row4_bytes, 5: row5_latency, 7: row7_bursts}
    wanted = [r for r in rows if r in funcs]
    if not wanted:
        return out
    with local_world(compiled=True) as world:
        for r in wanted:
            log(f"row {r}: running")
            t0 = time.monotonic()
            try:
                res = funcs[r](world, opts)
            except Exception as exc:  # a row that cannot measure says why; the others go on
                res = RowResult(r, {1: "Start-up", 4: "Terminal traffic",
                                    5: "Responsiveness", 7: "Bursts of keys"}[r],
                                status="error",
                                reason=f"{type(exc).__name__}: {exc}")
            res.seconds = time.monotonic() - t0
            out.append(res)
    return out
