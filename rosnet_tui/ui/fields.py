"""Text fields of the set-up screen (loaded with it, not at start-up)."""

from __future__ import annotations

from textual import events
from textual.reactive import reactive
from textual.widgets import Input


class OrderedInput(Input):
    """An Input whose editing keys (backspace, arrows...) keep their place among typed characters.

    Textual runs an Input's bound keys as actions after the event has travelled, while typed
    characters are inserted at once, so in a burst of input (a mobile SSH link delivers keys in
    bursts) "abc<backspace>d" can come out as "abd" missing the wrong letter. Running the
    widget's own bindings in line keeps the order (Textual issue 6605).
    """

    cursor_blink = reactive(False, init=False)  # a blink costs bytes twice a second, for ever

    async def _on_key(self, event: events.Key) -> None:
        if not event.is_printable:
            for binding in self._merged_bindings.key_to_bindings.get(event.key, []):
                if not binding.priority:
                    event.stop()
                    event.prevent_default()
                    await self.run_action(binding.action)
                    return
        await super()._on_key(event)
