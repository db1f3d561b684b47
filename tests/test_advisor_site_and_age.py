"""Issue 21's two advisor defects, over results shaped as the checks report them.

1. ROS 2: a member finds the master's Zenoh port refused and the master's SSH refused or
   unanswered: the whole site takes no connection, so the first advice is the master's modem or
   provider, worded as what was seen (a refused port alone cannot tell "nothing listens" from
   "the modem refuses").
2. ROS 1, a peer whose modem drops everything (no ping, no TCP answer): the age of the address
   ranks "the address is stale" against "the modem drops it": confirmed minutes ago, the modem
   leads; old, undated, or contradicted by a newer sync record, the address leads. The age comes
   from linux.resolve's declared ``dated`` rows (the check module is never imported here).

The lab shows the same end to end (tests/test_advisor_site_and_age_lab.py).
"""

from __future__ import annotations

import time

import pytest

from rosnet_tui.core.advisor import advise, first_failure
from rosnet_tui.core.checks import CheckContext
from rosnet_tui.core.checks.data import undeclared
from rosnet_tui.core.config.paths import Paths
from rosnet_tui.core.files.hosts import hosts_entries
from rosnet_tui.core.results import CheckResult, Status
from rosnet_tui.core.saved.settings import load_settings, render_settings, save_settings
from tests.advisor_support import ids, run, ssh_shut_out
from tests.builders import healthy_laptop, laptop_settings, put
from tests.builders import ros2_member as member

MIN, DAY = 60.0, 86400.0


# --------------------------------------------------------------------------- 1. ROS 2 site
def r2(cid: str, status: str, data: dict, step: str = "ros") -> CheckResult:
    return CheckResult(cid, step, Status(status), f"{cid} {status}", [], 0.1, 3.0, data)


def ros2_member_round(ssh_tcp: str | None, ssh_failure: str | None, ping: bool | None
                      ) -> list[CheckResult]:
    """A member's full round: the Zenoh port refused; SSH to the master as given."""
    ssh_ok = ssh_tcp == "connected" and ssh_failure is None
    return [
        r2("linux.ping", "pass" if ping or ssh_ok else "fail",
           {"peers": {"turtlebot": {"icmp": ping, "tcp22": ssh_tcp == "connected",
                                    "tcp": ssh_tcp, "port": 22}}}, "linux"),
        r2("linux.ssh", "pass" if ssh_ok else "fail",
           {"peers": {"turtlebot": {"ok": ssh_ok, "failure": ssh_failure, "tcp": ssh_tcp,
                                    "port": 22, "address": "203.0.113.2"}}}, "linux"),
        r2("ros2.router", "fail", {"role": "member", "failure": "refused", "reachable": False,
                                   "endpoint": "tcp/turtlebot:7447", "address": "203.0.113.2"}),
        r2("ros2.graph", "fail", {"missing": ["turtlebot"]}),
        r2("ros2.pubsub_out", "fail", {"ok": False, "failed_hop": "master_router",
                                       "peer": "turtlebot"}),
    ]


@pytest.mark.parametrize("ssh_tcp, ssh_failure, ping, said", [
    ("refused", "network", True, "refused too"),          # a modem (or carrier) sending resets
    ("timeout", "network", False, "did not answer either"),  # the carrier-grade NAT case
    (None, "timeout", None, "did not answer either"),
])
def test_zenoh_refused_and_ssh_shut_out_leads_with_the_masters_modem_or_provider(
        ssh_tcp, ssh_failure, ping, said):
    fs = advise(ros2_member_round(ssh_tcp, ssh_failure, ping), member(), strict=True)
    first = first_failure(fs)
    assert first.rule == "ros2.port.not_forwarded" and first.goto_step == "router", ids(fs)
    # worded as what was seen, then what it points at
    assert first.meaning.startswith(f"turtlebot's Zenoh port (203.0.113.2:7447) refused sami's "
                                    f"connection and its SSH port 22 {said}: "), first.meaning
    assert "modem or its provider" in first.meaning and "carrier-grade NAT" in first.meaning
    assert "isp.cgnat" in first.actions[0] and "TCP 7447" in first.actions[1]
    assert "No Zenoh router runs" not in " ".join(f.meaning for f in fs)
    assert "ros2.router.not_running" not in ids(fs) and "ros2.link.missing" not in ids(fs)
    # the Linux finding about the same peer does not blame sshd
    linux = [f for f in fs if f.rule in ("linux.ssh.refused", "linux.peer.unreachable")]
    assert linux and all("most likely sshd" not in f.meaning for f in linux), linux
    assert all(f.goto_step == "router" for f in linux)


