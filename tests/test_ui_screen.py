"""What the technician sees and keeps (issue 12): fitted tables, zoom, scrollable evidence, focus
that shows without colour, modals that say how to close them, set-up validation, the draft and
results kept across sessions."""

from __future__ import annotations

import json

import pytest
from textual.widgets import DataTable, Input

from rosnet_tui.core.checks import CheckContext, CheckSpec
from rosnet_tui.core.results import Outcome, Status
from rosnet_tui.core.saved.settings import load_settings, save_settings
from rosnet_tui.core.saved.ui_state import UiState
from rosnet_tui.ui.setup_screen import SetupScreen
from rosnet_tui.ui.step_screen import StepScreen
from rosnet_tui.ui.widgets import SHORT_TITLES, TITLE_MAX, CheckList
from tests.builders import complete_settings
from tests.test_ui_burst import key_event, make_app, settle


async def _long(ctx: CheckContext) -> Outcome:
    return Outcome(Status.FAIL, "a very long summary " * 8,
                   [f"evidence line {i} " + "x" * 60 for i in range(40)])


def long_specs(step: str) -> list[CheckSpec]:
    return [CheckSpec(f"{step}.long", step, "A check whose title is far too long for the table "
                      "at eighty columns", _long)]


@pytest.mark.parametrize("size", [(80, 24), (120, 40)])
async def test_check_table_fits_its_pane_and_cuts_with_an_ellipsis(tmp_path, size):
    app = make_app(tmp_path, complete_settings(), specs_for=long_specs)
    async with app.run_test(size=size) as pilot:
        await settle(app, pilot)
        app.post_message(key_event("r"))
        checks = app.screen.query_one(CheckList)
        for _ in range(50):
            await pilot.pause(0.05)
            if checks.rows["isp.long"].state == "fail":
                break
        table = app.screen.query_one(DataTable)
        await pilot.pause()
        assert not table.show_horizontal_scrollbar  # never a permanent scrollbar
        assert table.virtual_size.width <= table.size.width
        cells = [str(c) for c in table.get_row("isp.long")]
        assert cells[1].endswith("…") and cells[2].endswith("…")
        # the full title is in the evidence
        await pilot.press("e")
        await pilot.pause()
        text = str(app.screen.query_one("#evidence").render())
        assert "A check whose title is far too long for the table at eighty columns" in text


def test_short_titles_fit():
    assert all(len(t) <= TITLE_MAX for t in SHORT_TITLES.values())


async def test_evidence_scrolls_and_zooms(tmp_path):
    app = make_app(tmp_path, complete_settings(), specs_for=long_specs)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("r")
        checks = app.screen.query_one(CheckList)
        for _ in range(50):
            await pilot.pause(0.05)
            if checks.rows["isp.long"].state == "fail":
                break
        await pilot.press("e", "tab")  # the evidence box takes the focus
        await pilot.pause()
        box = app.screen.query_one("#evidence-box")
        assert app.focused is box
        await pilot.press("end")
        await pilot.pause()
        assert box.scroll_y > 0  # it scrolls: the advice no longer stops mid-sentence
        await pilot.press("z")
        await pilot.pause()
        assert app.screen.maximized is box
        assert box.region.height >= 20
        await pilot.press("z")
        await pilot.pause()
        assert app.screen.maximized is None


@pytest.mark.parametrize("focus", ["#check-table", "#config-pane", "#expected-pane"])
async def test_z_zooms_every_pane(tmp_path, focus):
    app = make_app(tmp_path, complete_settings())
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.pause()
        app.screen.query_one(focus).focus()
        await pilot.pause()
        await pilot.press("z")
        await pilot.pause()
        zoomed = app.screen.maximized
        assert zoomed is not None and zoomed.has_class("pane")
        assert zoomed.region.height >= 20


async def test_focus_shows_without_colour(tmp_path):
    """The focused pane gets a double rule and a reverse-video title: visible in NO_COLOR."""
    app = make_app(tmp_path, complete_settings())
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.pause()
        verify = app.screen.query_one("#verify-pane")
        config = app.screen.query_one("#config-pane")
        assert verify.styles.border_top[0] == "double"
        assert "reverse" in str(verify.styles.border_title_style)
        assert config.styles.border_top[0] == "solid"


