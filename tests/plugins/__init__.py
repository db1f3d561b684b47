"""Fixtures as pytest plugins (listed in tests/conftest.py)."""
