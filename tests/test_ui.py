"""The wizard, driven as a technician would with the keyboard (Textual's Pilot)."""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest
from textual.geometry import Region
from textual.widgets import DataTable, Input

from rosnet_tui.core.checks import CheckContext, CheckSpec
from rosnet_tui.core.config.paths import Paths
from rosnet_tui.core.config.settings_model import Peer, Settings
from rosnet_tui.core.net.netinfo import LocalNet
from rosnet_tui.core.results import Outcome, Status
from rosnet_tui.core.saved.settings import load_settings
from rosnet_tui.core.ssh.options import SshOptions
from rosnet_tui.core.wizard.session import WizardSession
from rosnet_tui.ui.app import RosnetApp
from rosnet_tui.ui.setup_screen import SetupScreen
from rosnet_tui.ui.step_screen import StepScreen
from rosnet_tui.ui.widgets import CheckList
from tests.builders import complete_settings

NET = LocalNet("wlan0", "10.10.10.1", "10.10.10.254", "02:00:00:00:0a:01", "255.255.255.0")


def make_app(tmp_path: Path, settings: Settings | None = None, specs=None, **kw) -> RosnetApp:
    """The app on a session whose files are in *tmp_path*; *kw*: more files (hosts_path,
    bashrc_path), the session's hooks (context_factory...) or open_setup."""
    files = {k: kw.pop(k) for k in ("hosts_path", "bashrc_path") if k in kw}
    open_setup = kw.pop("open_setup", False)
    paths = Paths(config_path=tmp_path / "config.toml", state_dir=tmp_path / "state", **files)
    session = WizardSession(settings or Settings(), paths, detect_net=lambda: NET,
                            specs_for=specs or (lambda step: []), **kw)
    return RosnetApp(session, open_setup=open_setup)


async def test_first_run_opens_setup_prefilled_and_refuses_bad_input(tmp_path):
    app = make_app(tmp_path)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.pause()
        assert isinstance(app.screen, SetupScreen)
        assert app.screen.query_one("#this-local-ip", Input).value == "10.10.10.1"
        await pilot.press(*"turtle bot")
        await pilot.pause()
        error = app.screen.query_one("#this-name-error")
        assert error.display and "spaces" in str(error.render())
        await pilot.press("ctrl+s")
        await pilot.pause()
        assert isinstance(app.screen, SetupScreen)  # refused in place
        assert not (tmp_path / "config.toml").exists()  # nothing saved
        assert app.screen.focused is app.screen.query_one("#this-name", Input)


async def test_setup_saves_valid_settings_and_opens_steps(tmp_path):
    app = make_app(tmp_path)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.pause()
        await pilot.press(*"turtlebot")
        await pilot.press("ctrl+n")  # add a peer
        await pilot.pause()
        await pilot.press(*"sami", "tab", *"192.168.1.10", "tab", *"198.51.100.2", "tab", *"ops")
        await pilot.press("ctrl+s")
        await pilot.pause()
        assert isinstance(app.screen, StepScreen)
    saved = load_settings(tmp_path / "config.toml")
    assert saved is not None and saved.complete
    assert saved.this.name == "turtlebot" and saved.this.local_ip == "10.10.10.1"
    assert saved.peers == [Peer("sami", "192.168.1.10", "198.51.100.2", "ops")]


async def test_bad_peer_address_is_refused_with_its_reason(tmp_path):
    app = make_app(tmp_path)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.pause()
        await pilot.press(*"turtlebot", "ctrl+n")
        await pilot.pause()
        await pilot.press(*"sami", "tab", *"192.168.1", "ctrl+s")
        await pilot.pause()
        assert isinstance(app.screen, SetupScreen)
        assert "not an IP" in str(app.screen.query_one("#peer-error").render())
        assert not (tmp_path / "config.toml").exists()


