"""The Router step's offer to let the modem forward the port (m): what it shows before asking.
Only settings for which nothing may be asked of any modem (so nothing leaves the machine)."""

from __future__ import annotations

from textual.app import App
from textual.widgets import Button, Static

from rosnet_tui.core.config.settings_model import RosSettings, Settings, ThisComponent
from rosnet_tui.ui.map_screen import MapScreen


class _Host(App):
    def __init__(self, screen: MapScreen) -> None:
        super().__init__()
        self._screen = screen

    def on_mount(self) -> None:
        self.push_screen(self._screen)


async def _shown(settings: Settings, tmp_path) -> tuple[str, bool]:
    app = _Host(MapScreen(settings, tmp_path / "state", timeout=1.0))
    async with app.run_test(size=(100, 30)) as pilot:
        for _ in range(50):
            await pilot.pause(0.05)
            text = str(app.screen.query_one("#write-diff", Static).render())
            if "Asking the modem" not in text:
                break
        return text, app.screen.query_one("#write-apply", Button).disabled


async def test_ros1_is_shown_the_manual_and_dmz_path_and_cannot_map(tmp_path):
    s = Settings(this=ThisComponent(name="turtlebot", role="master", local_ip="10.10.10.1"))
    text, disabled = await _shown(s, tmp_path)
    assert "no protocol maps a range" in text and "DMZ" in text and "10.10.10.1" in text
    assert disabled


async def test_a_ros2_member_needs_nothing(tmp_path):
    s = Settings(this=ThisComponent(name="sami", role="member", local_ip="192.168.1.10"),
                 ros=RosSettings(master="turtlebot", version=2))
    text, disabled = await _shown(s, tmp_path)
    assert "Nothing to forward" in text and disabled


async def test_the_map_window_says_how_it_closes_and_q_closes_it(tmp_path):
    """Like every window of the wizard (issue 12): its own key bar, Esc and a second key (q)."""
    s = Settings(this=ThisComponent(name="turtlebot", role="master", local_ip="10.10.10.1"))
    app = _Host(MapScreen(s, tmp_path / "state", timeout=1.0))
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.pause(0.2)
        bar = str(app.screen.query_one("KeyBar").render())
        assert "Esc/q" in bar and "Cancel" in bar
        assert str(app.screen.query_one("#write-apply", Button).label) == "[Map]"
        await pilot.press("y")  # ROS 1: nothing to map, y does nothing
        await pilot.pause()
        assert isinstance(app.screen, MapScreen)
        await pilot.press("q")
        await pilot.pause()
        assert not isinstance(app.screen, MapScreen)
