"""The wizard with web clients (issue 24): the set-up screen asks about rosbridge, and the ROS step
shows ros.rosbridge (and the bridge's text) exactly when `[rosbridge] enabled = true`."""

from __future__ import annotations

from dataclasses import replace

from textual.widgets import Input, Select

from rosnet_tui.core.checks.runner import select
from rosnet_tui.core.config.settings_model import RosbridgeSettings
from rosnet_tui.core.saved.settings import load_settings
from rosnet_tui.ui.widgets import CheckList
from tests.builders import complete_settings
from tests.test_ui import make_app


def _with_bridge(**kw):
    s = complete_settings()
    s.this = replace(s.this, name="sami", role="member", local_ip="192.168.1.10")
    s.peers[0] = replace(s.peers[0], name="turtlebot")
    s.ros.master = "turtlebot"
    s.rosbridge = RosbridgeSettings(**kw)
    return s


async def test_the_ros_step_shows_the_check_only_when_rosbridge_is_enabled(tmp_path):
    for enabled in (True, False):
        app = make_app(tmp_path / str(enabled), _with_bridge(enabled=enabled),
                       specs=lambda step: select([step]))
        async with app.run_test(size=(80, 24)) as pilot:
            await pilot.press("4")
            await pilot.pause()
            rows = list(app.screen.query_one(CheckList).rows)
            assert rows[:5] == ["ros.env", "ros.master", "ros.node_uris", "ros.pubsub_out",
                                "ros.pubsub_in"]
            assert ("ros.rosbridge" in rows) is enabled, rows
            text = app.screen.config_source
            assert ("rosbridge_websocket.launch" in text) is enabled
            assert ("ws://turtlebot:9090/" in text) is enabled


async def test_ros2_ros_step_shows_the_check_too(tmp_path):
    s = _with_bridge(enabled=True)
    s.ros.version = 2
    app = make_app(tmp_path, s, specs=lambda step: select([step]))
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("4")
        await pilot.pause()
        rows = list(app.screen.query_one(CheckList).rows)
        assert rows[0] == "ros2.env" and rows[-2:] == ["ros.rosbridge", "security.outsider"], rows
        assert "rosbridge_websocket_launch.xml" in app.screen.config_source


async def test_setup_asks_and_saving_it_puts_the_check_on_the_ros_step(tmp_path):
    app = make_app(tmp_path, complete_settings(), specs=lambda step: select([step]))
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("4")
        await pilot.pause()
        assert "ros.rosbridge" not in list(app.screen.query_one(CheckList).rows)
        await pilot.press("s")
        await pilot.pause()
        setup = app.screen
        assert setup.query_one("#rosbridge-enabled", Select).value is False
        assert not setup.query_one("#rosbridge-port-field").display   # off: nothing more asked
        setup.query_one("#rosbridge-enabled", Select).value = True
        await pilot.pause()
        assert setup.query_one("#rosbridge-port-field").display
        assert setup.query_one("#rosbridge-host-field").display
        port = setup.query_one("#rosbridge-port", Input)
        assert port.value == "9090"
        port.value = "70000"
        await pilot.press("ctrl+s")
        await pilot.pause()
        assert app.screen is setup                                   # refused, said why
        assert "between 1 and 65535" in str(setup.query_one("#rosbridge-port-error").render())
        port.value = "9091"
        await pilot.press("ctrl+s")
        await pilot.pause()
        saved = load_settings(tmp_path / "config.toml")
        assert saved.rosbridge == RosbridgeSettings(enabled=True, port=9091, host="")
        assert "[rosbridge]" in (tmp_path / "config.toml").read_text()
        rows = list(app.screen.query_one(CheckList).rows)
        assert rows[-2:] == ["ros.rosbridge", "security.outsider"], rows


async def test_an_unsaved_rosbridge_choice_comes_back_with_the_draft(tmp_path):
    app = make_app(tmp_path, complete_settings())
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("s")
        await pilot.pause()
        app.screen.query_one("#rosbridge-enabled", Select).value = True
        await pilot.pause()
        app.screen.query_one("#rosbridge-host", Input).value = "sami"
        app.screen.keep_draft()
    app = make_app(tmp_path, complete_settings())
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.pause()
        assert app.screen.query_one("#rosbridge-enabled", Select).value is True
        assert app.screen.query_one("#rosbridge-host-field").display
        assert app.screen.query_one("#rosbridge-host", Input).value == "sami"