async def test_complete_settings_open_on_the_steps_where_the_user_left_off(tmp_path):
    (tmp_path / "state").mkdir()
    (tmp_path / "state" / "ui.json").write_text('{"last_step": "linux"}')
    app = make_app(tmp_path, complete_settings())
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.pause()
        assert isinstance(app.screen, StepScreen) and app.screen.step.id == "linux"
        await pilot.press("s")  # set-up stays reachable
        await pilot.pause()
        assert isinstance(app.screen, SetupScreen)
        await pilot.press("escape")
        await pilot.pause()
        assert isinstance(app.screen, StepScreen)


async def test_walk_all_steps_and_back_with_three_panes_each(tmp_path):
    app = make_app(tmp_path, complete_settings())
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.pause()
        seen = []
        for key in ("1", "n", "n", "n", "n", "b", "b", "b", "b", "4", "2"):
            await pilot.press(key)
            await pilot.pause()
            screen = app.screen
            assert isinstance(screen, StepScreen)
            for pane in ("#expected-pane", "#config-pane", "#verify-pane"):
                widget = screen.query_one(pane)
                assert widget.region.height > 0 and widget.region.width > 0
            seen.append(screen.step.id)
        assert seen == ["isp", "router", "linux", "ros", "ros", "linux", "router", "isp", "isp",
                        "ros", "router"]
    assert '"router"' in (tmp_path / "state" / "ui.json").read_text()


async def test_digits_typed_into_a_field_do_not_jump_steps(tmp_path):
    app = make_app(tmp_path, complete_settings(), open_setup=True)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.pause()
        field = app.screen.query_one("#probe-port", Input)
        field.focus()
        field.value = ""
        await pilot.press("2", "3", "4", "5", "6")
        await pilot.pause()
        assert isinstance(app.screen, SetupScreen) and field.value == "23456"


async def test_configuration_follows_the_settings(tmp_path):
    app = make_app(tmp_path, complete_settings())
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("4")
        await pilot.pause()
        source = app.screen.config_source
        assert "ROS_MASTER_URI=http://turtlebot:11311" in source
        assert "is the ROS master" in source
        pane = app.screen.query_one("#config-text")
        drawn = "\n".join(strip.text for strip in pane.render_lines(Region(0, 0, *pane.size)))
        assert "export ROS_MASTER_URI=http://turtlebot:11311" in drawn


async def wait_until(pilot, predicate, seconds: float) -> None:
    """Let the app run until *predicate* holds, for at most *seconds*."""
    for _ in range(int(seconds / 0.05)):
        if predicate():
            return
        await pilot.pause(0.05)


def spec(id: str, step: str, func) -> CheckSpec:
    return CheckSpec(id, step, id.split(".")[1], func)


async def test_checks_stream_live_and_the_ui_stays_responsive(tmp_path):
    release = asyncio.Event()

    async def quick(ctx: CheckContext) -> Outcome:
        return Outcome(Status.PASS, "quick one passed", ["saw it"])

    async def slow(ctx: CheckContext) -> Outcome:
        await release.wait()
        return Outcome(Status.WARN, "slow one warned")

    async def hangs(ctx: CheckContext) -> Outcome:
        await asyncio.sleep(3600)
        return Outcome(Status.PASS, "never")

    specs = {"isp": [spec("isp.quick", "isp", quick), spec("isp.slow", "isp", slow),
                     spec("isp.hangs", "isp", hangs)]}
    ctx_factory = lambda s: CheckContext(settings=s, timeout_s=2.0)  # noqa: E731
    app = make_app(tmp_path, complete_settings(), specs=lambda step: specs.get(step, []),
                   context_factory=ctx_factory)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("1", "r")
        await pilot.pause(0.2)
        rows = app.screen.query_one(CheckList).rows
        assert rows["isp.quick"].state == "pass"
        assert rows["isp.slow"].state == "running" and rows["isp.hangs"].state == "running"
        await pilot.press("2")  # the UI answers while checks run
        await pilot.pause()
        assert app.screen.step.id == "router"
        assert app.screen.query_one(CheckList).rows  # and it is drawn
        release.set()
        await pilot.press("1")
        rows = app.screen.query_one(CheckList).rows
        await wait_until(pilot, lambda: rows["isp.hangs"].state != "running", 5)
        assert rows["isp.slow"].state == "warn"
        assert rows["isp.hangs"].state == "fail"
        assert "timed out" in rows["isp.hangs"].result.summary
        bar = app.screen.query_one("#step-bar")
        assert bar._states["isp"] == "fail" and "1 ISP [x]" in str(bar.render())