@pytest.mark.parametrize("key,screen", [("question_mark", "HelpScreen"),
                                        ("a", "AdvisorScreen")])
async def test_every_modal_says_how_it_closes_and_has_a_second_key(tmp_path, key, screen):
    app = make_app(tmp_path, complete_settings())
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press(key)
        await pilot.pause()
        assert type(app.screen).__name__ == screen
        bar = str(app.screen.query_one("KeyBar").render())
        assert "q" in bar.split()[0] or "Esc/q" in bar  # its own keys, not the step's
        assert "Run" not in bar
        await pilot.press("q")
        await pilot.pause()
        assert isinstance(app.screen, StepScreen)


async def test_cancel_says_which_steps_checks_it_cancelled(tmp_path):
    import asyncio

    async def hangs(ctx):
        await asyncio.sleep(3600)

    def specs(step):
        return [CheckSpec(f"{step}.hangs", step, "hangs", hangs)]

    app = make_app(tmp_path, complete_settings(), specs_for=specs)
    notes: list[str] = []
    app.notify = lambda message, **kw: notes.append(message)  # type: ignore[method-assign]
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("1", "r")
        await pilot.pause(0.1)
        await pilot.press("2", "c")  # on another step: it used to say nothing
        await pilot.pause(0.2)
        assert any("Cancelled the checks of 1 ISP" in n for n in notes), notes


# ---------------------------------------------------------------------------------- set-up
@pytest.mark.parametrize("name,why", [("localhost", "reserved"), ("ip6-allnodes", "reserved"),
                                      ("TurtleBot", "own name"), ("turtlebot", "own name"),
                                      ("SAMI", "ignore case")])
async def test_reserved_and_case_equal_peer_names_are_refused_in_place(tmp_path, name, why):
    app = make_app(tmp_path, complete_settings(), open_setup=True)
    async with app.run_test(size=(80, 24)) as pilot:
        await settle(app, pilot)
        await pilot.press("ctrl+n")
        await pilot.pause()
        await pilot.press(*name, "tab", *"10.1.1.1", "ctrl+s")
        await pilot.pause()
        assert isinstance(app.screen, SetupScreen)  # refused, in place
        error = str(app.screen.query_one("#peer-error").render())
        assert why in error, error
    assert load_settings(tmp_path / "config.toml") is None  # nothing saved


async def test_this_components_name_cannot_be_reserved(tmp_path):
    app = make_app(tmp_path, None)
    async with app.run_test(size=(80, 24)) as pilot:
        await settle(app, pilot)
        await pilot.press(*"LocalHost", "ctrl+s")
        await pilot.pause()
        assert isinstance(app.screen, SetupScreen)
        assert "reserved" in str(app.screen.query_one("#this-name-error").render())


async def test_values_shown_back_are_cut(tmp_path):
    app = make_app(tmp_path, None)
    async with app.run_test(size=(80, 24)) as pilot:
        await settle(app, pilot)
        field = app.screen.query_one("#this-local-ip", Input)
        field.focus()
        field.value = "9" * 500
        await pilot.pause()
        shown = str(app.screen.query_one("#this-local-ip-error").render())
        assert "not an IP address" in shown and len(shown) < 80


async def test_saving_an_unchanged_file_changes_no_byte(tmp_path):
    path = tmp_path / "config.toml"
    s = complete_settings()
    s.this.local_ip = ""  # detected at each run: the form must not write it in
    save_settings(s, path)
    path.write_text("# my robot\n" + path.read_text())
    before, mtime = path.read_bytes(), path.stat().st_mtime_ns
    settings = load_settings(path)
    app = make_app(tmp_path, settings, open_setup=True)
    async with app.run_test(size=(80, 24)) as pilot:
        await settle(app, pilot)
        await pilot.press("ctrl+s")
        await pilot.pause()
        assert isinstance(app.screen, StepScreen)
    assert path.read_bytes() == before and path.stat().st_mtime_ns == mtime


