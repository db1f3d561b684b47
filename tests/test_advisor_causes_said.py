"""What a ranked cause says and where `g` goes (issue 36): every observation that moves a cause
(or is noted with no weight) is said in words that name the machine and the address that were
tried, and each of the master's causes goes to the step that fixes it."""

from __future__ import annotations

from rosnet_tui.core.advisor.evidence import Evidence
from rosnet_tui.core.advisor.ranking import (
    address_dates,
    chat_causes,
    master_causes,
    peer_causes,
)
from tests.advisor_support import ssh_shut_out
from tests.builders import healthy_laptop, laptop_settings, put, ros2_member

HOME = laptop_settings()


def refused_master(ssh: str | None, address: str | None = None):
    """sami's round: turtlebot's master port refused; SSH "ok" (None) or its port 22
    answering *ssh*; linux.ssh's data with the *address* it dialled, when given."""
    r = healthy_laptop()
    put(r, "ros.master", "fail", reachable=False, topics=[], nodes=[], tcp="refused")
    if ssh is not None:
        ssh_shut_out(r, ssh, icmp=False)
    if address is not None:
        r["linux.ssh"].data["peers"]["turtlebot"]["address"] = address
    return r


def said(causes) -> dict[str, str]:
    return {c.key: c.sentence() for c in causes}


def test_the_masters_causes_name_the_address_ssh_dialled_or_the_settings_one():
    dialled = said(master_causes(Evidence(refused_master(None, "203.0.113.5"), HOME),
                                 "turtlebot"))
    assert "turtlebot answers SSH at 203.0.113.5 but refuses port 11311" in dialled["roscore"]
    # linux.ssh did not say which address: the one the settings give turtlebot
    settings = said(master_causes(Evidence(refused_master(None), HOME), "turtlebot"))
    assert "turtlebot answers SSH at 203.0.113.2 but refuses port 11311" in settings["roscore"]


def test_the_masters_causes_go_to_the_step_that_fixes_them():
    causes = master_causes(Evidence(refused_master("timeout"), HOME), "turtlebot")
    assert {c.key: c.step for c in causes} == {
        "roscore": "ros", "forwarding": "router", "address": "linux", "peer": "linux",
        "firewall": "linux"}


def test_a_refusal_blamed_on_the_peers_firewall_names_that_peer():
    r = healthy_laptop()
    put(r, "linux.chat_out", "fail", peers={"turtlebot": {"ok": False, "tcp": "refused"}})
    r["isp.public_ip"].data.update(public_ip="198.51.100.77")
    first = chat_causes(Evidence(r, HOME), "turtlebot", False)[0]
    assert first.key == "firewall"
    assert "turtlebot's peers-only firewall lets in the addresses it was given" in \
        first.sentence()
    master = refused_master("timeout")
    master["isp.public_ip"].data.update(public_ip="198.51.100.77")
    first = master_causes(Evidence(master, HOME), "turtlebot")[0]
    assert first.key == "firewall" and "turtlebot's peers-only firewall" in first.sentence()


def test_every_observation_on_the_masters_and_a_peers_causes_is_said():
    """Each branch of the master's and a peer's ranking, words checked: none blank."""
    rounds = []
    for ssh in (None, "refused", "timeout"):
        rounds.append(master_causes(Evidence(refused_master(ssh), HOME), "turtlebot"))
    silent = refused_master("timeout")
    put(silent, "ros.master", "fail", reachable=False, topics=[], nodes=[], tcp="timeout")
    silent["linux.resolve"].data["names"]["turtlebot"].update(resolved="203.0.113.99",
                                                               expected="203.0.113.2")
    rounds.append(master_causes(Evidence(silent, HOME), "turtlebot"))
    unknown = refused_master("refused")
    unknown["isp.public_ip"].data.pop("public_ip")            # nothing says: a note
    rounds.append(master_causes(Evidence(unknown, HOME), "turtlebot"))
    rounds.append(peer_causes(Evidence(refused_master("refused"), HOME), "turtlebot"))
    r2 = healthy_laptop()                                      # ROS 2: no peers-only table
    ssh_shut_out(r2, "refused", icmp=True)
    rounds.append(peer_causes(Evidence(r2, ros2_member()), "turtlebot"))
    for causes in rounds:
        for c in causes:
            assert all(isinstance(w, str) and w for w in c.seen_for + c.seen_against), c
    words = [w for causes in rounds for c in causes for w in c.seen_for + c.seen_against]
    for expected in ("its SSH port alike", "nothing listens there, or the modem",
                     "can refuse it too", "got no answer either", "resolves to 203.0.113.99",
                     "refuses at once; this was no refusal", "lets this machine in on SSH",
                     "refuses (resets) every address it does not hold",
                     "no peers-only firewall on ROS 1 here"):
        assert any(expected in w for w in words), expected


def test_another_address_of_the_same_age_is_not_newer():
    r = healthy_laptop()
    r["linux.resolve"].data["names"]["turtlebot"]["dated"] = [
        {"ip": "203.0.113.2", "by": "settings", "age_s": 600},
        {"ip": "203.0.113.9", "by": "sync", "age_s": 600}]
    same, other = address_dates(Evidence(r, HOME), "turtlebot", "203.0.113.2")
    assert same["ip"] == "203.0.113.2" and other is None
