"""The one door to Textual's internals (written against Textual 8.2.8).

The wizard needs a few things Textual does not offer publicly: whether the app is at rest (message
queues, pending callbacks), the bindings a key would meet, its own terminal-input parser and driver
hooks, and a last word before a crash. Every private Textual attribute, method or module the UI
relies on is reached here and nowhere else, and :data:`RELIED_ON` lists each of them:
tests/test_textual_compat.py checks them against the installed Textual, so an upgrade that removes
or renames one fails there, not in front of a user.

Nothing here imports Textual at start-up cost beyond what the app loads anyway: the parser module
is imported when the driver is built.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from typing import Any, NamedTuple


class Reliance(NamedTuple):
    """One internal of Textual this module uses: *owner* is a module path or ``module:Class``;
    *name* an attribute of it (on an instance when *on_instance*); *kind* says how it is used."""

    owner: str
    name: str
    kind: str  # "attribute", "method" (called), "override" (a method we override), "module"
    on_instance: bool = False


RELIED_ON: tuple[Reliance, ...] = (
    Reliance("textual.keys", "_character_to_key", "method"),
    Reliance("textual._xterm_parser", "XTermParser", "module"),
    Reliance("textual._xterm_parser:XTermParser", "_sequence_to_key_events", "override"),
    Reliance("textual.drivers.linux_driver", "XTermParser", "attribute"),
    Reliance("textual.drivers.linux_driver:LinuxDriver", "_get_terminal_size", "override"),
    Reliance("textual.drivers.linux_driver:LinuxDriver", "_enable_mouse_support", "override"),
    Reliance("textual.drivers.linux_driver:LinuxDriver", "_mouse", "attribute", True),
    Reliance("textual.drivers.linux_driver:LinuxDriver", "attrs_before", "attribute", True),
    Reliance("textual.drivers.linux_driver:LinuxDriver", "fileno", "attribute", True),
    Reliance("textual.message_pump:MessagePump", "_message_queue", "attribute", True),
    Reliance("textual._queue:Queue", "ready_event", "attribute", True),
    Reliance("textual.message_pump:MessagePump", "_closed", "attribute", True),
    Reliance("textual.message_pump:MessagePump", "_closing", "attribute", True),
    Reliance("textual.screen:Screen", "_callbacks", "attribute", True),
    Reliance("textual.screen:Screen", "_layout_required", "attribute", True),
    Reliance("textual.screen:Screen", "_recompose_required", "attribute", True),
    Reliance("textual.screen:Screen", "_binding_chain", "attribute"),
    Reliance("textual.screen:Screen", "_push_result_callback", "method"),
    Reliance("textual.dom:DOMNode", "_merged_bindings", "attribute", True),
    Reliance("textual.widgets:Input", "_on_key", "override"),
    Reliance("textual.app:App", "_exit", "attribute", True),
    Reliance("textual.app:App", "_driver", "attribute", True),
    Reliance("textual.app:App", "_filters", "attribute", True),
    Reliance("textual.app:App", "_installed_screens", "attribute", True),
    Reliance("textual.app:App", "_handle_exception", "override"),
)


# ---------------------------------------------------------------------- keys
def character_to_key(char: str) -> str:
    """Textual's key name for a printable character that is not alphanumeric ("?" ->
    "question_mark")."""
    from textual.keys import _character_to_key

    return _character_to_key(char)


def own_bindings(widget, key: str) -> list:
    """The bindings *widget* (and its classes) declare for *key*."""
    return list(widget._merged_bindings.key_to_bindings.get(key, []))


def binding_chain(screen) -> list:
    """(node, bindings) from the focused widget up to the app: where a key on *screen* is looked up."""
    return screen._binding_chain


# ---------------------------------------------------------------------- at rest
def queue_empty(pump) -> bool:
    """Whether *pump* (an app, screen or widget) has no message queued."""
    return pump._message_queue.empty()


def pump_idle(pump) -> bool:
    """True when *pump* has nothing queued and waits for its next message (or is closing)."""
    queue = pump._message_queue
    if not queue.empty():
        return False
    # Textual's queue wakes its reader with an asyncio.Event; a waiter on it means the pump
    # is blocked on an empty queue.
    waiters = getattr(queue.ready_event, "_waiters", None)
    if waiters is None:  # another asyncio: emptiness is the best we can tell
        return True
    return bool(waiters) or pump._closed or pump._closing


def callbacks_pending(screen) -> bool:
    """Whether *screen* still has callbacks waiting for the next refresh."""
    return bool(screen._callbacks)


def layout_pending(screen) -> bool:
    """Whether *screen* owes a layout (or a recompose) it has not done yet.

    Textual lays a screen out from a timer once its messages are handled, not through a message:
    between the screen going idle and that timer firing (late on a loaded machine) every queue
    is empty, yet a widget just shown or mounted has no place, and the focus order, which Textual
    sorts by place, puts it first.
    """
    return bool(screen._layout_required or screen._recompose_required)


def app_leaving(app) -> bool:
    """Whether *app* is exiting or closed."""
    return bool(app._exit or app._closing or app._closed)


def installed_screens(app) -> list:
    """The screens installed by name in *app* (instances, and factories not called yet)."""
    return list(getattr(app, "_installed_screens", {}).values())


def first_screen(screen):
    """*screen*, made ready to be the app's first screen (App.get_default_screen): switching away
    from a screen drops the result callback that pushing it gave it, and a first screen was never
    pushed, so it gets one that does nothing."""
    screen._push_result_callback(screen, None)
    return screen


# ---------------------------------------------------------------------- the app
def app_driver(app):
    """The driver *app* runs on (None before it starts, or headless without one)."""
    return app._driver


def app_filters(app) -> list:
    """The line filters *app* applies to every frame (Textual chose them for NO_COLOR...)."""
    return app._filters


def set_app_filters(app, filters: list) -> None:
    app._filters = filters


def saved_tty_attrs(driver):
    """The terminal attributes *driver* saved before it took the terminal (None: none saved)."""
    return getattr(driver, "attrs_before", None)


def driver_fileno(driver) -> int:
    """The file descriptor *driver* reads the terminal from."""
    return driver.fileno


class CrashHook:
    """App mixin: :meth:`before_crash` runs when an exception reaches Textual's handler, which
    then shows it and ends the app as usual."""

    def before_crash(self, error: BaseException) -> None:
        """Override: what to do first."""

    def _handle_exception(self, error: Exception) -> None:
        self.before_crash(error)
        super()._handle_exception(error)  # type: ignore[misc]


# ---------------------------------------------------------------------- widgets
class KeyFirst:
    """Input mixin: :meth:`key_first` sees each key before the Input's own handler and returns
    True when it has dealt with it (the Input's handler is then skipped)."""

    async def key_first(self, event) -> bool:
        return False

    async def _on_key(self, event) -> None:
        if await self.key_first(event):
            return
        await super()._on_key(event)  # type: ignore[misc]


# ---------------------------------------------------------------------- terminal driver
KeyEvents = Callable[[str, bool], Iterable[Any]]


def input_parser_class(key_events: Callable[[str, bool, KeyEvents], Iterator[Any]],
                       name: str = "Parser") -> type:
    """Textual's terminal-input parser, whose key events for an escape sequence come from
    ``key_events(sequence, alt, textual)``, where ``textual(sequence, alt)`` gives Textual's own."""
    from textual._xterm_parser import XTermParser

    class Parser(XTermParser):
        def _sequence_to_key_events(self, sequence: str, alt: bool = False):
            yield from key_events(sequence, alt, super()._sequence_to_key_events)

    Parser.__name__ = Parser.__qualname__ = name
    return Parser


def use_input_parser(parser_class: type) -> None:
    """Make Textual's Linux driver build *parser_class* when its input thread starts."""
    from textual.drivers import linux_driver

    linux_driver.XTermParser = parser_class  # type: ignore[misc]


class DriverHooks:
    """LinuxDriver mixin: :meth:`size_asked` runs whenever Textual asks the terminal's size (on
    every SIGWINCH), and :meth:`enable_mouse` replaces Textual's mouse set-up (it is told whether
    the app wants the mouse at all)."""

    def size_asked(self) -> None:
        """Override."""

    def enable_mouse(self, wanted: bool) -> None:
        """Override: Textual's own set-up when not overridden."""
        super()._enable_mouse_support()  # type: ignore[misc]

    def _get_terminal_size(self) -> tuple[int, int]:
        self.size_asked()
        return super()._get_terminal_size()  # type: ignore[misc]

    def _enable_mouse_support(self) -> None:
        self.enable_mouse(bool(self._mouse))  # type: ignore[attr-defined]
