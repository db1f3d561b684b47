"""Open the wizard (rosnet-tui with no command)."""

from __future__ import annotations

import argparse
import gc
import os
import sys
import threading

from rosnet_tui.cli.common import EXIT_FAIL, EXIT_USAGE, config_path

# Terminals that cannot draw a full-screen program.
NO_SCREEN_TERMS = ("dumb", "unknown", "")


def run_wizard(args: argparse.Namespace) -> int:
    from rosnet_tui.core.config.settings_model import SettingsError, new_settings
    from rosnet_tui.core.saved.settings import load_settings

    path = config_path(args)
    try:
        settings = load_settings(path)
    except SettingsError as exc:
        print(f"rosnet-tui: the settings file cannot be used:\n  {exc}\n"
              "Fix it by hand, or move it away to start the set-up afresh "
              "(rosnet-tui never overwrites it without asking).", file=sys.stderr)
        return EXIT_USAGE
    if not sys.stdout.isatty() or not sys.stdin.isatty():
        print("rosnet-tui: the wizard needs a terminal. Headless, use "
              "'rosnet-tui check' (see --help).", file=sys.stderr)
        return EXIT_USAGE
    term = os.environ.get("TERM", "")
    if term in NO_SCREEN_TERMS:
        print(f"rosnet-tui: this terminal (TERM={term or 'unset'}) cannot show the wizard; "
              "'rosnet-tui check' runs the same checks as plain text (or set TERM, e.g. "
              "TERM=xterm).", file=sys.stderr)
        return EXIT_USAGE
    if os.geteuid() == 0 and not os.environ.get("ROSNET_TUI_ALLOW_ROOT"):
        print("rosnet-tui: note: running as root is not needed; files that need root are "
              "written through sudo.", file=sys.stderr)
    # No cyclic garbage collection until the first frame: start-up makes tens of thousands of
    # objects that all live on (classes, styles, widgets), and the collector would scan them
    # over and over (about 30 ms, a full collection included). The app turns it back on once
    # its first frame is out (RosnetApp.on_ready), with what start-up made set aside (gc.freeze).
    gc.disable()
    try:
        import asyncio

        from rosnet_tui.core.config.paths import Paths
        from rosnet_tui.core.wizard.session import WizardSession
        from rosnet_tui.ui.app import RosnetApp

        session = WizardSession(settings or new_settings(), Paths(config_path=path))
        app = RosnetApp(session, open_setup=bool(getattr(args, "setup", False)))
        # Our own loop: leaving does not wait for threads still blocked on a dead network (a
        # check's connect or SSH handshake); asyncio.run() would, for as long as their timeouts.
        loop = asyncio.new_event_loop()
        asyncio.set_event_loop(loop)
        result = app.run(loop=loop)
    finally:
        gc.enable()  # already on, unless the app stopped before its first frame
    code = app.return_code or 0
    if code == 1:  # Textual has printed the error; a crash never exits 0
        print("rosnet-tui: the wizard stopped on an error (above). Results and an unsaved "
              "set-up were kept: run rosnet-tui again to go on.", file=sys.stderr)
        code = EXIT_FAIL
    elif not code:
        code = int(result or 0)
    return _leave(loop, code)


def _leave(loop, code: int) -> int:
    """Return *code*, or end the process at once when threads are still blocked on the network
    (their results are no longer wanted; everything worth keeping is already written)."""
    executor = getattr(loop, "_default_executor", None)
    if executor is not None:
        executor.shutdown(wait=False, cancel_futures=True)
    busy = [t for t in threading.enumerate()
            if t is not threading.main_thread() and t.is_alive() and not t.daemon]
    if busy:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    return code
