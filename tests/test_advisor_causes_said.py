"""What a ranked cause says and where `g` goes (issue 36): every observation that moves a cause
(or is noted with no weight) is said in words that name the machine and the address that were
tried, and each of the master's causes goes to the step that fixes it."""

from __future__ import annotations

from rosnet_tui.core.advisor.evidence import Evidence
from rosnet_tui.core.advisor.ranking import (
    Cause,
    Nat,
    address_dates,
    chat_causes,
    local_ip_moved,
    master_causes,
    nat_seen,
    peer_causes,
    peer_tcp,
    rank,
    ssh_refused_first,
    table1_causes,
)
from tests.advisor_support import ssh_shut_out
from tests.builders import healthy_laptop, laptop_settings, put, res, ros2_member, t1

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
    peer = healthy_laptop()
    ssh_shut_out(peer, "refused", icmp=True, address="203.0.113.2")
    put(peer, "ros.master", "fail", reachable=False, topics=[], nodes=[], tcp="timeout")
    peer["isp.public_ip"].data.update(public_ip="198.51.100.77")
    first = peer_causes(Evidence(peer, HOME), "turtlebot")[0]
    assert first.key == "firewall" and "turtlebot's peers-only firewall" in first.sentence()
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


# --------------------------------------------------------------------------- Table 1's words
def closed(answer=None, via="peer:sami", **port_open):
    r = t1(True, False)
    data = dict(test_port=12345, public_ip_ping=None,
                ports=[{"port": 12345, "reachable": False, "listener": True, "via": via,
                        "answer": answer}])
    data.update(port_open)
    put(r, "router.port_open", "fail", **data)
    return r


def t1_said(r, s=HOME) -> dict[str, str]:
    return said(table1_causes(Evidence(r, s)))


def test_table1_says_who_tried_which_address_and_port_and_what_answered():
    assert "sami's connection to 198.51.100.2:12345 came back unreachable: the modem forwards " \
        "it to a local address" in t1_said(closed("unreachable"))["forwarding"]
    # the port test's own public address first; the checker by its name
    got = t1_said(closed("unreachable", via="echoip", public_ip="203.0.113.77"))
    assert "the port checker's connection to 203.0.113.77:12345 came back" in got["forwarding"]
    assert "the port checker's connection" in t1_said(closed("unreachable", via=None))[
        "forwarding"]
    assert "203.0.113.77:12345 was answered by another program, not our listener" in t1_said(
        closed("other", public_ip="203.0.113.77"))["forwarding"]
    token = closed("other")
    token["router.port_open"].data["ports"].append(
        {"port": 40000, "reachable": True, "listener": True, "via": "peer:sami",
         "answer": "token"})
    assert "198.51.100.2:12345 was answered by another program while the other ports reached " \
        "our listener" in t1_said(token)["port_in_use"]


def test_table1_reads_the_test_port_from_the_port_test_then_the_listener_then_the_settings():
    # the port test names its test port; the listener's port differs: the port test's counts
    r = closed("unreachable")
    put(r, "router.listener", "pass", port=23456, listening=True)
    assert ":12345 came back unreachable" in t1_said(r)["forwarding"]
    # no test port in the port test: the listener's, and the row of that port is the answer
    r["router.port_open"].data.pop("test_port")
    r["router.port_open"].data["ports"] = [
        {"port": 12345, "reachable": False, "listener": True, "via": "echoip", "answer": "other"},
        {"port": 23456, "reachable": False, "listener": True, "via": "echoip",
         "answer": "unreachable"}]
    assert ":23456 came back unreachable" in t1_said(r)["forwarding"]
    # neither: the settings' probe.port (12345 here); no row for it: no answer to read
    r["router.port_open"].data["ports"] = [{"port": 40000, "reachable": False, "via": "echoip",
                                            "answer": "refused"}]
    del r["router.listener"]
    causes = table1_causes(Evidence(r, HOME))
    assert [c.key for c in causes] == ["forwarding", "isp", "port_in_use"]
    assert not any("refused" in c.sentence() for c in causes)


def test_a_local_ip_moved_only_on_evidence():
    def moved(**li):
        r = healthy_laptop()
        put(r, "router.local_ip", "pass", **{"local_ip": "192.168.1.23", **li})
        return local_ip_moved(Evidence(r, HOME))
    assert moved(changed=False, previous_ip="192.168.1.10", differs=False) is None
    assert moved(changed=True, previous_ip="192.168.1.10", differs=False) == \
        ("192.168.1.10", "192.168.1.23")
    hist = [{"ip": "192.168.1.5"}, {"ip": "192.168.1.10"}, {"ip": "192.168.1.23"}]
    assert moved(history=hist, differs=False) == ("192.168.1.10", "192.168.1.23")
    # the history's last address is not the one now: it says nothing
    assert moved(history=hist[:2] + hist[1:2], differs=False) is None
    assert moved(history=[{"ip": "192.168.1.23"}, {"ip": "192.168.1.23"}], differs=False) is None


