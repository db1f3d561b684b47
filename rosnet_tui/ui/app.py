"""The wizard: a thin Textual layer over rosnet_tui.core.

The app only declares its screens and routes navigation; each screen is handed the
:class:`~rosnet_tui.core.wizard.session.WizardSession` (settings, check states, findings, the door to
run checks, write plans) and reports back with messages.
"""

from __future__ import annotations

import gc
import os

from textual.app import App
from textual.binding import Binding

from rosnet_tui.core.procedure import STEP_IDS
from rosnet_tui.core.wizard.session import WizardSession
from rosnet_tui.core.wizard.steps import step_for
from rosnet_tui.ui import textual_compat as tc
from rosnet_tui.ui.keys import OrderedKeys
from rosnet_tui.ui.messages import Navigate, SettingsSaved
from rosnet_tui.ui.step_screen import StepScreen
from rosnet_tui.ui.terminal import frugal_driver_class
from rosnet_tui.ui.theme import THEME, linux_console, use_console_glyphs
from rosnet_tui.ui.widgets import StepBar


class RosnetApp(OrderedKeys, tc.CrashHook, App[int]):
    CSS_PATH = "app.tcss"
    TITLE = "rosnet-tui"
    ENABLE_COMMAND_PALETTE = False

    BINDINGS = [
        Binding("1", "goto('isp')", "ISP", show=False),
        Binding("2", "goto('router')", "Router", show=False),
        Binding("3", "goto('linux')", "Linux", show=False),
        Binding("4", "goto('ros')", "ROS", show=False),
        Binding("b", "back", "Back"),
        Binding("n", "next", "Next"),
        Binding("a", "advisor", "Advisor"),
        Binding("s", "setup", "Set-up"),
        Binding("question_mark", "help", "Help", key_display="?"),
        Binding("q", "leave", "Quit"),
        Binding("ctrl+z", "suspend_process", "Suspend", show=False, priority=True),
        Binding("ctrl+l", "redraw", "Redraw", show=False),
    ]

    WIDE_AT = 110  # columns from which configuration and verification sit side by side

    def __init__(self, session: WizardSession, *, open_setup: bool = False) -> None:
        """*session*: the settings, the :class:`~rosnet_tui.core.config.paths.Paths`, and how checks are
        found and run (tests hand in their own); *open_setup*: start on the set-up screen."""
        super().__init__(driver_class=None if os.environ.get("ROSNET_TUI_FRUGAL") == "0"
                         else frugal_driver_class())
        self._init_ordered_keys()
        # The theme and the console's glyphs are chosen before the first style is computed
        # (choosing them later restyles every widget, at start-up).
        self.register_theme(THEME)
        self.theme = THEME.name
        # Setting the theme queues a refresh of the CSS, which parses every stylesheet again
        # (twice: once for the check, once more as the next widget class adds its own). Nothing is
        # parsed or styled yet, so the stylesheet takes the theme's variables now and the queued
        # refresh is skipped (refresh_css below): one parse before the first frame, not three.
        self._theme_variables: dict[str, str] | None = self.get_css_variables()
        self.stylesheet.set_variables(self._theme_variables)
        if self.no_color:  # NO_COLOR: the terminal's own colours only (Textual chose its filter
            from textual.filter import Monochrome, NoColor  # for its default theme: greys)

            tc.set_app_filters(self, [NoColor() if isinstance(f, Monochrome) else f
                                   for f in tc.app_filters(self)])
        if linux_console():
            self.add_class("linux")
            use_console_glyphs()
        self.open_setup = open_setup
        self.session = session
        self.current_step = self.session.last_step()

    # ------------------------------------------------------------------ start-up
    def get_default_screen(self) -> StepScreen:
        """The first screen is the step to show. (Pushed over Textual's blank default screen, it
        would be drawn twice more at start-up: every layout of a screen beneath repaints the
        one on top.)"""
        self.set_class(self.size.width >= self.WIDE_AT, "wide")
        for step_id in STEP_IDS:
            screen = StepScreen(step_for(step_id, self.session.settings), self.session)
            self.install_screen(screen, name=f"step-{step_id}")
        return tc.first_screen(self.get_screen(f"step-{self.current_step}"))

    def on_mount(self) -> None:
        self._catch_signals()
        # Back from Ctrl+Z: the terminal shows the shell's screen, so the step is drawn whole
        # (Textual would redraw only what changed meanwhile: nothing).
        self.app_resume_signal.subscribe(self, lambda _app: self.screen.refresh(repaint=True))
        if self.open_setup or not self.session.settings.complete or self.session.draft():
            self.action_setup()

    def on_ready(self) -> None:
        """The first frame is out: garbage collection back on (the CLI paused it for the
        start-up, cli/wizard.py), the objects start-up made frozen first, so that no collection
        scans them again; the terminal left on plain attributes, as the first change expects."""
        if not gc.isenabled():
            gc.freeze()
            gc.enable()
        plain = getattr(tc.app_driver(self), "plain_attributes", None)
        if plain is not None:
            plain()

    def refresh_css(self, animate: bool = True) -> None:
        first, self._theme_variables = self._theme_variables, None
        if first is not None and first == self.get_css_variables():
            return  # the refresh queued by setting the theme in __init__: nothing to change
        super().refresh_css(animate)

    def on_resize(self, event) -> None:
        self.set_class(event.size.width >= self.WIDE_AT, "wide")

    # ------------------------------------------------------------------ navigation
    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        # Single letters act on the step screens only (elsewhere they are typed); Ctrl+Q always quits.
        if action in ("goto", "back", "next", "setup", "leave", "advisor"):
            return isinstance(self.screen, StepScreen)
        return True

    def action_goto(self, step_id: str) -> None:
        if step_id == self.current_step and isinstance(self.screen, StepScreen):
            return
        self.current_step = step_id
        self.switch_screen(f"step-{step_id}")
        self.session.record_step(step_id)

    def on_navigate(self, message: Navigate) -> None:
        if isinstance(self.screen, StepScreen):
            self.action_goto(message.step_id)

    def on_step_bar_selected(self, message: StepBar.Selected) -> None:
        self.action_goto(message.step_id)

    def _step_index(self) -> int:
        return STEP_IDS.index(self.current_step)

    def action_next(self) -> None:
        i = self._step_index()
        if i + 1 < len(STEP_IDS):
            self.action_goto(STEP_IDS[i + 1])
        else:
            self.notify("This is the last step.", timeout=3)

    def action_back(self) -> None:
        i = self._step_index()
        if i > 0:
            self.action_goto(STEP_IDS[i - 1])
        else:
            self.notify("This is the first step.", timeout=3)

    def action_setup(self) -> None:
        from rosnet_tui.ui.setup_screen import SetupScreen  # loaded when first opened

        def done(saved: bool | None) -> None:
            if saved:
                self.notify(f"Settings saved to {self.session.paths.config_path}", timeout=4)

        self.push_screen(SetupScreen(self.session), done)

    def on_settings_saved(self, _message: SettingsSaved) -> None:
        """Settings changed: every mounted step re-renders its tailored configuration."""
        for step_id in STEP_IDS:
            screen = self.get_screen(f"step-{step_id}")
            if isinstance(screen, StepScreen) and screen.is_mounted:
                screen.refresh_config()

    async def action_leave(self) -> None:
        await self.action_quit()

    async def action_quit(self) -> None:
        self.keep_state()  # Ctrl+Q in the middle of the set-up keeps what was typed
        await super().action_quit()

    def action_redraw(self) -> None:
        """Ctrl+L: send the whole screen again (after line noise, or a message over it)."""
        forget = getattr(tc.app_driver(self), "forget_screen", None)
        if forget is not None:
            forget()
        self.refresh(repaint=True, layout=True)
        self.screen.refresh(repaint=True)

    # ------------------------------------------------------------------ leaving
    def _catch_signals(self) -> None:
        """SIGTERM and SIGHUP (a dropped SSH session) end the wizard the normal way: what was
        typed is kept, the terminal is given back as it was."""
        import asyncio
        import signal

        if self.is_headless:
            return
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGTERM, signal.SIGHUP):
            try:
                loop.add_signal_handler(sig, self._on_signal, sig)
            except (NotImplementedError, RuntimeError, ValueError):
                pass

    def _on_signal(self, sig: int) -> None:
        import threading

        self.keep_state()
        self.exit(return_code=128 + int(sig))
        # Should leaving hang (the loop blocked), give the terminal back and go anyway.
        timer = threading.Timer(self.HARD_EXIT_S, self._hard_exit, args=(128 + int(sig),))
        timer.daemon = True
        timer.start()

    HARD_EXIT_S = 2.0

    def _hard_exit(self, code: int) -> None:
        import os
        import termios

        driver = tc.app_driver(self)
        try:
            os.write(2, b"\x1b[<u\x1b[?1000l\x1b[?1003l\x1b[?1006l\x1b[?2004l\x1b[?7h"
                        b"\x1b[?1049l\x1b[?25h\x1b[m")
            attrs = tc.saved_tty_attrs(driver)
            if attrs is not None:
                termios.tcsetattr(tc.driver_fileno(driver), termios.TCSANOW, attrs)
        except (OSError, termios.error, AttributeError):
            pass
        os._exit(code)

    def keep_state(self) -> None:
        """Save what is not saved yet (the set-up draft); results are saved as they land."""
        for screen in self.screen_stack:
            keep = getattr(screen, "keep_draft", None)
            if keep is not None:
                try:
                    keep()
                except Exception:  # keeping a draft must never stand in the way of leaving
                    pass

    def before_crash(self, error: BaseException) -> None:
        self.keep_state()  # a crash keeps the draft too

    def action_advisor(self) -> None:
        from rosnet_tui.ui.advisor_screen import AdvisorScreen

        def done(step_id: str | None) -> None:
            if step_id:
                self.action_goto(step_id)

        self.push_screen(AdvisorScreen(self.session), done)

    def action_help(self) -> None:
        from rosnet_tui.ui.help_screen import HelpScreen

        if not isinstance(self.screen, HelpScreen):
            self.push_screen(HelpScreen())
