"""The wizard on the ROS 2 path: the set-up screen asks for the ROS version and shows only what
it needs; switching it changes the ROS step's checks and text, at 80x24."""

from __future__ import annotations

from textual.widgets import Select

from rosnet_tui.core.checks.runner import select
from rosnet_tui.core.saved.settings import load_settings
from rosnet_tui.ui.widgets import CheckList
from tests.builders import complete_settings
from tests.test_ui import make_app


async def test_switching_to_ros2_in_setup_changes_the_ros_step(tmp_path):
    app = make_app(tmp_path, complete_settings(), specs=lambda step: select([step]))
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("4")
        await pilot.pause()
        assert list(app.screen.query_one(CheckList).rows)[0] == "ros.env"
        await pilot.press("s")
        await pilot.pause()
        setup = app.screen
        assert not setup.query_one("#zenoh-field").display      # ROS 1: no Zenoh fields
        setup.query_one("#ros-version", Select).value = 2
        await pilot.pause()
        assert setup.query_one("#zenoh-field").display and setup.query_one("#domain-field").display
        await pilot.press("ctrl+s")
        await pilot.pause()
        saved = load_settings(tmp_path / "config.toml")
        assert saved.ros.version == 2 and saved.ros.zenoh_port == 7447
        step = app.screen
        assert list(step.query_one(CheckList).rows) == [
            "ros2.env", "ros2.router", "ros2.graph", "ros2.pubsub_out", "ros2.pubsub_in",
            "ros2.link", "security.outsider"]
        assert "rmw_zenoh" in step.config_source and "tls/" in step.config_source
        await pilot.press("2")
        await pilot.pause()
        assert "7447" in app.session.router_card_text(76)


async def test_ros2_fields_in_a_burst_equal_slow_typing(tmp_path):
    """The ROS version picked and the Zenoh fields it reveals typed in one burst (issue 12's
    burst-safe keys): the same screen and saved settings as typed slowly."""
    from tests.test_ui_burst import compare

    keys = ["tab"] * 6 + ["enter", "up", "enter", "tab", "backspace", "7448", "tab",
                          "backspace", "5", "ctrl+s"]  # a field's text is selected as it is entered
    state = await compare(tmp_path, complete_settings(), keys, open_setup=True)
    assert state["screen"] == "StepScreen", state
    saved = load_settings(tmp_path / "burst" / "config.toml")
    assert (saved.ros.version, saved.ros.zenoh_port, saved.ros.domain_id) == (2, 7448, 5)


async def test_an_unsaved_ros_version_comes_back_with_the_draft(tmp_path):
    """The set-up draft keeps the version as text; the next session selects ROS 2 again."""
    app = make_app(tmp_path, complete_settings())
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("s")
        await pilot.pause()
        app.screen.query_one("#ros-version", Select).value = 2
        await pilot.pause()
        app.screen.keep_draft()
    app = make_app(tmp_path, complete_settings())
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.pause()
        assert app.screen.query_one("#ros-version", Select).value == 2
        assert app.screen.query_one("#zenoh-field").display


async def test_a_step_first_shown_after_the_switch_is_the_ros2_step(tmp_path):
    """Switching to ROS 2 before the ROS step was ever shown: that step still came up with
    ROS 1's expected outcome (its Step was made when the app started)."""
    app = make_app(tmp_path, complete_settings(), specs=lambda step: select([step]))
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("s")
        await pilot.pause()
        app.screen.query_one("#ros-version", Select).value = 2
        await pilot.pause()
        await pilot.press("ctrl+s")
        await pilot.pause()
        await pilot.press("4")
        await pilot.pause()
        step = app.screen
        assert list(step.query_one(CheckList).rows)[0] == "ros2.env"
        assert "Zenoh" in str(step.query_one("#expected-text").render())


def ros2_settings():
    s = complete_settings()
    s.ros.version = 2
    return s


def quick_registry(step: str):
    """The registered checks of *step* (their ids, ROS versions and switches), each answering
    at once: what the runner picks, without touching the network."""
    from dataclasses import replace

    from rosnet_tui.core.results import Outcome, Status

    async def fine(ctx):
        return Outcome(Status.PASS, "fine", [])

    return [replace(spec, func=fine) for spec in select([step])]


async def test_the_ros2_linux_step_lists_only_the_checks_that_run(tmp_path):
    """Issue 29 §4 row 5: under ROS 2 the Linux step listed "Only peers get in" (linux.firewall,
    a ROS 1 check), before and after `r`, where it stayed "not run yet"."""
    app = make_app(tmp_path, ros2_settings(), specs=quick_registry)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("3")
        await pilot.pause()
        picked = [c.id for c in select(["linux"], settings=app.session.settings)]
        checks = app.screen.query_one(CheckList)
        assert list(checks.rows) == picked and "linux.firewall" not in picked
        await pilot.press("r")
        for _ in range(100):
            await pilot.pause(0.02)
            if all(r.state == "pass" for r in checks.rows.values()):
                break
        assert {cid: r.state for cid, r in checks.rows.items()} == {c: "pass" for c in picked}
        assert app.session.step_states()["linux"] == "pass"


async def test_the_ros2_router_card_says_only_the_fleet_gets_in(tmp_path):
    """Issue 29 §4 row 3: the router card (step 2) under ROS 2 with mutual TLS (the default)
    said rmw_zenoh has no authentication and whoever reaches 7447 joins."""
    app = make_app(tmp_path, ros2_settings())
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("2")
        await pilot.pause()
        await pilot.pause()
        card = str(app.screen.query_one("#router-card").render())
        assert "!! Exposure" in card and "certificate" in card
        assert "no authentication" not in card and "joins" not in card
