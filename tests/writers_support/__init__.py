"""Helpers for the writers' crash tests: rosnet-tui commands run against a bind-mounted
/etc/hosts in a private mount namespace, and killed when the test says."""
