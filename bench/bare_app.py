"""The baseline: a bare Textual app that shows one static line (the floor for any Textual program).

    python -m bench.bare_app [N_UPDATES]

Keys mirror what the benchmark does to rosnet-tui: "1".."4" change the line (a "step change"),
"r" changes it N_UPDATES times, 50 ms apart (one update per streamed check result), "q" quits.
"""

from __future__ import annotations

import sys

from textual.app import App, ComposeResult
from textual.binding import Binding
from textual.widgets import Static

LINE = "bench: a bare Textual app"


class BareApp(App[int]):
    BINDINGS = [Binding(k, f"show({k})", show=False) for k in "1234"] + [
        Binding("r", "stream", show=False),
        Binding("q", "quit", show=False),
    ]
    ENABLE_COMMAND_PALETTE = False

    def __init__(self, updates: int = 4) -> None:
        super().__init__()
        self.updates = updates

    def compose(self) -> ComposeResult:
        yield Static(LINE, id="line", markup=False)

    def action_show(self, n: int) -> None:
        self.query_one("#line", Static).update(f"bare step {n}")

    def action_stream(self) -> None:
        line = self.query_one("#line", Static)
        line.update("bare results: running")
        for i in range(1, self.updates + 1):
            self.set_timer(0.05 * i, lambda i=i: line.update(f"bare result {i}/{self.updates}"))


def main() -> int:
    updates = int(sys.argv[1]) if len(sys.argv) > 1 else 4
    return BareApp(updates).run() or 0


if __name__ == "__main__":
    raise SystemExit(main())
