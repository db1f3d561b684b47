"""Keys in the order they were typed, whatever the link does to their timing.

On a laggy SSH link several keys arrive in one read. Textual hands each key to the focused widget
at once, but a key bound to an action (Tab, Ctrl+N, Ctrl+S, a digit on a step screen...) runs its
action only after the event has travelled back up to the app, and a new screen or widget is
mounted later still: the keys behind it land in the wrong field, or on the wrong screen.

:class:`OrderedKeys` (a mixin for the App) queues the keys of a burst and lets the next one go only
when the app is idle again: every message queue of the app and of the screen's widgets empty and
waited on, the screen mounted and laid out, nothing waiting for the next refresh. That is exactly
the state in which a slowly typed key arrives, so a burst has the effect of the same keys typed
slowly. (The layout is done by a timer, not a message: a key let go before it, on a loaded machine,
met fields just shown with no place yet, and Tab skipped them.)

It also reads an unbound Alt+key as what it almost always is on a slow link: Escape followed at
once by the key (the terminal cannot tell them apart).
"""

from __future__ import annotations

import asyncio
import time
from collections import deque

from textual import events

from rosnet_tui.ui import textual_compat as tc

# At most this long for the app to settle after a key before the next goes anyway: a key is never
# held for ever, even if some widget keeps its queue busy.
SETTLE_LIMIT_S = 2.0
_POLL_S = 0.002


def split_alt(event: events.Key) -> list[events.Key]:
    """Escape then the key, for an ``alt+`` key event (the caller decides whether it is bound)."""
    char = event.character
    if not event.key.startswith("alt+") or not char or len(char) != 1 or not char.isprintable():
        return [event]
    key = char if char.isalnum() else tc.character_to_key(char)
    return [events.Key("escape", "\x1b"), events.Key(key, char)]


# After Escape, these begin a longer sequence (CSI, SS3, OSC, DCS...): never split there.
_SEQUENCE_STARTS = "[O]P_^X"


def escape_first_parser():
    """Textual's terminal-input parser, reading Escape followed at once by a character as Escape
    and then that character (imported with the driver).

    Textual maps some Escape+character pairs to other keys, as macOS Option combinations do: Esc 1
    is read as '¡', Esc Tab as Shift+Tab, Esc Backspace as Ctrl+W. On a slow link Escape and the
    next key often arrive together, so help stayed open and the key was lost.
    """
    def key_events(sequence: str, alt: bool, textual):
        if (len(sequence) == 2 and sequence[0] == "\x1b"
                and sequence[1] not in _SEQUENCE_STARTS and sequence[1] != "\x1b"):
            yield events.Key("escape", "\x1b")
            yield from textual(sequence[1], False)
            return
        yield from textual(sequence, alt)

    return tc.input_parser_class(key_events, "EscapeFirstParser")


class OrderedKeys:
    """App mixin: keys take effect one after the other, each once the app has settled."""

    _pending_keys: deque[events.Key]
    _key_task: asyncio.Task | None = None

    def _init_ordered_keys(self) -> None:
        self._pending_keys = deque()
        self._key_task = None

    def keys_pending(self) -> int:
        """Keys received and not yet handed on."""
        return len(self._pending_keys) + (1 if self._key_task and not self._key_task.done()
                                          else 0)

    def keys_at_rest(self) -> bool:
        """No key waiting and the app settled: the state a key typed now would meet (tests wait
        for it instead of a fixed time)."""
        return not self.keys_pending() and self._settled()

    # ------------------------------------------------------------------ idle
    def _settled(self, *, inside_app: bool = False) -> bool:
        """Whether a key typed now would meet the app at rest."""
        app = self  # type: ignore[assignment]
        try:
            screen = app.screen  # type: ignore[attr-defined]
        except Exception:
            return True
        if not screen.is_mounted or tc.callbacks_pending(screen) or tc.layout_pending(screen):
            return False  # laid out: a field just shown has its place in the focus order
        if inside_app:  # the app is handling the key itself: its queue must be empty
            if not tc.queue_empty(app):
                return False
        elif not tc.pump_idle(app):
            return False
        for node in screen.walk_children(with_self=True):
            if not node.is_mounted or not tc.pump_idle(node):
                return False
        return True

    def _is_bound(self, key: str) -> bool:
        try:
            chain = tc.binding_chain(self.screen)  # type: ignore[attr-defined]
        except Exception:
            return False
        return any(key in bindings.key_to_bindings for _node, bindings in chain)

    # ------------------------------------------------------------------ intake
    def _take_key(self, event: events.Key) -> bool:
        """Queue a key from the terminal; True when it may be handled right now (in order, with
        the app at rest), False when it waits its turn."""
        keys = [event]
        if event.key.startswith("alt+") and not self._is_bound(event.key):
            keys = split_alt(event)
        if len(keys) == 1 and not self._pending_keys and (
                self._key_task is None or self._key_task.done()) and self._settled(inside_app=True):
            return True
        self._pending_keys.extend(keys)
        if self._key_task is None or self._key_task.done():
            self._key_task = asyncio.create_task(self._release_keys())
        return False

    async def _release_keys(self) -> None:
        while self._pending_keys:
            deadline = time.monotonic() + SETTLE_LIMIT_S
            while not self._settled() and time.monotonic() < deadline:
                await asyncio.sleep(_POLL_S)
            if not self._pending_keys or tc.app_leaving(self):
                break
            event = self._pending_keys.popleft()
            released = events.Key(event.key, event.character)
            released._rosnet_released = True  # type: ignore[attr-defined]
            self.post_message(released)  # type: ignore[attr-defined]
            await asyncio.sleep(0)  # let it be picked up before settling again

    async def on_event(self, event: events.Event) -> None:
        if (isinstance(event, events.Key) and not event.is_forwarded
                and not getattr(event, "_rosnet_released", False)
                and not self._take_key(event)):
            return  # queued: it comes back, released, when its turn comes
        await super().on_event(event)  # type: ignore[misc]
