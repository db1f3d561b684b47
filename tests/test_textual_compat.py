"""Textual's internals the wizard relies on are reached through rosnet_tui/ui/textual_compat.py only,
and each of them still exists in the installed Textual: an upgrade that removes or renames one
fails here (issue 23)."""

from __future__ import annotations

import ast
import asyncio
import importlib
import inspect
import re
from pathlib import Path

import pytest

from rosnet_tui.ui import textual_compat as tc

UI = Path(tc.__file__).parent
COMPAT = Path(tc.__file__)


def owner_of(reliance: tc.Reliance):
    module, _, cls = reliance.owner.partition(":")
    obj = importlib.import_module(module)
    return getattr(obj, cls) if cls else obj


def instance_of(cls):
    """A real instance of the Textual class *cls* (not started), to see its instance attributes."""
    from textual.app import App
    from textual.drivers.linux_driver import LinuxDriver

    async def make():  # a driver takes the running loop
        if issubclass(cls, LinuxDriver):
            return cls(App(), debug=False, mouse=True, size=None)
        return cls()

    return asyncio.run(make())


@pytest.mark.parametrize("reliance", tc.RELIED_ON, ids=lambda r: f"{r.owner}.{r.name}")
def test_each_internal_exists_in_the_installed_textual(reliance: tc.Reliance) -> None:
    owner = owner_of(reliance)
    if reliance.on_instance:
        assert hasattr(instance_of(owner), reliance.name), reliance
    else:
        assert hasattr(owner, reliance.name), reliance
    if reliance.kind in ("method", "override"):
        assert callable(getattr(owner, reliance.name)), reliance


# The signatures our overrides and calls are written for.
SIGNATURES = {
    ("textual._xterm_parser:XTermParser", "_sequence_to_key_events"): ["self", "sequence", "alt"],
    ("textual.drivers.linux_driver:LinuxDriver", "_get_terminal_size"): ["self"],
    ("textual.drivers.linux_driver:LinuxDriver", "_enable_mouse_support"): ["self"],
    ("textual.widgets:Input", "_on_key"): ["self", "event"],
    ("textual.app:App", "_handle_exception"): ["self", "error"],
    ("textual.keys", "_character_to_key"): ["character"],
    ("textual.screen:Screen", "_push_result_callback"): ["self", "requester", "callback", "future"],
}


@pytest.mark.parametrize("where", sorted(SIGNATURES), ids=lambda w: f"{w[0]}.{w[1]}")
def test_overridden_and_called_internals_keep_their_signature(where) -> None:
    owner = owner_of(tc.Reliance(where[0], where[1], "method"))
    fn = getattr(owner, where[1])
    assert list(inspect.signature(fn).parameters) == SIGNATURES[where]
    if where[1] == "_on_key":
        assert inspect.iscoroutinefunction(fn)
    if where[1] == "_sequence_to_key_events":
        assert inspect.isgeneratorfunction(fn)


def test_every_override_and_call_has_its_signature_checked() -> None:
    relied = {(r.owner, r.name) for r in tc.RELIED_ON if r.kind in ("method", "override")}
    assert relied == set(SIGNATURES)


def test_the_queue_wakes_its_reader_with_an_asyncio_event() -> None:
    """pump_idle tells "waiting for a message" by the waiters on the queue's event."""
    from textual._queue import Queue

    queue = Queue()
    assert isinstance(queue.ready_event, asyncio.Event)
    assert hasattr(queue.ready_event, "_waiters")


def test_the_linux_driver_builds_its_parser_from_its_module_name() -> None:
    """use_input_parser swaps the module-level name the driver's input thread builds from."""
    from textual.drivers import linux_driver

    assert "XTermParser(" in inspect.getsource(linux_driver.LinuxDriver)


def private_names_in_compat() -> set[str]:
    """Every ``._name`` and ``from textual... import _name`` written in textual_compat.py."""
    source = COMPAT.read_text()
    names = set(re.findall(r"\.(_[a-z][a-z_]*)\b", source))
    names |= set(re.findall(r"import (_[a-z][a-z_]*)\b", source))
    return names


def test_the_list_names_every_internal_the_module_touches() -> None:
    listed = {r.name for r in tc.RELIED_ON}
    listed |= {part for r in tc.RELIED_ON for part in re.split("[.:]", r.owner)}
    asyncio_internal = {"_waiters"}  # checked above, on asyncio.Event
    assert private_names_in_compat() - listed - asyncio_internal == set()


def ui_sources() -> list[Path]:
    root = UI.parent
    return [p for p in root.rglob("*.py") if p != COMPAT
            and re.search(r"^\s*(from|import) textual", p.read_text(), re.M)]


def test_no_other_module_reaches_textual_internals() -> None:
    internal = {r.name for r in tc.RELIED_ON if r.name.startswith("_")}
    offences = []
    for path in ui_sources():
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("textual"):
                if "._" in "." + node.module or any(a.name.startswith("_") for a in node.names):
                    offences.append(f"{path.name}:{node.lineno} imports {node.module}")
            elif isinstance(node, ast.Import):
                offences += [f"{path.name}:{node.lineno} imports {a.name}" for a in node.names
                             if a.name.startswith("textual._")]
            elif (isinstance(node, ast.Attribute) and node.attr in internal
                  and ast.unparse(node) != "os._exit"):
                offences.append(f"{path.name}:{node.lineno} .{node.attr}")
            elif (isinstance(node, ast.Call) and ast.unparse(node.func) in ("getattr", "setattr")
                  and len(node.args) > 1 and isinstance(node.args[1], ast.Constant)
                  and node.args[1].value in internal):
                offences.append(f"{path.name}:{node.lineno} getattr {node.args[1].value}")
            elif isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and node.name in internal:
                offences.append(f"{path.name}:{node.lineno} overrides {node.name}")
    assert offences == []