async def test_cancel_puts_unfinished_checks_back_to_not_run(tmp_path):
    async def hangs(ctx: CheckContext) -> Outcome:
        await asyncio.sleep(3600)
        return Outcome(Status.PASS, "never")

    specs = {"ros": [spec("ros.hangs", "ros", hangs)]}
    app = make_app(tmp_path, complete_settings(), specs=lambda step: specs.get(step, []),
                   context_factory=lambda s: CheckContext(settings=s, timeout_s=30))
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("4", "r")
        await pilot.pause(0.1)
        assert app.screen.query_one(CheckList).rows["ros.hangs"].state == "running"
        await pilot.press("c")
        await pilot.pause(0.2)
        assert app.screen.query_one(CheckList).rows["ros.hangs"].state == "not run"


async def test_evidence_expands_for_the_highlighted_check(tmp_path):
    async def evidence(ctx: CheckContext) -> Outcome:
        return Outcome(Status.FAIL, "port closed", ["GET /port/12345 -> reachable: false"])

    specs = {"router": [spec("router.demo", "router", evidence)]}
    app = make_app(tmp_path, complete_settings(), specs=lambda step: specs.get(step, []))
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("2", "r")
        await pilot.pause(0.2)
        await pilot.press("e")
        await pilot.pause()
        box = app.screen.query_one("#evidence-box")
        text = app.screen.query_one("#evidence")
        assert box.display and "reachable: false" in str(text.render())
        assert isinstance(app.screen.focused, DataTable)
        await pilot.press("enter")  # Enter toggles too
        await pilot.pause()
        assert not box.display


async def test_help_opens_and_closes(tmp_path):
    app = make_app(tmp_path, complete_settings())
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("question_mark")
        await pilot.pause()
        assert type(app.screen).__name__ == "HelpScreen"
        await pilot.press("escape")
        await pilot.pause()
        assert isinstance(app.screen, StepScreen)


@pytest.mark.parametrize("size", [(80, 24), (120, 40)])
async def test_layout_fits_small_and_large_terminals(tmp_path, size):
    app = make_app(tmp_path, complete_settings())
    async with app.run_test(size=size) as pilot:
        await pilot.press("2")
        await pilot.pause()
        screen = app.screen
        config = screen.query_one("#config-pane").region
        verify = screen.query_one("#verify-pane").region
        if size[0] >= 110:
            assert config.y == verify.y and config.right <= verify.x  # side by side
        else:
            assert config.bottom <= verify.y  # stacked
        assert verify.height >= 5


async def test_advisor_names_the_cause_and_jumps_to_its_step(tmp_path):
    """Table 1, listener up + Closed: the advisor's findings show, and g goes to their step."""

    async def local_ip(ctx):
        return Outcome(Status.PASS, "same", data={"local_ip": "10.10.10.1", "interface": "wlan0",
                                                  "gateway": "10.10.10.254",
                                                  "expected_ip": "10.10.10.1", "differs": False})

    async def port_free(ctx):
        return Outcome(Status.PASS, "free", data={"port": 12345, "in_use": False,
                                                  "process": None, "pid": None})

    async def listener(ctx):
        return Outcome(Status.PASS, "up", data={"port": 12345, "listening": True})

    async def port_open(ctx):
        return Outcome(Status.FAIL, "closed from outside", data={
            "ports": [{"port": 12345, "reachable": False, "listener": True, "via": "echoip"}],
            "test_port": 12345, "test_port_open": False, "public_ip": "203.0.113.2"})

    specs = {"router": [spec("router.local_ip", "router", local_ip),
                        spec("router.port_free", "router", port_free),
                        spec("router.listener", "router", listener),
                        spec("router.port_open", "router", port_open)]}
    app = make_app(tmp_path, complete_settings(), specs=lambda step: specs.get(step, []))
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("2", "r")
        rows = app.screen.query_one(CheckList).rows
        await wait_until(pilot, lambda: rows["router.port_open"].state == "fail", 5)
        rules = [f.rule for f in app.session.findings]
        assert any(r.startswith("table1.listener_up_closed") for r in rules)
        # the evidence of the failed check carries the advice
        await pilot.press("end", "e")
        await pilot.pause()
        assert "Advice 1:" in str(app.screen.query_one("#evidence").render())
        await pilot.press("a")
        await pilot.pause()
        assert type(app.screen).__name__ == "AdvisorScreen"
        n_findings = app.screen.query_one(DataTable).row_count
        assert n_findings == len(app.session.findings) >= 3
        first = app.session.findings[0]
        detail = str(app.screen.query_one("#advisor-detail").render())
        assert first.meaning.split(".")[0][:40] in detail.replace("\n", " ")
        await pilot.press("t")  # every rule, the matching ones marked
        await pilot.pause()
        assert app.screen.query_one(DataTable).row_count > n_findings
        await pilot.press("t")
        await pilot.pause()
        target = next(f.goto_step for f in app.session.findings if f.goto_step)
        await pilot.press("g")
        await pilot.pause()
        assert isinstance(app.screen, StepScreen) and app.screen.step.id == target