def test_zenoh_refused_with_ssh_answering_still_points_at_the_router_hedged():
    fs = advise(ros2_member_round("connected", None, True), member(), strict=True)
    first = first_failure(fs)
    assert first.rule == "ros2.router.not_running", ids(fs)
    assert first.meaning.startswith("A connection to tcp/turtlebot:7447 (203.0.113.2) was "
                                    "refused: most likely no Zenoh router listens on turtlebot")
    assert "answers SSH at the same address" in first.meaning


def test_zenoh_refused_without_ssh_evidence_says_a_refusal_alone_cannot_tell():
    """The ROS step alone (no linux.* results): the router first, with the doubt said."""
    fs = advise(ros2_member_round("refused", "network", True)[2:], member(), strict=True)
    first = first_failure(fs)
    assert first.rule == "ros2.router.not_running", ids(fs)
    assert "a refusal alone cannot tell that from turtlebot's modem refusing" in first.meaning


def test_the_master_itself_says_nothing_listens_here():
    from tests.builders import ros2_master as master
    fs = advise([r2("ros2.router", "fail", {"role": "master", "listen_problem": "not_running",
                                            "listening": [], "reachable": False})],
                master(), strict=True)
    assert first_failure(fs).meaning.startswith("Nothing listens on TCP 7447 on turtlebot")


# --------------------------------------------------------------------------- 2. address age
def silent_peer(*dated: dict) -> dict[str, CheckResult]:
    """sami's round: turtlebot's modem drops everything (no ping, no TCP); *dated* rows."""
    r = healthy_laptop()
    r["linux.resolve"].data["names"]["turtlebot"]["dated"] = list(dated)
    ssh_shut_out(r, "timeout", icmp=False, address="203.0.113.2")
    put(r, "ros.master", "fail", reachable=False, topics=[], nodes=[], tcp="timeout")
    return r


def row(by: str, age_s: float, ip: str = "203.0.113.2") -> dict:
    at = time.strftime("%Y-%m-%dT%H:%M:%S+00:00", time.gmtime(time.time() - age_s))
    return {"ip": ip, "by": by, "at": at, "age_s": age_s}


def test_undated_silent_peer_keeps_the_stale_address_first_and_says_it_is_undated():
    first = first_failure(run(silent_peer()))
    assert first.rule == "linux.peer.unreachable" and first.goto_step == "linux"
    assert "most likely 203.0.113.2 is not turtlebot's address any more" in first.meaning
    assert "nothing here says when 203.0.113.2 was last confirmed" in first.meaning


@pytest.mark.parametrize("by, words", [("settings", "settings saved"),
                                       ("sync", "turtlebot's own sync record")])
def test_address_confirmed_minutes_ago_puts_forwarding_or_firewall_first(by, words):
    first = first_failure(run(silent_peer(row(by, 3 * MIN))))
    assert first.rule == "linux.peer.unreachable" and first.goto_step == "router", first
    assert ("most likely turtlebot's modem does not forward port 22 to turtlebot (or its "
            "firewall drops it)") in first.meaning
    assert f"203.0.113.2 was confirmed 3 min ago ({words})" in first.meaning
    assert first.actions[0].startswith("Check that turtlebot's modem forwards TCP 22")
    assert "firewall" in first.actions[0]
    assert any("getent hosts turtlebot" in a for a in first.actions[1:])   # still listed


def test_address_confirmed_days_ago_keeps_the_address_first_with_its_age():
    first = first_failure(run(silent_peer(row("settings", 40 * DAY))))
    assert first.goto_step == "linux"
    assert "most likely 203.0.113.2 is not turtlebot's address any more" in first.meaning
    assert "203.0.113.2 was last confirmed 40 days ago (settings saved)" in first.meaning


def test_the_newest_confirmation_counts():
    first = first_failure(run(silent_peer(row("settings", 40 * DAY), row("sync", 5 * MIN))))
    assert first.goto_step == "router"
    assert "203.0.113.2 was confirmed 5 min ago (turtlebot's own sync record)" in first.meaning