# Private names used on objects other than self, that are not Textual's.
NOT_TEXTUAL = {"os._exit", "span._replace", "released._rosnet_released"}


def test_no_other_object_is_reached_through_a_private_name() -> None:
    """Outside textual_compat, a ``._name`` is only ever our own (on self) or one of NOT_TEXTUAL
    (so a new reach into a Textual object, self.app._x, fails here)."""
    offences = []
    for path in ui_sources():
        for node in ast.walk(ast.parse(path.read_text())):
            if (isinstance(node, ast.Attribute) and node.attr.startswith("_")
                    and not node.attr.startswith("__")
                    and not (isinstance(node.value, ast.Name) and node.value.id == "self")
                    and ast.unparse(node) not in NOT_TEXTUAL
                    and not (isinstance(node.value, ast.Call)
                             and ast.unparse(node.value.func) == "super")):
                offences.append(f"{path.name}:{node.lineno} {ast.unparse(node)}")
    assert offences == []


def textual_classes_in_ui() -> list[type]:
    """Every class of rosnet_tui.ui built on a Textual class (the driver too)."""
    from rosnet_tui.ui.terminal import frugal_driver_class

    classes = {frugal_driver_class()}
    for path in sorted(UI.glob("*.py")):
        module = importlib.import_module(f"rosnet_tui.ui.{path.stem}")
        for obj in vars(module).values():
            if (inspect.isclass(obj) and obj.__module__ == module.__name__
                    and any(b.__module__.startswith("textual") for b in obj.__mro__)):
                classes.add(obj)
    return sorted(classes, key=lambda c: c.__qualname__)


def own_private_names(cls) -> set[str]:
    """The single-underscore names *cls* (and our mixins) define or use: methods, self._x."""
    from textual.reactive import Reactive

    names = set()
    for klass in cls.__mro__:
        if klass.__module__.startswith("textual") or klass is object:
            continue
        if klass.__module__ == tc.__name__:
            continue  # the compat mixins override Textual's names on purpose
        names |= {n for n in vars(klass) if n.startswith("_") and not n.startswith("__")
                  and n != "_is_protocol"  # typing writes it into every Generic subclass
                  and not (n.startswith("_default_") and isinstance(  # a reactive's default,
                      vars(klass).get(n[len("_default_"):]), Reactive))}  # written by Textual
        try:
            source = inspect.getsource(klass)
        except (OSError, TypeError):
            continue
        names |= set(re.findall(r"self\.(_[a-z][a-z0-9_]*)", source))  # set or read
    return names


def textual_private_names(cls) -> set[str]:
    """The single-underscore names of the Textual classes *cls* is built on (class and instance),
    less those Textual writes into every subclass itself (its metaclass and __init_subclass__)."""
    names: set[str] = set()
    textual_base = next(b for b in cls.__mro__ if b.__module__.startswith("textual"))
    generated = set(vars(type("Probe", (textual_base,), {})))
    for base in cls.__mro__:
        if not base.__module__.startswith("textual"):
            continue
        names |= {n for n in dir(base) if n.startswith("_") and not n.startswith("__")}
        try:
            names |= set(vars(instance_of(base)))
        except Exception:  # an abstract or argument-hungry base: its class names only
            pass
    return {n for n in names if not n.startswith("__")} - generated


def test_our_subclasses_neither_shadow_nor_read_textual_private_names() -> None:
    """A private name of ours that Textual also uses would silently replace Textual's; reading
    one of Textual's (self._driver...) is reaching its internals outside textual_compat."""
    clashes = {}
    for cls in textual_classes_in_ui():
        clash = own_private_names(cls) & textual_private_names(cls)
        if clash:
            clashes[cls.__qualname__] = sorted(clash)
    assert clashes == {}


async def test_the_doors_answer_on_a_running_app() -> None:
    from textual.app import App
    from textual.screen import Screen

    class Tiny(App):
        def on_mount(self) -> None:
            self.install_screen(Screen(), name="other")

    app = Tiny()
    async with app.run_test() as pilot:
        await pilot.pause()
        assert not tc.app_leaving(app)
        assert not tc.callbacks_pending(app.screen)
        # a callback for after the refresh of a screen that owes a layout: queued to the screen
        # as a message first, then held by the screen until its refresh, then gone once run
        ran = asyncio.Event()
        app.screen.refresh(layout=True)
        app.screen.call_after_refresh(ran.set)
        assert not tc.queue_empty(app.screen)
        held = False
        for _ in range(10_000):               # bounded; each turn lets the app run
            held = held or tc.callbacks_pending(app.screen)
            if ran.is_set():
                break
            await asyncio.sleep(0)
        await asyncio.wait_for(ran.wait(), 10)
        assert held and not tc.callbacks_pending(app.screen)
        await pilot.pause()
        assert tc.queue_empty(app.screen)
        assert len(tc.installed_screens(app)) == 1
        assert isinstance(tc.binding_chain(app.screen), list)
        assert tc.app_filters(app) is not None
        assert tc.character_to_key("?") == "question_mark"
    assert tc.app_leaving(app)
