"""The benchmark script runs (benchmarks are not timed tests: no figure is asserted here).

A quick run with one repetition: rows 1, 4, 5 anywhere; rows 2, 3, 6 on the network lab (root and
namespaces; skipped with the reason otherwise).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.lab import lab_available

REPO = Path(__file__).resolve().parents[1]
RUN = REPO / "bench" / "run"


def bench(tmp_path: Path, *args: str, timeout: float = 90) -> tuple[subprocess.CompletedProcess,
                                                                    dict, str]:
    out_json, out_md = tmp_path / "bench.json", tmp_path / "bench.md"
    env = {k: v for k, v in os.environ.items() if not k.startswith("ROS_")}
    env["PYTHON"] = sys.executable
    r = subprocess.run([str(RUN), "--quick", "--reps", "1", "--json", str(out_json),
                        "--markdown", str(out_md), *args], cwd=REPO, env=env,
                       stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=timeout)
    assert r.returncode == 0, f"exit {r.returncode}\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}"
    return r, json.loads(out_json.read_text()), out_md.read_text()


def rows_by_number(doc: dict) -> dict[int, dict]:
    return {row["row"]: row for row in doc["rows"]}


def test_help_lists_the_flags():
    r = subprocess.run([str(RUN), "--help"], cwd=REPO, capture_output=True, text=True,
                       timeout=30, env=dict(os.environ, PYTHON=sys.executable))
    assert r.returncode == 0, r.stderr
    for flag in ("--reps", "--rows", "--quick", "--json", "--markdown"):
        assert flag in r.stdout


def test_usage_errors_exit_2():
    r = subprocess.run([str(RUN), "--rows", "10"], cwd=REPO, capture_output=True, text=True,
                       timeout=30, env=dict(os.environ, PYTHON=sys.executable))
    assert r.returncode == 2 and "rows are 1-9" in r.stderr


def test_rows_that_run_anywhere(tmp_path):
    r, doc, md = bench(tmp_path, "--rows", "1,4,5,7", timeout=600)
    rows = rows_by_number(doc)
    assert sorted(rows) == [1, 4, 5, 7]
    for n in (1, 4, 5, 7):
        assert rows[n]["status"] == "measured", rows[n]
        for line in rows[n]["lines"]:
            assert line["app"] and line["app_median"] is not None, line
            if line["baseline"]:  # both sides measured, one sample each
                assert line["base"] and line["base_median"] is not None, line
    # Row 4: every screen, both terminals, both sizes, against the targets.
    assert len(rows[4]["lines"]) == 24
    assert all(line["goal"] for line in rows[4]["lines"])
    assert [line["measure"] for line in rows[7]["lines"]] == [
        "Burst = slow: first-run set-up", "Burst = slow: steps"]
    startup = rows[1]["lines"][0]
    assert 0 < startup["app_median"] < 30 and 0 < startup["base_median"] < 30
    assert rows[1]["lines"][1]["app_median"] > 10  # MB: a Python process with Textual
    first_frame = rows[4]["lines"][0]
    assert first_frame["app_median"] > 1000 and first_frame["base_median"] > 100  # bytes
    assert "rosnet-tui" in r.stdout and "Baseline" in r.stdout  # the table was printed
    assert md.count("\n| ") >= 30 and "| # | Measure" in md


@pytest.mark.lab
def test_lab_rows(tmp_path):
    ok, why = lab_available()
    if not ok:
        pytest.skip(f"lab rows of the bench: {why}")
    if shutil.which("roscore") is None:   # the one reason the bench may skip these rows
        pytest.skip("lab rows of the bench: roscore is not installed (Debian package ros-core)")
    _r, doc, md = bench(tmp_path, "--rows", "2,3,6", timeout=600)   # a smoke test, not a timing: ~40 s quiet, 60+ s loaded
    rows = rows_by_number(doc)
    assert sorted(rows) == [2, 3, 6]
    # the lab and roscore are here: a row marked "skipped" (the lab or a module of ours that
    # cannot be imported, a lab that cannot be built) is a failure, not a pass
    assert rows[2]["status"] == "measured", rows[2]
    full = rows[2]["lines"][0]
    assert full["status"] == "measured", full["note"]  # both sides said "all good"
    assert full["app_median"] > 0 and full["base_median"] > 0
    assert rows[3]["status"] == "measured", rows[3]
    assert len(rows[3]["lines"]) == 5  # four scenarios and the worst margin
    # tests/sync_support/bench.py is in the tree: "not available yet" means it broke
    assert rows[6]["status"] == "measured", rows[6]
    assert "Bad news" in md or "every verdict" in md
