"""relay.tunnel's advice (the check against real sshd: tests/test_ssh_jump.py)."""

from __future__ import annotations

from rosnet_tui.core.advisor import advise
from rosnet_tui.core.checks import CheckContext
from rosnet_tui.core.checks.linux import check_ping
from rosnet_tui.core.checks.linux_chat import check_chat_in, check_chat_out
from rosnet_tui.core.config.settings_model import RelaySettings
from rosnet_tui.core.files.hosts import hosts_entries
from rosnet_tui.core.results import CheckResult, Status
from tests.builders import robot_settings


def _settings():
    s = robot_settings()
    s.ros.version = 2
    s.ros.security = "mtls"
    s.relay = RelaySettings(host="relay", ssh_user="tunnel",
                            tunnels={s.this.name: 2201, "sami": 2202})
    return s


def _ssh_case(failure: str, tcp: str | None):
    def build():
        peer = {"ok": False, "failure": failure, "fingerprint": None, "host_key": None,
                "address": None, "detail": f"{failure} on the way", "tcp": tcp, "port": 22}
        r = CheckResult("linux.ssh", "linux", Status.FAIL, "no SSH to sami", [], 0.1, 3.0,
                        {"peers": {"sami": peer}})
        return {"linux.ssh": r}, _settings()
    return build


def _case(failure: str):
    def build():
        d = {"relay": "relay", "port": 2201, "up": False, "failure": failure,
             "fingerprint": None, "detail": f"{failure} at 127.0.0.1:2201"}
        r = CheckResult("relay.tunnel", "linux", Status.FAIL, "the tunnel does not reach", [],
                        0.1, 3.0, d)
        return {"relay.tunnel": r}, _settings()
    return build


# The advisor's rule cases (tests/test_advisor_rules.py runs every rule on its case).
RELAY_TUNNEL_CASES = {"relay.tunnel.down": _case("down"),
                      "linux.ssh.relay": _ssh_case("network", "refused")}


def test_a_peer_behind_the_relay_is_not_sent_to_its_modem():
    for failure, tcp, words in (("network", "refused", "`rosnet-tui relay tunnel`"),
                                ("relay", None, "`ssh tunnel@relay`")):
        results, s = _ssh_case(failure, tcp)()
        fs = advise(results, s, strict=True)
        rules = [f.rule for f in fs]
        assert "linux.ssh.relay" in rules
        assert not {"linux.ssh.refused", "linux.peer.unreachable"} & set(rules), rules
        f = next(f for f in fs if f.rule == "linux.ssh.relay")
        assert words in f.actions[0] and "modem" not in " ".join(f.actions)
    # Without the relay, the same failure is the direct path's: the modem is named again.
    results, s = _ssh_case("network", "refused")()
    s.relay = RelaySettings()
    assert "linux.ssh.refused" in [f.rule for f in advise(results, s, strict=True)]


def test_each_cause_gets_its_own_first_action():
    firsts = {}
    for why in ("down", "other_host", "not_sshd", "relay", "timeout"):
        results, s = _case(why)()
        f = next(f for f in advise(results, s, strict=True) if f.rule == "relay.tunnel.down")
        assert f.severity == "fail" and "2201" in f.meaning
        firsts[why] = f.actions[0]
    assert "`rosnet-tui relay tunnel`" in firsts["down"]
    assert "sudo ss -tlnp" in firsts["other_host"] and "known_hosts" in firsts["relay"]
    assert len(set(firsts.values())) == 5


def test_a_passing_tunnel_says_nothing():
    results, s = _case("down")()
    results["relay.tunnel"].status = Status.PASS
    results["relay.tunnel"].data.update(up=True, failure=None)
    assert not [f for f in advise(results, s, strict=True) if f.rule.startswith("relay.")]


async def test_direct_paths_the_relay_makes_unnecessary_are_not_tested():
    ctx = CheckContext(settings=_settings(), timeout_s=1.0, upnp=False)
    ping = await check_ping(ctx)
    assert ping.status == Status.SKIP and "sami is reached through the relay relay" in ping.summary
    for chat in (check_chat_out, check_chat_in):
        out = await chat(ctx)
        assert out.status == Status.SKIP and "every router dials the relay" in out.summary


def test_no_hosts_entry_sends_a_relayed_peer_to_a_carrier_address():
    s = _settings()
    assert [e.name for e in hosts_entries(s, "remote")] == ["turtlebot"]
    assert [e.name for e in hosts_entries(s, "office")] == ["turtlebot", "sami"]   # same LAN
    s.relay = RelaySettings(host="relay")                  # a relay, but no tunnel for sami
    assert [e.name for e in hosts_entries(s, "remote")] == ["turtlebot", "sami"]
