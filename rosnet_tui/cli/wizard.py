"""Open the wizard (rosnet-tui with no command)."""

from __future__ import annotations

import argparse
import os
import sys

from rosnet_tui.cli import EXIT_USAGE, config_path


def run_wizard(args: argparse.Namespace) -> int:
    from rosnet_tui.core.settings import SettingsError, load_settings, new_settings

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
    if os.geteuid() == 0 and not os.environ.get("ROSNET_TUI_ALLOW_ROOT"):
        print("rosnet-tui: note: running as root is not needed; files that need root are "
              "written through sudo.", file=sys.stderr)
    from rosnet_tui.ui.app import AppDeps, RosnetApp

    app = RosnetApp(AppDeps(config_path=path, settings=settings or new_settings(),
                            open_setup=bool(getattr(args, "setup", False))))
    return app.run() or 0