def test_an_inner_router_seen_on_the_path_keeps_the_wan_address_upnp_gave():
    r = healthy_laptop()
    r["isp.cgnat"].data = dict(double_nat=True, hop="10.0.0.1", wan_ip="198.51.100.7",
                               hops=["192.168.1.254", "10.0.0.1", "10.9.9.9"], method="traceroute")
    assert nat_seen(Evidence(r, HOME)) == Nat("inner", "10.0.0.1", "198.51.100.7")


# --------------------------------------------------------------------------- a peer's words
def test_a_peers_causes_say_what_was_seen_and_go_to_their_steps():
    rounds = {}
    for kind, icmp, master in (("refused", True, "connected"), ("refused", True, "refused"),
                               ("unreachable", True, None), ("timeout", True, "timeout"),
                               ("timeout", False, "refused"), ("timeout", True, "connected")):
        r = healthy_laptop()
        ssh_shut_out(r, kind, icmp=icmp, address="203.0.113.2")
        if master:
            put(r, "ros.master", "fail", reachable=master == "connected", topics=[], nodes=[],
                tcp=master)
        causes = peer_causes(Evidence(r, HOME), "turtlebot")
        assert {c.key: c.step for c in causes} == {
            "sshd": "linux", "forwarding": "router", "offline": "isp", "address": "linux",
            "firewall": "linux"}
        for c in causes:
            assert all(isinstance(w, str) and w for w in c.seen_for + c.seen_against), c
        rounds[(kind, icmp, master)] = said(causes)
    assert "203.0.113.2 answered (it refused), so it is online" in \
        rounds[("refused", True, "connected")]["offline"]
    assert "203.0.113.2 answered (it refused)" in rounds[("refused", True, "refused")]["address"]
    assert "turtlebot's master lets this machine in at the same address" in \
        rounds[("refused", True, "connected")]["firewall"]
    assert "or turtlebot itself is off (the same answer)" in \
        rounds[("unreachable", True, None)]["offline"]
    assert "turtlebot itself may be off (its modem would still answer ping)" in \
        rounds[("timeout", True, "timeout")]["offline"]
    silent = rounds[("timeout", False, "refused")]
    assert "203.0.113.2 answers (it refused the ROS master's port 11311)" in silent["address"]
    assert "203.0.113.2 answers, so it is online" in silent["offline"]
    assert "but port 22 is dropped: most likely 22 is not forwarded (it is outside the " \
        "forwarded range)" in rounds[("timeout", True, "connected")]["forwarding"]


def test_a_peers_port_and_tcp_answer_come_from_ssh_then_ping():
    r = healthy_laptop()
    ssh_shut_out(r, "refused", icmp=True, address="203.0.113.2")
    r["linux.ssh"].data["peers"]["turtlebot"]["port"] = 2222
    ev = Evidence(r, HOME)
    assert "203.0.113.2 refused port 2222" in said(peer_causes(ev, "turtlebot"))["sshd"]
    r["linux.ssh"].data["peers"]["turtlebot"].pop("tcp")      # ping's fallback answer
    assert peer_tcp(Evidence(r, HOME), "turtlebot") == "refused"
    # SSH got in after all: the refusal is not the first thing to explain
    assert ssh_refused_first(Evidence(r, HOME), "turtlebot")
    r["linux.ssh"].data["peers"]["turtlebot"]["ok"] = True
    assert not ssh_refused_first(Evidence(r, HOME), "turtlebot")


def test_ros2_a_peer_dropping_ssh_while_its_zenoh_router_answers_names_no_ros1_range():
    r = healthy_laptop()
    ssh_shut_out(r, "timeout", icmp=True, address="203.0.113.2")
    r["ros2.router"] = res("ros2.router", "pass", reachable=True)
    got = said(peer_causes(Evidence(r, ros2_member()), "turtlebot"))["forwarding"]
    assert "turtlebot's Zenoh router answers at 203.0.113.2, but port 22 is dropped: most " \
        "likely 22 is not forwarded." in got and "forwarded range" not in got


def test_causes_outside_the_tie_order_come_after_it():
    ranked = rank([Cause("extra", None, 0), Cause("isp", "isp", 0), Cause("forwarding", "router",
                                                                             0)],
                  ["forwarding", "isp"])
    assert [c.key for c in ranked] == ["forwarding", "isp", "extra"]
