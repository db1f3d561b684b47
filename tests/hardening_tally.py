"""The adversarial tally of the hardening tests (issue 15): how many bad inputs or faults each area
tried and how many held. A test that finds one that did not hold fails anyway; the tally gives the
figures. With ``ROSNET_TALLY=FILE`` set, each count is appended to FILE as one JSON line;
``python -m tests.hardening_tally FILE`` sums them per area.
"""

from __future__ import annotations

import json
import os
import sys
from collections import defaultdict


def tally(area: str, tried: int, held: int, what: str = "") -> None:
    path = os.environ.get("ROSNET_TALLY")
    if not path:
        return
    with open(path, "a", encoding="utf-8") as f:
        f.write(json.dumps({"area": area, "tried": tried, "held": held, "what": what}) + "\n")


def summary(path: str) -> dict[str, tuple[int, int]]:
    out: dict[str, list[int]] = defaultdict(lambda: [0, 0])
    with open(path, encoding="utf-8") as f:
        for line in f:
            d = json.loads(line)
            out[d["area"]][0] += d["tried"]
            out[d["area"]][1] += d["held"]
    return {k: (v[0], v[1]) for k, v in sorted(out.items())}


if __name__ == "__main__":
    total = [0, 0]
    for area, (tried, held) in summary(sys.argv[1]).items():
        print(f"{area:<22} tried {tried:>6}  held {held:>6}")
        total[0] += tried
        total[1] += held
    print(f"{'all':<22} tried {total[0]:>6}  held {total[1]:>6}")