# ---------------------------------------------------------------------------------- kept
async def test_results_and_draft_come_back_in_the_next_session(tmp_path):
    async def ok(ctx):
        return Outcome(Status.PASS, "all fine here", ["seen"])

    def specs(step):
        return [CheckSpec(f"{step}.ok", step, "fine", ok)]

    app = make_app(tmp_path, complete_settings(), specs_for=specs)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("2", "r")
        await pilot.pause(0.3)
        assert app.screen.query_one(CheckList).rows["router.ok"].state == "pass"
        await pilot.press("s", "ctrl+n")
        await pilot.pause()
        await pilot.press(*"newpeer")
        await pilot.pause(0.5)  # kept 0.3 s after the last key
    state = json.loads((tmp_path / "state" / "ui.json").read_text())
    assert state["results"]["router.ok"]["result"]["summary"] == "all fine here"
    draft = state["drafts"][UiState.draft_key(tmp_path / "config.toml")]
    assert draft["peers"][-1]["name"] == "newpeer"

    app = make_app(tmp_path, complete_settings(), specs_for=specs)
    async with app.run_test(size=(80, 24)) as pilot:
        await settle(app, pilot)
        assert isinstance(app.screen, SetupScreen)  # the unsaved set-up, back
        names = [w.value for w in app.screen.query(Input) if w.id and w.id.endswith("-name")]
        assert "newpeer" in names
        await pilot.press("escape")  # discard it
        await pilot.pause()
        await pilot.press("2")
        await pilot.pause()
        row = app.screen.query_one(CheckList).rows["router.ok"]
        assert row.state == "pass" and row.at  # the earlier result, shown with its time
        assert "results of" in app.screen.query_one("#verify-pane").border_title
        assert app.session.findings is not None
    assert not json.loads((tmp_path / "state" / "ui.json").read_text()).get("drafts")


def test_a_damaged_state_file_is_ignored(tmp_path):
    from rosnet_tui.core.config.paths import Paths
    from rosnet_tui.core.wizard.session import WizardSession

    (tmp_path / "state").mkdir()
    (tmp_path / "state" / "ui.json").write_text('{"results": {"x": 5}, "draft": [1], "la')
    s = WizardSession(complete_settings(),
                      Paths(config_path=tmp_path / "c.toml", state_dir=tmp_path / "state"))
    assert s.last_step() == "isp" and s.draft() is None and s.latest_results() == {}


async def test_the_advisors_advice_scrolls_and_zooms(tmp_path):
    async def fails(ctx):
        return Outcome(Status.FAIL, "broken", ["it broke"])

    def specs(step):
        return [CheckSpec("router.port_open", step, "ports", fails)] if step == "router" else []

    app = make_app(tmp_path, complete_settings(), specs_for=specs)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("2", "r")
        await pilot.pause(0.3)
        await pilot.press("a")
        await pilot.pause()
        assert type(app.screen).__name__ == "AdvisorScreen"
        await pilot.press("tab", "z")
        await pilot.pause()
        box = app.screen.query_one("#advisor-detail-box")
        assert app.screen.maximized is box and box.region.height >= 20


def test_every_check_has_a_short_title():
    """The table is drawn before the checks are loaded: every check needs its words there
    (router.upnp and the ros2.* checks showed their ids)."""
    from rosnet_tui.core.checks import REGISTRY, load_builtin_checks

    load_builtin_checks()
    assert set(REGISTRY) - set(SHORT_TITLES) == set()


@pytest.mark.parametrize("size", [(80, 24), (120, 40)])
async def test_every_line_of_a_code_block_gets_the_same_indent(tmp_path, size):
    """Issue 29 §4 row 8: the Configuration pane indented only the first line of a code block
    (the hosts lines of step 3 stood misaligned)."""
    from textual.geometry import Region

    app = make_app(tmp_path, complete_settings())
    async with app.run_test(size=size) as pilot:
        await pilot.press("3")
        await pilot.pause()
        text = app.screen.query_one("#config-text")
        lines = [s.text.rstrip() for s in text.render_lines(Region(0, 0, text.size.width,
                                                                   text.size.height))]
    hosts = [line for line in lines if line.strip().endswith(("turtlebot", "sami"))
             and line.strip()[0].isdigit()]
    assert [h.split()[-1] for h in hosts] == ["turtlebot", "sami"]
    assert all(h.startswith("  ") and not h.startswith("   ") for h in hosts), hosts
    assert len({h.rindex(" ") for h in hosts}) == 1, hosts  # the names in one column


