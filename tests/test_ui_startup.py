"""The wizard's start-up (issue 25, bench row 1): its first frame comes out whole, in one go, and
what it does to be quick leaves nothing behind (garbage collection is back on, the terminal on
plain attributes)."""

from __future__ import annotations

import gc
import re

import pytest

from bench.local_env import local_world, spawn_app
from bench.pty_harness import strip_ansi
from bench.rows_local import app_title
from rosnet_tui.core.config.paths import Paths
from rosnet_tui.core.wizard.session import WizardSession
from rosnet_tui.ui.app import RosnetApp
from rosnet_tui.ui.step_screen import StepScreen
from tests.builders import complete_settings


@pytest.fixture(scope="module")
def world():
    with local_world() as w:
        yield w


def test_the_first_frame_is_whole_when_its_first_words_show(world):
    """What the terminal has got when the step's first words arrive already holds the whole step
    (header, step bar, all three panes, key bar): no partial frame completed by later repaints."""
    world.fresh_state()
    p = spawn_app(world)
    try:
        seen = p.wait_text(app_title("1"), 30)
        assert seen is not None, p.text_since(0)[-600:]
        upto = b"".join(c.data for c in p.chunks if c.t <= seen)
        text = strip_ansi(upto.decode("utf-8", "replace"))
        for part in ("rosnet-tui", ">1 ISP", "expected outcome", "Configuration", "Verification",
                     "Internet (DNS, HTTP)", "not run yet: press r", "? Help"):
            assert part in text, (part, text[-800:])
        # Once it is out, the terminal is left on plain attributes (the next screen's first
        # cell needs no reset): the last attribute change sent is a plain reset.
        p.wait_quiet(0.5, 10)
        raw = p.raw_since(0).decode("utf-8", "replace")
        assert re.findall(r"\x1b\[[0-9;]*m", raw)[-1] == "\x1b[m", repr(raw[-200:])
    finally:
        p.close(b"q")


async def test_garbage_collection_is_back_on_after_the_first_frame(tmp_path):
    """The command line pauses the collector for the start-up (cli/wizard.py); the app turns it
    back on with its first frame, whatever happens after."""
    session = WizardSession(complete_settings(),
                            Paths(config_path=tmp_path / "config.toml", state_dir=tmp_path / "st"))
    gc.disable()
    try:
        app = RosnetApp(session)
        async with app.run_test(size=(80, 24)) as pilot:
            await pilot.pause()
            assert isinstance(app.screen, StepScreen)
            assert gc.isenabled()
            assert len(app.screen_stack) == 1  # the step is the first screen, none beneath it
            await pilot.press("2")  # and can be switched away from like any other
            await pilot.pause()
            assert isinstance(app.screen, StepScreen) and app.screen.step.id == "router"
            await pilot.press("1")
            await pilot.pause()
            assert app.screen.step.id == "isp"
    finally:
        gc.enable()
        gc.unfreeze()
