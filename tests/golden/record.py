"""Record the advisor's golden inputs and outputs (run by hand, not by the test suite).

    python -m tests.golden.record            # re-record inputs from the tests, then outputs
    python -m tests.golden.record --outputs  # only recompute outputs from the stored inputs

Recording runs the advisor tests (TEST_FILES) and tests/test_report.py with ``advise()`` wrapped: every
call (also in the ``rosnet-tui report`` subprocesses, through a sitecustomize on PYTHONPATH)
appends its (results, settings, strict) and what it returned to a JSON-lines file. Each distinct
input becomes one case of tests/golden/advise_inputs.json; the round trip through JSON is
verified (the replayed findings must equal the ones the live call returned). Outputs are the
rule ids (--ids), the troubleshooting document (--markdown) and every case's findings.

Re-record only on purpose: the golden files are what proves a refactoring changed nothing.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
INPUTS = HERE / "advise_inputs.json"
FINDINGS = HERE / "advise_findings.json"
IDS = HERE / "rule_ids.txt"
MARKDOWN = HERE / "TROUBLESHOOTING.md"
LOG_ENV = "ROSNET_TUI_GOLDEN_LOG"
# Every advisor test that calls advise() (the rules' cases run in test_advisor_rules.py).
TEST_FILES = ("tests/test_advisor_rules.py", "tests/test_advisor_isp.py",
              "tests/test_advisor_router.py", "tests/test_advisor_linux.py",
              "tests/test_advisor_ros.py", "tests/test_report.py", "tests/test_advisor_ros2.py")


def install() -> None:
    """Wrap rosnet_tui.core.advisor.advise so each call is logged (when LOG_ENV is set)."""
    log = os.environ.get(LOG_ENV)
    if not log:
        return
    from rosnet_tui.core import advisor
    from tests.golden import codec

    real = advisor.advise
    if getattr(real, "_golden", False):
        return

    def advise(results, settings, *, strict=False):
        if not isinstance(results, dict):
            results = list(results)      # an iterator would be consumed by the real call
        entry = {"test": os.environ.get("PYTEST_CURRENT_TEST", "subprocess").split(" ")[0],
                 "strict": strict, "results": codec.results_to_json(results),
                 "settings": codec.settings_to_json(settings)}
        line = json.dumps(entry)         # now: the tests mutate their results afterwards
        out = codec.outcome(real, results, settings, strict)
        with open(log, "a", encoding="utf-8") as fh:
            fh.write(json.dumps({"input": json.loads(line), "outcome": out}) + "\n")
        return real(results, settings, strict=strict)    # (raises again if it raised)

    advise._golden = True
    advisor.advise = advise


# Loaded as a pytest plugin (-p tests.golden.record): patch before the test modules import it.
install()


def record_inputs() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "calls.jsonl"
        site = Path(tmp) / "site"
        site.mkdir()
        (site / "sitecustomize.py").write_text(
            "import tests.golden.record  # noqa: F401  (installs the advise() recorder)\n")
        env = dict(os.environ)
        env[LOG_ENV] = str(log)
        env["PYTHONPATH"] = os.pathsep.join([str(site), str(ROOT), env.get("PYTHONPATH", "")])
        subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "tests.golden.record",
                        *TEST_FILES], cwd=ROOT, env=env, check=True)
        calls = [json.loads(ln) for ln in log.read_text(encoding="utf-8").splitlines()]
    cases: list[dict] = []
    outcomes: dict[str, dict] = {}
    seen: dict[str, str] = {}
    counts: dict[str, int] = {}
    for c in calls:
        inp = c["input"]
        key = json.dumps([inp["strict"], inp["results"], inp["settings"]], sort_keys=True)
        if key in seen:
            continue
        test = inp["test"]
        counts[test] = counts.get(test, 0) + 1
        name = f"{test}#{counts[test]}"
        seen[key] = name
        cases.append({"case": name, "strict": inp["strict"], "results": inp["results"],
                      "settings": inp["settings"]})
        outcomes[name] = c["outcome"]
    from tests.golden import codec

    INPUTS.write_text(codec.dumps_cases(cases), encoding="utf-8")
    print(f"{len(calls)} advise() calls, {len(cases)} distinct inputs -> {INPUTS}")
    # The round trip must be exact: the replayed outcome is the one the live call had.
    from rosnet_tui.core.advisor import advise

    for case in cases:
        got = replay(advise, case)
        if got != outcomes[case["case"]]:
            raise SystemExit(f"{case['case']}: the replay differs from the recorded call")


def replay(advise, case: dict) -> dict:
    from tests.golden import codec

    return codec.outcome(advise, codec.results_from_json(case["results"]),
                         codec.settings_from_json(case["settings"]), case["strict"])


def outputs() -> dict[Path, str]:
    """The golden files' contents, computed by the code as it is now."""
    from rosnet_tui.core.advisor import advise
    from tests.golden import codec

    cases = json.loads(INPUTS.read_text(encoding="utf-8"))["cases"]
    findings = [{"case": c["case"], **replay(advise, c)} for c in cases]

    def cli(flag: str) -> str:
        return subprocess.run([sys.executable, "-m", "rosnet_tui.core.advisor", flag],
                              capture_output=True, text=True, cwd=ROOT, timeout=60,
                              check=True).stdout

    return {FINDINGS: codec.dumps(findings), IDS: cli("--ids"), MARKDOWN: cli("--markdown")}


def main(argv: list[str]) -> int:
    if "--outputs" not in argv:
        record_inputs()
    for path, text in outputs().items():
        path.write_text(text, encoding="utf-8")
        print(f"wrote {path.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