async def test_write_hosts_and_bashrc_with_preview_then_undo(tmp_path):
    hosts = tmp_path / "hosts"
    stock = "127.0.0.1\tlocalhost\n# keep me\n::1 ip6-localhost\n"
    hosts.write_text(stock)
    bashrc = tmp_path / "bashrc"
    bashrc.write_text("alias ll='ls -l'\nexport ROS_IP=10.10.10.1\n")
    app = make_app(tmp_path, complete_settings(), hosts_path=hosts, bashrc_path=bashrc)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("3", "w")
        await pilot.pause()
        assert type(app.screen).__name__ == "WriteScreen"
        assert "+198.51.100.2" in str(app.screen.preview.diff()).replace(" ", "").replace("\t", "")
        assert hosts.read_text() == stock  # a preview writes nothing
        await pilot.click("#write-apply")
        await pilot.pause()
        # ROS 1: the peers-only firewall is offered next, as a preview (cancelled here).
        assert type(app.screen).__name__ == "WriteScreen"
        assert "nft table inet rosnet_tui" in app.screen.plan.title
        assert "tcp dport { 22, 1024-65000 } drop" in app.screen.preview.ruleset
        await pilot.press("escape")
        await pilot.pause()
        assert isinstance(app.screen, StepScreen)
        text = hosts.read_text()
        assert "# BEGIN rosnet-tui" in text and "# keep me" in text and "sami" in text
        assert "::1 ip6-localhost" in text

        await pilot.press("4", "w")
        await pilot.pause()
        screen = app.screen
        assert type(screen).__name__ == "WriteScreen"
        await pilot.click("#write-option")  # comment out the ROS_IP line
        await pilot.pause()
        await pilot.click("#write-apply")
        await pilot.pause()
        written = bashrc.read_text()
        assert "export ROS_MASTER_URI=http://turtlebot:11311" in written
        assert "alias ll='ls -l'" in written
        assert "\nexport ROS_IP=10.10.10.1" not in written and "ROS_IP=10.10.10.1" in written

        await pilot.press("u")  # undo the last write: the bashrc
        await pilot.pause()
        await pilot.click("#write-apply")
        await pilot.pause()
        assert bashrc.read_text() == "alias ll='ls -l'\nexport ROS_IP=10.10.10.1\n"
        assert "# BEGIN rosnet-tui" in hosts.read_text()  # one apply per undo


