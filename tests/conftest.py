"""Shared fixtures: the network lab (tests/lab/) for the tests that need a real network."""

pytest_plugins = ["tests.lab.fixtures"]
