"""Messages the screens send up to the app (they never call it)."""

from __future__ import annotations

from textual.message import Message


class Navigate(Message):
    """Go to another step of the procedure (e.g. the advisor's "go to the cause")."""

    def __init__(self, step_id: str) -> None:
        self.step_id = step_id
        super().__init__()


class SettingsSaved(Message):
    """The settings were saved: screens that show them re-render."""
