"""Golden outputs of the advisor: what it says must not change when its code is moved around.

tests/golden/ holds, recorded with ``python -m tests.golden.record`` before the advisor became a
package: the rule ids (``python -m rosnet_tui.core.advisor --ids``), the troubleshooting
document (``--markdown``) and ``advise()``'s findings, every field, over every (results,
settings) pair the advisor tests and tests/test_report.py fed it (the case names keep the file
they came from then: tests/test_advisor.py, since split per step). Each test recomputes one of
them with the code as it is and compares byte for byte.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from tests.golden import codec, record

ROOT = Path(__file__).resolve().parents[1]


def _cli(flag: str) -> str:
    return subprocess.run([sys.executable, "-m", "rosnet_tui.core.advisor", flag],
                          capture_output=True, text=True, cwd=ROOT, timeout=60,
                          check=True).stdout


def test_rule_ids_unchanged():
    assert _cli("--ids") == record.IDS.read_text(encoding="utf-8")


def test_troubleshooting_document_unchanged():
    golden = record.MARKDOWN.read_text(encoding="utf-8")
    assert _cli("--markdown") == golden
    assert (ROOT / "docs" / "TROUBLESHOOTING.md").read_text(encoding="utf-8") == golden


def test_findings_unchanged():
    from rosnet_tui.core.advisor import advise

    cases = json.loads(record.INPUTS.read_text(encoding="utf-8"))["cases"]
    assert len(cases) >= 100
    golden = json.loads(record.FINDINGS.read_text(encoding="utf-8"))
    got = [{"case": c["case"], **record.replay(advise, c)} for c in cases]
    for want, have in zip(golden, got, strict=True):     # one case at a time: a readable diff
        assert have == want, want["case"]
    assert codec.dumps(got) == record.FINDINGS.read_text(encoding="utf-8")

