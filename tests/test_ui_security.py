"""The set-up screen's Security field: on by default (the ROS version's choice: mutual TLS under
ROS 2), off saves [ros] security = "none", and on again follows the version."""

from __future__ import annotations

from textual.widgets import Select

from rosnet_tui.core.saved.settings import load_settings
from tests.test_ui import complete_settings, make_app


async def test_security_field_saves_off_and_on(tmp_path):
    app = make_app(tmp_path, complete_settings())
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("s")
        await pilot.pause()
        setup = app.screen
        assert setup.query_one("#ros-security", Select).value == "on"
        setup.query_one("#ros-version", Select).value = 2
        setup.query_one("#ros-security", Select).value = "none"
        await pilot.pause()
        await pilot.press("ctrl+s")
        await pilot.pause()
        saved = load_settings(tmp_path / "config.toml")
        assert (saved.ros.version, saved.ros.security) == (2, "none")
        await pilot.press("s")
        await pilot.pause()
        setup = app.screen
        assert setup.query_one("#ros-security", Select).value == "none"
        setup.query_one("#ros-security", Select).value = "on"
        await pilot.pause()
        await pilot.press("ctrl+s")
        await pilot.pause()
        assert load_settings(tmp_path / "config.toml").ros.security == "mtls"
