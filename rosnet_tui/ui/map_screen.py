"""The Router step's offer: let the modem forward this component's port itself (m).

The core finds the modem and says what it would ask (rosnet_tui.core.upnp.forwards.preview);
this screen shows it - protocol, external port, internal address and port, lease - and asks.
Nothing is asked of the modem before Map is pressed; `u` (undo) removes the forward again.
"""

from __future__ import annotations

from pathlib import Path

from rich.text import Text
from textual import on, work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical, VerticalScroll
from textual.widgets import Button, Static

from rosnet_tui.core.config.settings_model import Settings
from rosnet_tui.core.upnp import forwards as fw
from rosnet_tui.core.upnp.wire import ModemError
from rosnet_tui.ui.dialog import SCROLL_BINDINGS, ConfirmDialog
from rosnet_tui.ui.widgets import KeyBar


class MapScreen(ConfirmDialog[bool]):
    """Preview -> consent -> map. Dismisses True when the modem made (or renewed) a forward."""

    BINDINGS = [Binding("escape,q,f10", "cancel", "Cancel", key_display="Esc/q"),
                Binding("y", "map", "Map"), *SCROLL_BINDINGS]
    CONFIRM_ACTIONS = ("map",)

    def __init__(self, settings: Settings, state_dir: Path, timeout: float = 3.0,
                 **kwargs) -> None:
        super().__init__(**kwargs)
        self.settings = settings
        self.state_dir = state_dir
        self.timeout = timeout
        self.plan: fw.MapPreview | None = None

    def compose(self) -> ComposeResult:
        with Vertical(id="write-box"):
            yield Static("Let the modem forward the port itself", id="write-title")
            with VerticalScroll(id="write-diff-box"):
                yield Static("Asking the modem (UPnP IGD, PCP, NAT-PMP)...", id="write-diff",
                             markup=False)
            yield Static("", id="write-status", markup=False)
            with Horizontal(id="write-buttons"):
                yield Button(Text("[Map]"), id="write-apply", variant="primary", compact=True,
                             disabled=True)
                yield Button(Text("[Cancel]"), id="write-cancel", compact=True)
        yield KeyBar()

    def on_mount(self) -> None:
        self._look()

    @work(exclusive=True, exit_on_error=False, thread=True)
    def _look(self) -> None:
        plan = fw.preview(self.settings, state_dir=self.state_dir, timeout=self.timeout)
        self.app.call_from_thread(self.show_plan, plan)

    def show_plan(self, plan: fw.MapPreview) -> None:
        """Show what would be asked of the modem; Map (and `y`) only when something can be."""
        self.plan = plan
        text = "\n".join(plan.lines) or plan.blocked
        if plan.blocked and plan.lines:
            text += "\n\n" + plan.blocked
        self.query_one("#write-diff", Static).update(text)
        notes = [f"warning: {w}" for w in plan.warnings]
        if not plan.blocked:
            notes.append("Map asks the modem now; `u` (or `rosnet-tui undo`) removes it again. "
                         "The sync service renews the lease.")
        self.query_one("#write-status", Static).update("\n".join(notes))
        self.set_confirm(not plan.blocked)

    @on(Button.Pressed, "#write-cancel")
    def action_cancel(self) -> None:
        self.dismiss(False)

    @on(Button.Pressed, "#write-apply")
    def action_map(self) -> None:
        if self.plan is None or self.plan.blocked or self.plan.modem is None:
            return
        self.set_confirm(False)   # asked once
        self._do_map()

    @work(exclusive=True, exit_on_error=False, thread=True)
    def _do_map(self) -> None:
        plan = self.plan
        assert plan is not None and plan.modem is not None
        try:
            result = fw.map_forwards(self.settings, plan.modem, plan.need.forwards,
                                     state_dir=self.state_dir, via=plan.via,
                                     timeout=max(self.timeout * 2, 5.0))
        except fw.MapRefused as exc:
            told = exc.told()
            self.app.call_from_thread(self._refused, told[:1].upper() + told[1:])
            return
        except (ModemError, OSError) as exc:
            self.app.call_from_thread(self._refused, f"The modem did not give a usable answer, "
                                                     f"nothing was changed: {exc}")
            return
        ports = ", ".join(f"TCP {m['port']}" for m in result.made) or \
            ", ".join(f"TCP {p}" for p in result.refreshed)
        self.app.call_from_thread(self._done, f"The modem forwards {ports} to this machine now.")

    def _refused(self, words: str) -> None:
        self.query_one("#write-status", Static).update(words)
        self.notify(words, severity="error", timeout=12)

    def _done(self, words: str) -> None:
        self.notify(words, timeout=6)
        self.dismiss(True)