def _app_on(config, state, settings=None):
    """The app on settings file *config*, with the state folder *state* shared by every file."""
    from rosnet_tui.core.config.paths import Paths
    from rosnet_tui.core.config.settings_model import Settings
    from rosnet_tui.core.wizard.session import WizardSession
    from rosnet_tui.ui.app import RosnetApp
    from tests.test_ui import NET

    return RosnetApp(WizardSession(settings or Settings(), Paths(config_path=config,
                                                                 state_dir=state),
                                   detect_net=lambda: NET, specs_for=lambda step: []))


async def test_a_draft_belongs_to_its_settings_file(tmp_path):
    """Issue 29 §4 row 2: `--config new.toml`, Ctrl+Q, then the everyday file: a blank set-up
    opened over complete settings ("typed ..., not saved yet" though nothing was typed), and
    Ctrl+S would have saved it over that file."""
    state, new, main = tmp_path / "state", tmp_path / "new.toml", tmp_path / "config.toml"
    save_settings(complete_settings(), main)
    app = _app_on(new, state)
    async with app.run_test(size=(80, 24)) as pilot:   # a first run on new.toml: nothing typed
        await pilot.pause()
        assert isinstance(app.screen, SetupScreen)
        await pilot.press("ctrl+q")
        await pilot.pause()
    assert app.session.draft() is None       # nothing typed: no draft
    app = _app_on(main, state, load_settings(main))
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.pause()
        assert isinstance(app.screen, StepScreen)

    app = _app_on(new, state)   # now something is typed on new.toml, and left unsaved
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.pause()
        await pilot.press(*"robot2")
        await pilot.press("ctrl+q")
        await pilot.pause()
    app = _app_on(main, state, load_settings(main))   # not offered over the other file
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.pause()
        assert isinstance(app.screen, StepScreen) and app.session.draft() is None
        await pilot.press("s")   # its own set-up shows its own settings
        await pilot.pause()
        assert app.screen.query_one("#this-name", Input).value == "turtlebot"
        await pilot.press("escape")
        await pilot.pause()
    assert load_settings(main) == complete_settings() and not new.exists()
    app = _app_on(new, state)   # and still there for its own file
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.pause()
        assert isinstance(app.screen, SetupScreen)
        assert app.screen.query_one("#this-name", Input).value == "robot2"


async def test_the_help_fits_one_page_at_80x24(tmp_path):
    """Every key on one page, as the help says: no line wraps, nothing to scroll."""
    from rosnet_tui.ui.help_screen import HELP

    app = make_app(tmp_path, complete_settings())
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("question_mark")
        await pilot.pause()
        body = app.screen.query_one("#help-body")
        text = app.screen.query_one("#help-text")
        assert text.size.height == len(HELP.rstrip("\n").splitlines())   # nothing wrapped
        assert body.max_scroll_y == 0


async def test_the_write_screen_prints_the_undo_command_that_finds_the_journal(tmp_path):
    """Issue 29 §4 row 10's sibling: the write screen said `rosnet-tui undo` without the
    settings file and state dir in use; that command looks in the everyday journal and finds
    nothing. It gives the exact command (the one the command line prints)."""
    from rosnet_tui.core.files.privilege import rosnet_command
    from tests.test_ui import make_app as make_ui_app

    bashrc = tmp_path / "bashrc"
    bashrc.write_text("alias ll='ls -l'\n")
    app = make_ui_app(tmp_path, complete_settings(), bashrc_path=bashrc)
    undo = rosnet_command(["undo"], config=tmp_path / "config.toml", state_dir=tmp_path / "state")
    assert undo == (f"rosnet-tui undo --config {tmp_path / 'config.toml'} "
                    f"--state-dir {tmp_path / 'state'}")
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("4", "w")
        await pilot.pause()
        assert type(app.screen).__name__ == "WriteScreen"
        status = str(app.screen.query_one("#write-status").render())
        assert f"`{undo}` reverts" in status.replace("\n", " "), status
        await pilot.press("escape")
        await pilot.pause()
    assert bashrc.read_text() == "alias ll='ls -l'\n"
