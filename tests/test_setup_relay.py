"""The set-up screen asks for a relay (issue 30), and the Router step's configuration pane says
what the relay needs; at 80x24."""

from __future__ import annotations

from textual.widgets import Input, Select

from rosnet_tui.core.config.settings_model import RelaySettings
from rosnet_tui.core.exposure.router_card import build_router_card, render_router_card
from rosnet_tui.core.saved.settings import load_settings
from rosnet_tui.core.wizard.setup_form import FIELD_BY_ID, FIELDS, settings_from_form, shown
from tests.builders import ROBOT_NET, complete_settings, ros2_master
from tests.test_ui import make_app


def _values(s):
    return {f.id: f.value(s) for f in FIELDS}


def test_the_form_reads_and_writes_the_relay():
    s = ros2_master(security="mtls")
    relay = FIELD_BY_ID["relay-host"]
    assert relay.hint.startswith("Both sites behind carrier NAT or no forwarding possible")
    assert shown(relay, {"ros-version": 2}) and not shown(relay, {"ros-version": 1})
    back, problems = settings_from_form(s, {**_values(s), "relay-host": "relay"}, s.peers,
                                        "10.10.10.1")
    assert problems == [] and back.relay == RelaySettings(host="relay")
    assert relay.why("not a name!") is not None
    # Kept as it was: the other [relay] keys of the file stay with the name.
    s.relay = RelaySettings(host="relay", ssh_user="tunnel", tunnels={"turtlebot": 2201})
    back, problems = settings_from_form(s, _values(s), s.peers, "10.10.10.1")
    assert problems == [] and back.relay == s.relay
    # Blank, or ROS 1 (the field hidden): no relay, and none of its keys.
    for change in ({"relay-host": ""}, {"ros-version": 1}):
        back, _ = settings_from_form(s, {**_values(s), **change}, s.peers, "10.10.10.1")
        assert back.relay == RelaySettings(), change


def test_the_router_card_says_what_the_relay_needs():
    s = ros2_master(security="mtls")
    s.relay = RelaySettings(host="relay.example.org", zenoh_port=7448, ssh_port=2222)
    card = render_router_card(build_router_card(s, ROBOT_NET), width=76)
    needs = " ".join(card.split("The relay: what it needs", 1)[1].split("\n\n", 1)[0].split())
    for words in ("public address", "TCP 7448", "SSH open (TCP 2222", "relay serve"):
        assert words in needs, card
    assert "7448" not in card.split("1. Port forwarding", 1)[1].split("2. DHCP", 1)[0]
    assert "nothing of ROS is exposed on this modem" in " ".join(card.split())
    assert max(len(line) for line in card.splitlines()) <= 76
    s.relay = RelaySettings()
    plain = render_router_card(build_router_card(s, ROBOT_NET), width=76)
    assert "The relay" not in plain and "TCP 7447" in plain


async def test_the_set_up_screen_asks_for_a_relay_under_ros2(tmp_path):
    app = make_app(tmp_path, complete_settings())
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("s")
        await pilot.pause()
        setup = app.screen
        assert not setup.query_one("#relay-field").display     # ROS 1: no relay
        assert not setup.query_one("#relay-host-hint").display
        setup.query_one("#ros-version", Select).value = 2
        await pilot.pause()
        assert setup.query_one("#relay-field").display
        hint = str(setup.query_one("#relay-host-hint").render())
        assert "Both sites behind carrier NAT or no forwarding possible: a relay" in hint
        # A valid value leaves no empty error line under its field; a bad one says why.
        assert not setup.query_one("#ros-zenoh-port-error").display
        assert not setup.query_one("#relay-host-error").display
        setup.query_one("#relay-host", Input).value = "not a name!"
        await pilot.pause()
        error = setup.query_one("#relay-host-error")
        assert error.display and str(error.render()).strip(), error.render()
        setup.query_one("#relay-host", Input).value = "relay"
        await pilot.pause()
        assert not setup.query_one("#relay-host-error").display
        await pilot.press("ctrl+s")
        await pilot.pause()
        saved = load_settings(tmp_path / "config.toml")
        assert saved.ros.version == 2 and saved.relay.host == "relay"
        await pilot.press("2")
        await pilot.pause()
        await pilot.pause()
        card = str(app.screen.query_one("#router-card").render())
        assert "The relay: what it needs" in card and "TCP 7447" in card


def test_the_isp_step_under_a_relay_asks_no_public_ip_of_the_master():
    """The ISP step's configuration told a relayed master its connection must accept TCP 7447
    and needs a public IP; under the relay nothing reaches any site."""
    from rosnet_tui.core.wizard.steps import configure_isp_ros2

    s = ros2_master(security="mtls")
    plain = configure_isp_ros2(s)
    assert "needs a public IP" in plain and "use a relay" in plain
    s.relay = RelaySettings(host="relay.example.org")
    text = " ".join(configure_isp_ros2(s).split())
    assert "needs a public IP" not in text and "no port forwarding and no public IP" in text
    assert "Only the relay needs a public address" in text