def test_a_newer_sync_record_with_another_address_puts_the_address_first():
    first = first_failure(run(silent_peer(row("settings", 2 * MIN),
                                          row("sync", 1 * MIN, ip="203.0.113.9"))))
    assert first.goto_step == "linux"
    assert "most likely 203.0.113.2 is not turtlebot's address any more" in first.meaning
    assert "turtlebot's own sync record of 60 s ago gives 203.0.113.9" in first.meaning


def test_age_does_not_override_a_refusal():
    """A refusal means the address answers: the address is not the suspect, whatever its age."""
    r = silent_peer(row("settings", 40 * DAY))
    r["linux.ssh"].data["peers"]["turtlebot"]["tcp"] = "refused"
    first = first_failure(run(r))
    assert first.rule == "linux.ssh.refused"
    assert "not turtlebot's address any more" not in first.meaning


# --------------------------------------------------------------------------- the producer
def test_linux_resolve_dates_a_peer_by_the_settings_file_and_the_sync_record(tmp_path):
    """What linux.resolve adds per peer (its address_dates; the resolver itself is not asked
    here, so no name leaves the machine): a settings file saved now, and a sync record of
    turtlebot's applied two hours ago."""
    from rosnet_tui.core.checks.linux import address_dates
    from rosnet_tui.core.saved.sync_applied import save_applied
    from rosnet_tui.core.saved.sync_records import new_record

    path = tmp_path / "config.toml"
    s = laptop_settings()
    save_settings(s, path)
    assert s.saved_at is not None and abs(s.saved_at - time.time()) < 5
    loaded = load_settings(path)
    assert loaded is not None and loaded.saved_at == s.saved_at and loaded == s
    state = tmp_path / "state"
    ctx = CheckContext(settings=loaded, paths=Paths(state_dir=state))
    assert [d["by"] for d in address_dates(ctx, hosts_entries(loaded))["turtlebot"]] == \
        ["settings"]                                          # no sync record yet
    save_applied(state, {"turtlebot": new_record("turtlebot", local_ip="10.10.10.1",
                                                 public_ip="203.0.113.2", role="master",
                                                 now=time.time() - 7200)})
    dated = address_dates(ctx, hosts_entries(loaded))
    assert set(dated) == {"turtlebot"}                        # our own name is not dated
    rows = dated["turtlebot"]
    assert [d["by"] for d in rows] == ["settings", "sync"], rows
    assert rows[0]["ip"] == rows[1]["ip"] == "203.0.113.2"
    assert rows[0]["age_s"] < 10 and 7190 < rows[1]["age_s"] < 7300
    data = {"names": {"turtlebot": {"resolved": "203.0.113.2", "expected": "203.0.113.2",
                                    "dated": rows}}, "wrong": [], "loopback": []}
    assert not undeclared("linux.resolve", data)
    # a LAN profile: the settings date the LAN address; sync records (public IPs) do not apply
    lan = CheckContext(settings=laptop_settings(profile="office", office_ip="10.0.0.5"),
                       paths=Paths(state_dir=state))
    assert address_dates(lan, hosts_entries(lan.settings))["turtlebot"] == []


def test_settings_built_in_memory_are_not_dated(tmp_path):
    s = laptop_settings()
    assert s.saved_at is None
    assert "saved_at" not in render_settings(s)


def test_the_wizard_dates_its_settings_when_it_saves_them_or_finds_them_saved(tmp_path):
    """The wizard's save (WizardSession.save_settings): a new file takes the time of the save;
    settings the file already holds take the file's time (it is not rewritten)."""
    import dataclasses
    import os

    from rosnet_tui.core.wizard.session import WizardSession

    path = tmp_path / "config.toml"
    session = WizardSession(laptop_settings(), Paths(config_path=path, state_dir=tmp_path))
    fresh = laptop_settings()
    session.save_settings(fresh)
    assert fresh.saved_at == os.stat(path).st_mtime and session.settings.saved_at is not None
    os.utime(path, (time.time() - 40 * DAY,) * 2)
    same = dataclasses.replace(laptop_settings(), saved_at=None)
    session.save_settings(same)                           # the file already says this
    assert same.saved_at == os.stat(path).st_mtime < time.time() - 39 * DAY