async def test_unknown_host_key_is_shown_and_trusted_only_on_request(tmp_path):
    from cryptography.hazmat.primitives import serialization
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

    from rosnet_tui.core.results import CheckResult

    pub = Ed25519PrivateKey.generate().public_key().public_bytes(
        serialization.Encoding.OpenSSH, serialization.PublicFormat.OpenSSH).decode()
    ssh_dir = tmp_path / "ssh"
    data = {"peers": {"sami": {"ok": False, "failure": "host_key_unknown", "host_key": pub,
                               "fingerprint": "SHA256:test", "address": "198.51.100.2"}}}
    result = CheckResult("linux.ssh", "linux", Status.FAIL, "host key not trusted yet", [],
                         0.1, 3.0, data)

    async def ssh_check(ctx):
        return Outcome(Status.FAIL, "host key not trusted yet", data=data)

    specs = {"linux": [spec("linux.ssh", "linux", ssh_check)]}
    app = make_app(tmp_path, complete_settings(), specs=lambda step: specs.get(step, []),
                   context_factory=lambda s: CheckContext(
                       settings=s, ssh_options=SshOptions(ssh_dir=ssh_dir)))
    async with app.run_test(size=(80, 24)) as pilot:
        app.session.set_check_state("linux.ssh", "fail", result)
        await pilot.press("3", "k")
        await pilot.pause()
        assert type(app.screen).__name__ == "TrustKeyScreen"
        assert "SHA256:test" in str(app.screen.query_one("#trust-text").render())
        await pilot.press("enter")  # the focused default is "Do not trust"
        await pilot.pause()
        assert isinstance(app.screen, StepScreen)
        assert not (ssh_dir / "known_hosts").exists()
        await pilot.press("k")
        await pilot.pause()
        await pilot.click("#trust-yes")
        await pilot.pause()
        assert (ssh_dir / "known_hosts").read_text().split()[1:] == pub.split()


async def test_a_burst_of_keys_is_applied_in_order(tmp_path):
    """Over a laggy SSH link keys arrive in bursts: a backspace must not overtake the letters."""
    from textual import events

    from tests.test_ui_burst import settle

    app = make_app(tmp_path)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.pause()
        field = app.screen.query_one("#this-name", Input)
        field.focus()
        burst = [("t", "t"), ("u", "u"), ("r", "r"), ("x", "x"), ("backspace", None),
                 ("t", "t"), ("l", "l"), ("e", "e"), ("left", None), ("left", None),
                 ("Z", "Z")]
        for key, char in burst:  # posted at once, without waiting between them
            app.post_message(events.Key(key, char))
        await settle(app, pilot)  # every key handled (not a fixed 0.3 s: a loaded machine)
        assert field.value == "turtZle"


async def test_ros_step_shows_the_sync_state(tmp_path):
    import time

    from rosnet_tui.core.sync.status import empty_status, save_status

    app = make_app(tmp_path, complete_settings())
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("4")
        await pilot.pause()
        source = app.screen.config_source
        assert "Address sync" in source and "sync install-service" in source

    status = empty_status()
    now = time.time()
    status.update(name="turtlebot", role="master", store="folder /srv/rosnet", interval_s=60,
                  pid=None, started_at=now - 100, alive_at=now - 50, stopped_at=now - 40,
                  profile="remote")
    status["peers"] = {"sami": {"record": {"name": "sami", "role": "member",
                                           "local_ip": "192.168.1.10",
                                           "public_ip": "198.51.100.7", "seq": 3,
                                           "timestamp": "2026-11-22T02:00:00Z"},
                                "source": "folder", "seen_at": now - 45}}
    (tmp_path / "state").mkdir(exist_ok=True)
    save_status(tmp_path / "state", status)
    app = make_app(tmp_path, complete_settings())
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("4")
        await pilot.pause()
        source = app.screen.config_source
        assert "198.51.100.7" in source and "stopped" in source


async def test_ctrl_q_quits_from_the_first_run_setup(tmp_path):
    app = make_app(tmp_path)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.pause()
        assert isinstance(app.screen, SetupScreen)
        await pilot.press("q")  # typed into the name field, not a quit
        await pilot.pause()
        assert app.is_running and app.screen.query_one("#this-name", Input).value == "q"
        await pilot.press("ctrl+q")
        await pilot.pause()
    assert not app.is_running
    assert not (tmp_path / "config.toml").exists()


async def test_q_quits_from_a_step(tmp_path):
    app = make_app(tmp_path, complete_settings())
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("q")
        await pilot.pause()
    assert not app.is_running
