"""Ask before trusting a peer's SSH host key: show its fingerprint and how to verify it."""

from __future__ import annotations

from rich.text import Text
from textual import on
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.widgets import Button, Static

from rosnet_tui.core.ssh.known_hosts import verify_commands
from rosnet_tui.ui.dialog import ConfirmDialog
from rosnet_tui.ui.widgets import KeyBar


class TrustKeyScreen(ConfirmDialog[bool]):
    """Dismisses True only when the user chose to trust the key."""

    # No key trusts a key: a `y` typed ahead over a slow link, meant for the next write preview,
    # must never accept an unknown host key. Trusting takes Tab to the button and Enter.
    BINDINGS = [Binding("escape,q,f10", "refuse", "Do not trust", key_display="Esc/q")]
    CONFIRM_BUTTON, SAFE_BUTTON = "#trust-yes", "#trust-no"

    def __init__(self, name: str, port: int, host_key: str, fingerprint: str, address: str,
                 user: str = "", **kwargs) -> None:
        super().__init__(**kwargs)
        self.peer_name, self.port, self.host_key = name, port, host_key
        self.fingerprint, self.address, self.user = fingerprint, address, user

    def compose(self) -> ComposeResult:
        ktype = self.host_key.split(" ", 1)[0]
        with Vertical(id="write-box"):
            yield Static(f"Trust the SSH host key of {self.peer_name}?", id="write-title")
            yield Static(
                f"{self.peer_name} ({self.address or 'address unknown'}) presented a {ktype} key "
                "that this machine has never seen:\n\n"
                f"    {self.fingerprint}\n\n"
                "Compare it with the key on that machine, over a channel you trust (its screen, "
                "or a colleague reading it to you). If they differ, someone may be in between: "
                "do not trust it.\n\n"
                + verify_commands(self.peer_name, self.port, ktype, self.user),
                id="trust-text", markup=False)
            with Horizontal(id="write-buttons"):
                yield Button(Text("[They match: trust]"), id="trust-yes", variant="warning", compact=True)
                yield Button(Text("[Do not trust]"), id="trust-no", variant="primary", compact=True)
        yield KeyBar()

    @on(Button.Pressed, "#trust-yes")
    def action_trust(self) -> None:
        self.dismiss(True)

    @on(Button.Pressed, "#trust-no")
    def action_refuse(self) -> None:
        self.dismiss(False)
