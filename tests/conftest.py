"""Shared fixtures: the network lab (tests/lab/) for the tests that need a real network."""

import os

# Undeclared check-data keys raise in the whole suite (rosnet_tui/core/checks/data/).
os.environ.setdefault("ROSNET_TUI_STRICT_DATA", "1")

pytest_plugins = ["tests.lab.fixtures", "tests.plugins.ssh", "tests.plugins.roscore",
                  "tests.plugins.web"]
