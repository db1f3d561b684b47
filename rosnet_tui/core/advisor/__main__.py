"""``python -m rosnet_tui.core.advisor [--markdown | --ids]``: print the advisor's rules."""

from __future__ import annotations

import sys

from rosnet_tui.core.advisor.docs import render_rules_markdown
from rosnet_tui.core.advisor.engine import all_rules


def main(argv: list[str] | None = None) -> int:
    import argparse

    p = argparse.ArgumentParser(prog="python -m rosnet_tui.core.advisor",
                                description="Print the advisor's rules.")
    p.add_argument("--markdown", action="store_true",
                   help="print docs/TROUBLESHOOTING.md (the default)")
    p.add_argument("--ids", action="store_true", help="print the rule ids, one a line")
    args = p.parse_args(argv)
    if args.ids:
        sys.stdout.write("".join(f"{r.id}\n" for r in all_rules()))
    else:
        sys.stdout.write(render_rules_markdown())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
