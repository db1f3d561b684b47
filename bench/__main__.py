"""Entry point: ``bench/run`` (or ``python -m bench`` from the repository root)."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # `tests.lab` and `rosnet_tui` import from the repository root
    sys.path.insert(0, str(REPO))

from bench.model import Options  # noqa: E402

ALL_ROWS = (1, 2, 3, 4, 5, 6, 7, 8, 9)
ROW_NAMES = {1: "start-up time and peak RSS", 2: "full verification on the lab",
             3: "bad news fast (master down, no forwarding, peer unplugged)",
             4: "terminal traffic (bytes per screen, both terminals, both sizes)",
             5: "responsiveness while checks run", 6: "address sync (from the sync service)",
             7: "a burst of keys equals the same keys typed slowly",
             8: "the fleet grows (1 to 8 members) and the sync fan-out",
             9: "a dead link seen in seconds, and data again after it returns (ROS 2)"}
DEFAULT_JSON = REPO / "bench" / "results" / "latest.json"


def parse_rows(text: str) -> list[int]:
    try:
        rows = sorted({int(x) for x in text.replace(" ", "").split(",") if x})
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a list of row numbers like 1,4,5") from None
    bad = [r for r in rows if r not in ALL_ROWS]
    if bad or not rows:
        raise argparse.ArgumentTypeError(f"rows are {ALL_ROWS[0]}-{ALL_ROWS[-1]} (got {text!r})")
    return rows


def positive_int(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a whole number") from None
    if not 1 <= n <= 100:
        raise argparse.ArgumentTypeError("must be between 1 and 100")
    return n


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="bench/run",
        description="Measure rosnet-tui against baselines measured in the same run and print a "
                    "table (median of the repetitions). Rows: "
                    + "; ".join(f"{k} {v}" for k, v in ROW_NAMES.items())
                    + ". Rows 1, 4, 5, 7 run anywhere (loopback only); rows 2, 3, 6, 8, 9 need root and "
                      "network namespaces (the network lab of tests/lab) and are skipped, with "
                      "the reason, otherwise.",
        epilog="Exit code 0 when every selected row ran or was skipped with a reason (goals not "
               "met are results, not errors); 1 when a row failed to measure; 2 usage error.")
    p.add_argument("--reps", type=positive_int, default=None, metavar="N",
                   help="repetitions of each measurement (default 5, or 1 with --quick)")
    p.add_argument("--rows", type=parse_rows, default=list(ALL_ROWS), metavar="1,2,...",
                   help="which rows to run (default: all)")
    p.add_argument("--quick", action="store_true",
                   help="a fast smoke run: 1 repetition unless --reps, 0.3 s quiet, 1 s idle, 4 key "
                        "presses, standard tools capped at 2 s instead of 60 s, lab checks "
                        "at --timeout 1 in row 3, the folder store only in row 6")
    p.add_argument("--json", type=Path, default=DEFAULT_JSON, metavar="FILE",
                   help=f"write the results as JSON here (default {DEFAULT_JSON.relative_to(REPO)})")
    p.add_argument("--markdown", type=Path, default=None, metavar="FILE",
                   help="also write the table as Markdown (for docs/PERFORMANCE.md)")
    return p


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = build_parser().parse_args(argv)
    opts = Options.make(args.reps, args.quick)
    t_start = time.monotonic()

    def log(msg: str) -> None:  # progress, on stderr
        print(f"[bench {time.monotonic() - t_start:6.1f} s] {msg}", file=sys.stderr, flush=True)

    from bench.local_rows import run_local_rows
    from bench.report import markdown, metadata, print_table, write_json
    from bench.rows_lab import run_lab_rows

    log(f"rows {','.join(map(str, args.rows))}, {opts.reps} repetition(s)"
        + (", quick" if opts.quick else ""))
    results = []
    try:
        results += run_local_rows(args.rows, opts, log)
        results += run_lab_rows(args.rows, opts, log)
        if 8 in args.rows:
            from bench.fleet_row import run_fleet_row

            results += run_fleet_row(opts, log)
    except KeyboardInterrupt:
        print("bench: interrupted (everything it started has been stopped)", file=sys.stderr)
        return 130
    meta = metadata(opts, argv)
    meta["seconds"] = round(time.monotonic() - t_start, 1)
    print_table(results, opts, meta)
    write_json(args.json, results, meta)
    print(f"JSON: {args.json}")
    if args.markdown is not None:
        args.markdown.parent.mkdir(parents=True, exist_ok=True)
        args.markdown.write_text(markdown(results, opts, meta), encoding="utf-8")
        print(f"Markdown: {args.markdown}")
    failed = [r for r in results if r.status == "error" or any(ln.status == "error"
                                                                for ln in r.lines)]
    for r in failed:
        print(f"bench: row {r.row} could not be measured: "
              f"{r.reason or '; '.join(ln.note for ln in r.lines if ln.status == 'error')}",
              file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
