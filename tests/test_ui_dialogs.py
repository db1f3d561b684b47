"""The wizard's confirm dialogs (issue 29 §4 row 7): a disabled button still shows its label and
its key is not offered; every dialog has `y` and starts on its safe button; a sequence of
previews says where it is ("1 of 2") and Esc ends the whole sequence, writing nothing."""

from __future__ import annotations

from dataclasses import replace

from textual.widgets import Button

from rosnet_tui.ui.map_screen import MapScreen
from rosnet_tui.ui.step_screen import StepScreen
from rosnet_tui.ui.write_screen import UndoScreen, WriteScreen
from tests.builders import complete_settings
from tests.test_ui import make_app

STOCK_HOSTS = "127.0.0.1\tlocalhost\n# keep me\n"


def key_bar(app) -> str:
    return str(app.screen.query_one("KeyBar").render())


def shows_label(button: Button) -> bool:
    """The button's label has a line to be drawn on (a frame around a one-line button leaves it
    none: an empty box)."""
    row = button.content_region
    return row.height >= 1 and row.width >= len(str(button.label)) \
        and button.parent.content_region.contains_region(row)


async def test_a_disabled_map_button_shows_its_label_and_y_is_not_offered(tmp_path):
    """ROS 1: nothing can be mapped. The [Map] button drew as an empty box and the key bar still
    offered `y Map`, which did nothing."""
    app = make_app(tmp_path, complete_settings())
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("2", "m")
        screen = app.screen
        assert isinstance(screen, MapScreen)
        for _ in range(50):
            await pilot.pause(0.02)
            if screen.plan is not None:
                break
        button = screen.query_one("#write-apply", Button)
        assert button.disabled and shows_label(button)
        assert "dim" in str(button.styles.text_style)
        assert "Map" not in key_bar(app) and "Cancel" in key_bar(app)
        assert screen.focused is screen.query_one("#write-cancel")
        # A modem that could map: the key is offered, the button as any other.
        screen.show_plan(replace(screen.plan, blocked=""))
        await pilot.pause()
        assert not button.disabled and shows_label(button)
        assert "y Map" in key_bar(app)
        screen.show_plan(replace(screen.plan, blocked="no modem answered"))
        await pilot.pause()
        assert "Map" not in key_bar(app)


async def test_undo_has_y_and_starts_on_cancel(tmp_path):
    """The undo dialog had no `y` and no focused button."""
    bashrc = tmp_path / "bashrc"
    bashrc.write_text("alias ll='ls -l'\n")
    app = make_app(tmp_path, complete_settings(), bashrc_path=bashrc)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("4", "w")
        await pilot.pause()
        assert isinstance(app.screen, WriteScreen)
        assert app.screen.focused is app.screen.query_one("#write-cancel")
        assert "y Apply" in key_bar(app)
        await pilot.press("y")
        await pilot.pause()
        assert isinstance(app.screen, StepScreen) and "ROS_MASTER_URI" in bashrc.read_text()
        await pilot.press("u")
        await pilot.pause()
        screen = app.screen
        assert isinstance(screen, UndoScreen)
        assert screen.focused is screen.query_one("#write-cancel")
        assert "y Undo" in key_bar(app)
        await pilot.press("enter")  # the focused default is the safe one: nothing undone
        await pilot.pause()
        assert isinstance(app.screen, StepScreen) and "ROS_MASTER_URI" in bashrc.read_text()
        await pilot.press("u")
        await pilot.pause()
        await pilot.press("y")
        await pilot.pause()
        assert isinstance(app.screen, StepScreen)
        assert bashrc.read_text() == "alias ll='ls -l'\n"
        await pilot.press("u")  # nothing left to undo: the key is not offered
        await pilot.pause()
        screen = app.screen
        assert isinstance(screen, UndoScreen) and screen.query_one("#write-apply").disabled
        assert shows_label(screen.query_one("#write-apply", Button))
        assert "y Undo" not in key_bar(app)
        await pilot.press("y")
        await pilot.pause()
        assert app.screen is screen


async def test_esc_on_the_hosts_preview_ends_the_sequence_and_writes_nothing(tmp_path):
    """ROS 1, step 3, `w`: the hosts set and then the peers-only firewall. Esc on the first
    preview opened the second at once (and nothing said "1 of 2"), so a `q` meant to quit the
    wizard closed that one."""
    hosts = tmp_path / "hosts"
    hosts.write_text(STOCK_HOSTS)
    app = make_app(tmp_path, complete_settings(), hosts_path=hosts)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("3", "w")
        await pilot.pause()
        screen = app.screen
        assert isinstance(screen, WriteScreen) and "hosts set" in screen.plan.title
        assert "1 of 2" in str(screen.query_one("#write-title").render())
        await pilot.press("escape")
        await pilot.pause()
        assert isinstance(app.screen, StepScreen)
        assert hosts.read_text() == STOCK_HOSTS
        await pilot.press("q")  # the next key is the wizard's again
        await pilot.pause()
    assert not app.is_running


async def test_the_second_preview_of_a_sequence_says_so_and_esc_closes_it(tmp_path):
    hosts = tmp_path / "hosts"
    hosts.write_text(STOCK_HOSTS)
    app = make_app(tmp_path, complete_settings(), hosts_path=hosts)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("3", "w")
        await pilot.pause()
        await pilot.press("y")  # the hosts set written, then the firewall's preview
        await pilot.pause()
        screen = app.screen
        assert isinstance(screen, WriteScreen) and "firewall" in screen.plan.title
        assert "2 of 2" in str(screen.query_one("#write-title").render())
        assert "sami" in hosts.read_text()
        await pilot.press("escape")
        await pilot.pause()
        assert isinstance(app.screen, StepScreen)

        # Again, the hosts set already current: the first preview has nothing to write and
        # `y` goes on to the second.
        await pilot.press("w")
        await pilot.pause()
        first = app.screen
        assert isinstance(first, WriteScreen) and "1 of 2" in str(
            first.query_one("#write-title").render())
        assert "nothing to write" in str(first.query_one("#write-diff").render())
        assert "y Next" in key_bar(app)
        await pilot.press("y")
        await pilot.pause()
        assert isinstance(app.screen, WriteScreen) and "firewall" in app.screen.plan.title
        await pilot.press("escape")
        await pilot.pause()
        assert isinstance(app.screen, StepScreen)


async def test_every_confirm_dialog_has_y_and_a_focused_safe_button(tmp_path):
    """The siblings: every dialog of rosnet_tui/ui that asks before acting."""
    from rosnet_tui.ui.trust_screen import TrustKeyScreen

    for cls in (WriteScreen, UndoScreen, MapScreen, TrustKeyScreen):
        keys = {k.strip() for b in cls.BINDINGS for k in b.key.split(",")}
        assert "escape" in keys, cls.__name__
        # Trusting an unknown host key is never one typed-ahead letter away.
        assert ("y" in keys) is (cls is not TrustKeyScreen), cls.__name__
    app = make_app(tmp_path, complete_settings())
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.pause()
        app.push_screen(TrustKeyScreen("sami", 22, "ssh-ed25519 AAAA", "SHA256:x", "198.51.100.2"))
        await pilot.pause()
        screen = app.screen
        assert screen.focused is screen.query_one("#trust-no")
        assert "Trust" not in key_bar(app).replace("Do not trust", "")
        await pilot.press("y")
        await pilot.pause()
        assert app.screen is screen, "a typed-ahead y trusted a host key"
