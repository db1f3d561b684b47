"""Text fields of the set-up screen (loaded with it, not at start-up)."""

from __future__ import annotations

from textual import events
from textual.reactive import reactive
from textual.widgets import Input

from rosnet_tui.ui.textual_compat import KeyFirst, own_bindings


class OrderedInput(KeyFirst, Input):
    """An Input whose editing keys (backspace, arrows...) keep their place among typed characters.

    Textual runs an Input's bound keys as actions after the event has travelled, while typed
    characters are inserted at once, so in a burst of input (a mobile SSH link delivers keys in
    bursts) "abc<backspace>d" can come out as "abd" missing the wrong letter. Running the
    widget's own bindings in line keeps the order (Textual issue 6605).
    """

    cursor_blink = reactive(False, init=False)  # a blink costs bytes twice a second, for ever

    async def key_first(self, event: events.Key) -> bool:
        if not event.is_printable:
            for binding in own_bindings(self, event.key):
                if not binding.priority:
                    event.stop()
                    event.prevent_default()
                    await self.run_action(binding.action)
                    return True
        return False
