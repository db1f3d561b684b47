"""JSON forms of the advisor's inputs (check results, settings) and outputs (findings).

Used by the recorder (tests/golden/record.py) that captured every (results, settings) pair the
advisor tests feed ``advise()``, and by tests/test_advisor_golden.py, which replays them.
The forms are exact: a result or settings object read back is equal to the one written.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Iterable, Mapping
from typing import Any

from rosnet_tui.core.config.settings_model import (
    CheckSettings,
    FirewallSettings,
    Peer,
    ProbeSettings,
    RelaySettings,
    RosbridgeSettings,
    RosSettings,
    Settings,
    SyncSettings,
    ThisComponent,
)
from rosnet_tui.core.results import CheckResult, Status


def result_to_json(r: CheckResult) -> dict[str, Any]:
    status = r.status.value if isinstance(r.status, Status) else str(r.status)
    return {"id": r.id, "step": r.step, "status": status, "summary": r.summary,
            "evidence": list(r.evidence), "duration_s": r.duration_s, "timeout_s": r.timeout_s,
            "data": r.data}


def result_from_json(d: Mapping[str, Any]) -> CheckResult:
    return CheckResult(d["id"], d["step"], Status(d["status"]), d["summary"],
                       list(d["evidence"]), d["duration_s"], d["timeout_s"], d["data"])


def results_to_json(results: Mapping[str, CheckResult] | Iterable[CheckResult]
                    ) -> list[list[Any]]:
    """[[key, result], ...] in the order given (a list of results is keyed by their ids)."""
    pairs = results.items() if isinstance(results, Mapping) else ((r.id, r) for r in results)
    return [[k, result_to_json(r)] for k, r in pairs]


def results_from_json(pairs: list[list[Any]]) -> dict[str, CheckResult]:
    out: dict[str, CheckResult] = {}
    for k, r in pairs:
        out[k] = result_from_json(r)
    return out


def settings_to_json(s: Settings) -> dict[str, Any]:
    d = dataclasses.asdict(s)
    d["has_sync"] = s.has_sync
    return d


def settings_from_json(d: Mapping[str, Any]) -> Settings:
    """The settings of *d*; tables a case recorded before they existed ([rosbridge],
    [firewall], [relay]) are at their defaults, as they were then."""
    return Settings(this=ThisComponent(**d["this"]), peers=[Peer(**p) for p in d["peers"]],
                    ros=RosSettings(**d["ros"]), probe=ProbeSettings(**d["probe"]),
                    checks=CheckSettings(**d["checks"]), sync=SyncSettings(**d["sync"]),
                    rosbridge=RosbridgeSettings(**d.get("rosbridge", {})),
                    firewall=FirewallSettings(**d.get("firewall", {})),
                    relay=RelaySettings(**d.get("relay", {})), has_sync=d["has_sync"])


def dumps(obj: Any) -> str:
    """The one JSON layout of the golden files (stable, diff-friendly)."""
    return json.dumps(obj, indent=1, ensure_ascii=False) + "\n"


def dumps_cases(cases: list[dict[str, Any]]) -> str:
    """The inputs file: one case a line (compact; the cases are large and alike)."""
    lines = [json.dumps(c, ensure_ascii=False, separators=(",", ":")) for c in cases]
    return '{"cases": [\n' + ",\n".join(lines) + "\n]}\n"


def outcome(advise, results, settings, strict: bool) -> dict[str, Any]:
    """What ``advise()`` made of one input: its findings' every field, or the error it raised."""
    try:
        findings = advise(results, settings, strict=strict)
    except Exception as exc:   # strict calls over malformed data raise; record which error
        return {"raises": type(exc).__name__}
    return {"findings": [f.to_dict() for f in findings]}
