"""The help screen: every key on one page at 80x24, and how the four steps fit together."""

from __future__ import annotations

from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import VerticalScroll
from textual.screen import ModalScreen
from textual.widgets import Static

from rosnet_tui.ui.widgets import KeyBar

HELP = """\
rosnet-tui: keys                                Esc, q or ? closes this help

Four steps, on every component (robot and laptops) and its own modem: 1 ISP
(is forwarding allowed, the public IP), 2 Router/modem (forward the ports),
3 Linux (names in /etc/hosts), 4 ROS (Zenoh routers, or ROS 1's master URI).
Each step shows what to expect, what to configure here, and live checks.

 1-4    go to a step                 r       run the step's checks
 n / b  next / back                  R       re-run the highlighted check
 s      set-up: this machine, peers  c       stop running checks (any step)
 a      the advisor: what to do      e/Enter evidence and advice of a check
 w      write the configuration      g       go to the step of the cause
 u      undo the last write/forward  z       zoom the focused pane, or back
 m      modem forwards it (Router)   k       review an unknown SSH host key
 Tab    next pane                    Ctrl+L  draw the whole screen again
 q      quit (Ctrl+Q anywhere)       Ctrl+Z  suspend (fg brings it back)
 ?      this help

Previews (w u m k): y goes ahead; Esc or q backs out and skips the rest.
Set-up: Tab and Shift+Tab move, Ctrl+N adds a peer, Ctrl+S saves, Esc or F10
goes back. Keys typed ahead on a slow link are applied in the order typed.
Results, findings and an unsaved set-up survive a dropped session.
Headless, the same checks: rosnet-tui check --json
"""


class HelpScreen(ModalScreen[None]):
    BINDINGS = [Binding("escape,q,question_mark,f10", "close", "Close", key_display="Esc/q/?")]

    def compose(self) -> ComposeResult:
        with VerticalScroll(id="help-body"):
            yield Static(HELP.rstrip("\n"), id="help-text", markup=False)
        yield KeyBar()

    def action_close(self) -> None:
        self.dismiss(None)
