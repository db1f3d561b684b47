"""Shared fixtures: the network lab (tests/lab/) for the tests that need a real network."""

import os

# Undeclared check-data keys raise in the whole suite (rosnet_tui/core/checks/data/).
os.environ.setdefault("ROSNET_TUI_STRICT_DATA", "1")
# The suite's runs of `rosnet-tui check` leave no warm process behind (each test's own settings,
# namespaces and environment); tests/test_warm.py turns it on for its own runs.
os.environ["ROSNET_TUI_WARM"] = "0"

pytest_plugins = ["tests.lab.fixtures", "tests.plugins.ssh", "tests.plugins.roscore",
                  "tests.plugins.web"]
