"""What every dialog that asks before acting has in common (write, undo, map, trust a key).

`y` does what its confirm button says and Esc (q, F10) backs out; it opens on its safe button,
so an Enter typed ahead never acts; while the confirm button is disabled its key is not offered
(nor taken); the arrow and page keys scroll the preview whichever button has the focus.
"""

from __future__ import annotations

from typing import TypeVar

from rich.text import Text
from textual.binding import Binding
from textual.css.query import NoMatches
from textual.screen import ModalScreen
from textual.widgets import Button

R = TypeVar("R")

SCROLL_BINDINGS = [Binding(key, f"scroll_preview('{how}')", show=False)
                   for key, how in (("up", "scroll_up"), ("down", "scroll_down"),
                                    ("pageup", "page_up"), ("pagedown", "page_down"),
                                    ("home", "scroll_home"), ("end", "scroll_end"))]


class ConfirmDialog(ModalScreen[R]):
    """A modal that acts only on `y` or its confirm button. Subclasses name the buttons and the
    confirm actions (bound to `y` in their BINDINGS)."""

    CONFIRM_BUTTON = "#write-apply"
    SAFE_BUTTON = "#write-cancel"
    PREVIEW_BOX = "#write-diff-box"
    # The actions `y` may run; each is offered only while the confirm button is enabled.
    CONFIRM_ACTIONS: tuple[str, ...] = ()

    def on_mount(self) -> None:
        self.query_one(self.SAFE_BUTTON, Button).focus()

    def confirm_enabled(self) -> bool:
        try:
            return not self.query_one(self.CONFIRM_BUTTON, Button).disabled
        except NoMatches:
            return False

    def set_confirm(self, enabled: bool, label: str | None = None) -> None:
        """Enable or disable the confirm button (and so its key), and relabel it."""
        button = self.query_one(self.CONFIRM_BUTTON, Button)
        if label is not None and str(button.label) != label:
            button.label = Text(label)   # Text: "[Apply]" is not markup
        if button.disabled == enabled:
            button.disabled = not enabled
        self.refresh_bindings()

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        if action in self.CONFIRM_ACTIONS:
            return self.confirm_enabled()
        return True

    def action_scroll_preview(self, how: str) -> None:
        try:
            box = self.query_one(self.PREVIEW_BOX)
        except NoMatches:
            return
        getattr(box, f"action_{how}")()
