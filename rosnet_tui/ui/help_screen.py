"""The help screen: keys, and how the four steps fit together."""

from __future__ import annotations

from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import VerticalScroll
from textual.screen import ModalScreen
from textual.widgets import Markdown

HELP = """\
# rosnet-tui

Four steps, done on **every** component (robot and laptops) and its own modem:
**1 ISP** (is forwarding allowed, what is my public IP), **2 Router/modem** (forward the ports),
**3 Linux** (names in `/etc/hosts`), **4 ROS** (`ROS_MASTER_URI`). Each step shows what to expect,
what to configure on *this* component, and live checks.

| key | does |
|---|---|
| `1`-`4` | go to a step |
| `n` / `b` | next / back |
| `r` | run the step's checks |
| `R` | re-run the highlighted check |
| `c` | cancel running checks |
| `e` or `Enter` | show / hide the evidence and advice of the highlighted check |
| `a` | the advisor: what the results mean, what to do |
| `g` | go back to the step where the highlighted check's cause is |
| `w` | write the configuration (Linux: hosts set; ROS: `ROS_MASTER_URI`) |
| `u` | undo the last write (or the last forward the modem made) |
| `m` | let the modem forward the port itself (Router step: UPnP IGD, PCP, NAT-PMP) |
| `k` | review a peer's unknown SSH host key (Linux step) |
| `z` | zoom the focused pane (again to restore) |
| `Tab` | move between panes |
| `s` | set-up: this component and its peers |
| `q` | quit (`Ctrl+Q` anywhere) |

Headless, the same checks: `rosnet-tui check --json`.

Press `Esc` to close.
"""


class HelpScreen(ModalScreen[None]):
    BINDINGS = [Binding("escape,question_mark,q", "close", "Close")]

    def compose(self) -> ComposeResult:
        with VerticalScroll(id="help-body"):
            yield Markdown(HELP)

    def action_close(self) -> None:
        self.dismiss(None)
