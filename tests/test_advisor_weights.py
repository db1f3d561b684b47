"""Each piece of Table 1's evidence moves the ranking on its own, against the connection type's
tie-break (home: the modem first; telecom: the carrier first) or against competing evidence: a
weight that is zeroed or cut changes a ranking here (issue 36)."""

from __future__ import annotations

import pytest

from rosnet_tui.core.addresses import is_private, is_shared
from rosnet_tui.core.advisor.evidence import Evidence
from rosnet_tui.core.advisor.ranking import (
    Nat,
    address_dates,
    chat_causes,
    dated_words,
    master_answer,
    master_causes,
    nat_seen,
    peer_causes,
    peer_check_ids,
    table1_causes,
)
from rosnet_tui.core.words import age
from tests.advisor_support import ssh_shut_out
from tests.builders import healthy_laptop, laptop_settings, put, ros2_member, t1

HOME, TELECOM = laptop_settings(), laptop_settings(connection="telecom")


def order(r, s=HOME) -> list[str]:
    return [c.key for c in table1_causes(Evidence(r, s))]


def closed(answer=None, ping=None, *others: dict):
    r = t1(True, False)
    put(r, "router.port_open", "fail", test_port=12345, public_ip_ping=ping,
        ports=[{"port": 12345, "reachable": False, "listener": True, "via": "peer:sami",
                "answer": answer}, *others])
    return r


def test_with_no_evidence_the_connection_type_decides():
    assert order(closed()) == ["forwarding", "isp", "port_in_use"]
    assert order(closed(), TELECOM) == ["isp", "forwarding", "port_in_use"]


def test_a_refusal_puts_the_modem_before_the_carrier_on_a_carriers_line():
    assert order(closed("refused"), TELECOM)[0] == "forwarding"


def test_unreachable_puts_the_modem_first_on_a_carriers_line():
    assert order(closed("unreachable"), TELECOM)[0] == "forwarding"


def test_another_program_answering_puts_forwarding_first_unless_only_this_port_is_taken():
    assert order(closed("other"), TELECOM)[0] == "forwarding"
    tok = {"port": 40000, "reachable": True, "listener": True, "via": "peer:sami",
           "answer": "token"}
    assert order(closed("other", None, tok), TELECOM)[0] == "port_in_use"


def test_silence_with_ping_is_the_modem_without_ping_the_carrier():
    assert order(closed("timeout", True), TELECOM)[0] == "forwarding"
    assert order(closed("timeout", False), HOME)[0] == "isp"


def test_a_refusal_counts_against_a_held_port_and_the_carrier():
    r = closed("refused")
    put(r, "isp.cgnat", "warn", double_nat=True, wan_ip="192.168.0.2", method="upnp",
        hop="192.168.0.2")
    # double NAT behind our own router: the inner router first, the provider (if the outer one
    # is its) second, a held port last: a service holding it would have accepted
    assert order(r) == ["forwarding", "isp", "port_in_use"]
    # also when port_free did not run (nothing says the port is free): the provider's share of
    # the double NAT (+30) outweighs the refusal's (-20)
    del r["router.port_free"]
    assert order(r) == ["forwarding", "isp", "port_in_use"]


def test_carrier_nat_outweighs_a_changed_local_ip_and_a_far_private_hop_outweighs_other_ports():
    r = closed()
    put(r, "isp.cgnat", "warn", cgnat=True, hop="100.64.0.1", method="traceroute")
    put(r, "router.local_ip", "warn", local_ip="192.168.1.23", differs=True,
        expected_ip="192.168.1.10")
    assert order(r)[0] == "isp"
    far = closed(None, None, {"port": 40000, "reachable": True, "listener": True, "via": "echoip"})
    put(far, "isp.cgnat", "warn", double_nat=True, method="traceroute", hop="10.20.30.1",
        hops=["192.168.1.254", "198.51.100.1", "10.20.30.1"])
    assert order(far)[0] == "isp"


def test_a_changed_local_ip_puts_forwarding_first_on_a_carriers_line():
    r = closed()
    put(r, "router.local_ip", "warn", local_ip="192.168.1.23", differs=True,
        expected_ip="192.168.1.10")
    assert order(r, TELECOM)[0] == "forwarding"
    r = closed()
    put(r, "router.local_ip", "pass", local_ip="192.168.1.23", changed=True,
        previous_ip="192.168.1.10")
    assert order(r, TELECOM)[0] == "forwarding"
    r = closed()
    put(r, "router.local_ip", "pass", local_ip="192.168.1.23",
        history=[{"ip": "192.168.1.10"}, {"ip": "192.168.1.23"}])
    assert order(r, TELECOM)[0] == "forwarding"
    r = closed()
    put(r, "router.local_ip", "pass", local_ip="192.168.1.10",
        history=[{"ip": "192.168.1.10"}, {"ip": "192.168.1.10"}])
    assert order(r, TELECOM)[0] == "isp"


def test_a_held_port_outweighs_other_evidence_for_forwarding():
    r = closed(None, None, {"port": 40000, "reachable": True, "listener": True, "via": "echoip"})
    put(r, "router.port_free", "warn", in_use=True, process="sshd", pid=99)
    assert order(r, TELECOM) == ["port_in_use", "forwarding", "isp"]


@pytest.mark.parametrize(("seconds", "words"), [
    (-5, "0 s"), (0.5, "0 s"), (89, "89 s"), (90, "2 min"), (5399, "90 min"), (5400, "2 h"),
    (7200, "2 h"), (36 * 3600 - 1, "36 h"), (36 * 3600, "2 days"), (86400 * 12, "12 days"),
])
def test_an_age_in_words_changes_unit_at_90_s_90_min_and_36_h(seconds, words):
    assert age(seconds) == words


@pytest.mark.parametrize(("ip", "private", "cgnat"), [
    ("10.1.2.3", True, False), ("172.16.0.1", True, False), ("172.31.255.254", True, False),
    ("172.32.0.1", False, False), ("192.168.1.1", True, False), ("198.51.100.1", False, False),
    ("100.64.0.1", False, True), ("100.127.255.254", False, True), ("100.128.0.1", False, False),
    ("not-an-address", False, False), ("", False, False),
])
def test_private_and_carrier_nat_addresses(ip, private, cgnat):
    assert is_private(ip) is private and is_shared(ip) is cgnat


def test_the_masters_answer_is_read_only_for_the_master_seen_from_another_seat():
    r = healthy_laptop()
    put(r, "ros.master", "fail", reachable=False, tcp="refused")
    ev = Evidence(r, laptop_settings())
    assert master_answer(ev, "turtlebot") == "refused"
    assert master_answer(ev, "sami") is None                   # not the master
    put(r, "ros.master", "pass", reachable=True, tcp="connected")
    assert master_answer(Evidence(r, laptop_settings()), "turtlebot") == "connected"
    s = ros2_member()
    r2 = {"ros2.router": r["ros.master"]}
    r2["ros2.router"].data = {"reachable": False, "failure": "refused"}
    assert master_answer(Evidence(r2, s), "turtlebot") == "refused"
    r2["ros2.router"].data = {"reachable": False, "failure": "tls"}
    assert master_answer(Evidence(r2, s), "turtlebot") is None   # not a network answer


# --------------------------------------------------------------------------- a peer's address
HOUR = 3600.0


def silent_peer(*dated: dict, master: str = "timeout"):
    """turtlebot drops everything and answers no ping (address +, offline +); *dated* rows."""
    r = healthy_laptop()
    r["linux.resolve"].data["names"]["turtlebot"]["dated"] = list(dated)
    ssh_shut_out(r, "timeout", icmp=False, address="203.0.113.2")
    put(r, "ros.master", "fail", reachable=master == "connected", topics=[], nodes=[],
        tcp=master)
    return r


def peer_order(r) -> list[str]:
    return [c.key for c in peer_causes(Evidence(r, laptop_settings()), "turtlebot")]


def dated(by: str, age_s: float, ip: str = "203.0.113.2") -> dict:
    return {"ip": ip, "by": by, "at": "2026-01-01T00:00:00+00:00", "age_s": age_s}


def test_the_age_of_the_address_moves_the_address_against_the_modem_and_an_offline_peer():
    # no ping: the address (+) and an offline peer (+) compete with the modem dropping it
    assert peer_order(silent_peer())[0] == "address"                       # undated
    assert peer_order(silent_peer(dated("settings", 0.2 * HOUR)))[0] == "forwarding"
    # within a day: the address loses a little, the modem gains a little; the peer being off
    # now leads, the modem before the address
    # (the firewall cause trails: nothing says this machine's address moved)
    assert peer_order(silent_peer(dated("settings", 5 * HOUR))) == [
        "offline", "forwarding", "address", "sshd", "firewall"]
    assert peer_order(silent_peer(dated("settings", 30 * HOUR)))[0] == "address"
    # a newer sync record of the peer with another address outweighs a fresh confirmation
    r = silent_peer(dated("settings", 0.5 * HOUR), dated("sync", 0.1 * HOUR, "203.0.113.9"))
    assert peer_order(r)[0] == "address"
    # an older record of another address does not
    r = silent_peer(dated("settings", 0.1 * HOUR), dated("sync", 0.5 * HOUR, "203.0.113.9"))
    assert peer_order(r)[0] == "forwarding"


def test_a_name_that_resolves_elsewhere_outweighs_the_masters_answer():
    r = silent_peer(master="connected")        # the master answers: the modem drops port 22
    assert peer_order(r)[0] == "forwarding"
    r["linux.resolve"].data["names"]["turtlebot"].update(resolved="203.0.113.99",
                                                          expected="203.0.113.2")
    assert peer_order(r)[0] == "address"


# --------------------------------------------------------------------------- the ROS master
def master_order(r, s=HOME, name: str = "turtlebot") -> list[str]:
    return [c.key for c in master_causes(Evidence(r, s), name)]


def master_down(tcp: str, ssh: str | None):
    """sami's round: the master's port answers *tcp*; SSH to turtlebot: "ok", or its port 22
    answers *ssh* ("refused", "timeout") and SSH fails on the network."""
    r = healthy_laptop()
    put(r, "ros.master", "fail", reachable=False, topics=[], nodes=[], tcp=tcp)
    if ssh != "ok":
        ssh_shut_out(r, ssh, icmp=False)
    return r


def test_a_refused_master_port_is_roscore_when_ssh_answers_and_the_modem_when_both_refuse():
    # (the tie-break puts roscore first: each case below is decided by the evidence)
    assert master_order(master_down("refused", "refused"))[0] == "forwarding"
    # refused here, SSH silent: roscore (nothing listens) before the modem, the peer last
    # (the peer's firewall, which resets strangers, trails: nothing says this machine moved)
    assert master_order(master_down("refused", "timeout")) == [
        "roscore", "forwarding", "peer", "address", "firewall"]


def test_a_silent_master_port_is_the_modem_when_ssh_answers_the_peer_when_ssh_fails_too():
    assert master_order(master_down("timeout", "ok"))[0] == "forwarding"
    assert master_order(master_down("unreachable", "ok"))[0] == "forwarding"
    assert master_order(master_down("timeout", "timeout")) == [
        "peer", "forwarding", "roscore", "address", "firewall"]


def test_a_master_name_that_leads_elsewhere_outweighs_the_rest():
    r = master_down("timeout", "ok")
    r["linux.resolve"].data["names"]["turtlebot"].update(resolved="203.0.113.99",
                                                          expected="203.0.113.2")
    assert master_order(r)[0] == "address"


# --------------------------------------------------------------------------- the chats
def chat_order(r, inbound: bool, s=HOME) -> list[str]:
    return [c.key for c in chat_causes(Evidence(r, s), "turtlebot", inbound)]


def chat_failed(inbound: bool, tcp: str | None, port_open: bool | None = None):
    r = healthy_laptop()
    cid = "linux.chat_in" if inbound else "linux.chat_out"
    put(r, cid, "fail", peers={"turtlebot": {"ok": False, "tcp": tcp}})
    put(r, "router.port_open", "pass" if port_open else "fail", test_port_open=port_open)
    return r


def test_a_refused_chat_is_the_modem_then_a_firewall():
    assert chat_order(chat_failed(False, "refused"), False) == ["forwarding", "firewall", "hosts"]


def test_a_refusal_is_the_peers_firewall_only_when_this_machines_address_moved():
    """ROS 1's peers-only table resets the addresses it does not hold: a refusal is its doing
    when this machine's public IP is not the one the peers were given; when it is, the table
    lets this machine in (the firewall moves down)."""
    r = chat_failed(False, "refused")
    same = {c.key: c for c in chat_causes(Evidence(r, HOME), "turtlebot", False)}
    assert any("lets this machine in" in w for w in same["firewall"].seen_against)
    r["isp.public_ip"].data.update(public_ip="198.51.100.77")
    moved = chat_causes(Evidence(r, HOME), "turtlebot", False)
    assert moved[0].key == "firewall" and "198.51.100.77" in moved[0].sentence()
    r["isp.public_ip"].data.pop("public_ip")              # nothing says: no weight either way
    unknown = {c.key: c for c in chat_causes(Evidence(r, HOME), "turtlebot", False)}
    assert unknown["firewall"].score == unknown["forwarding"].score


def test_an_open_test_port_clears_the_modem_and_points_at_the_name():
    # turtlebot reached our port from outside in the port test, but not by our name
    assert chat_order(chat_failed(True, None, True), True) == ["hosts", "firewall", "forwarding"]
    assert chat_order(chat_failed(True, "timeout", False), True)[0] == "forwarding"


def test_a_name_resolving_elsewhere_puts_the_hosts_entry_first():
    r = chat_failed(False, "timeout")
    r["linux.resolve"].data["names"]["turtlebot"].update(resolved="203.0.113.99",
                                                          expected="203.0.113.2")
    assert chat_order(r, False)[0] == "hosts"


def test_on_a_lan_nothing_is_forwarded_whatever_the_chat_saw():
    office = laptop_settings(profile="office")
    assert chat_order(chat_failed(False, "timeout"), False, office) == [
        "firewall", "hosts", "forwarding"]


def test_a_chat_says_who_refused_and_who_dropped():
    out = chat_causes(Evidence(chat_failed(False, "refused"), HOME), "turtlebot", False)
    assert "the connection to turtlebot was refused" in out[0].sentence()
    assert "a firewall on turtlebot that rejects would refuse it too" in out[1].sentence()
    inb = chat_causes(Evidence(chat_failed(True, "timeout", False), HOME), "turtlebot", True)
    assert "the connection to sami got no answer (dropped)" in inb[0].sentence()
    assert "the test port is closed from outside" in inb[0].sentence()
    # the other direction's result is not read
    assert "dropped" not in chat_causes(Evidence(chat_failed(True, "timeout"), HOME),
                                        "turtlebot", False)[0].sentence()


# --------------------------------------------------------------------------- dated addresses
def test_dated_rows_newest_first_and_only_well_formed_ones():
    r = silent_peer(dated("settings", 900), {"ip": "", "by": "sync", "age_s": 5},
                    {"ip": "203.0.113.7", "by": "sync", "age_s": "old"},
                    dated("sync", 900, "203.0.113.9"), dated("settings", 60))
    same, other = address_dates(Evidence(r, HOME), "turtlebot", "203.0.113.2")
    assert same["age_s"] == 60 and other is None          # 900 s is not newer than 60 s
    same, other = address_dates(Evidence(r, HOME), "turtlebot", "203.0.113.9")
    assert same["age_s"] == 900 and other["age_s"] == 60


def test_dated_words_name_their_source():
    assert dated_words("turtlebot", dated("sync", 60)) == (
        "203.0.113.2 was confirmed 60 s ago (turtlebot's own sync record)")
    assert dated_words("turtlebot", dated("settings", 60)).endswith("(settings saved)")
    assert dated_words("turtlebot", dated("dns", 60)).endswith("(dns)")


def test_an_hour_old_address_is_no_longer_fresh_and_a_day_old_one_is_old():
    assert peer_order(silent_peer(dated("settings", HOUR))) == [
        "offline", "forwarding", "address", "sshd", "firewall"]
    assert peer_order(silent_peer(dated("settings", 24 * HOUR)))[0] == "address"


def test_the_port_and_address_a_peer_finding_names():
    r = silent_peer()
    r["linux.ssh"].data["peers"]["turtlebot"].pop("port", None)
    r["linux.ping"].data["peers"]["turtlebot"]["port"] = 2222
    r["linux.ssh"].data["peers"]["turtlebot"]["address"] = "203.0.113.5"
    put(r, "ros.master", "pass", reachable=True, tcp="connected")
    first = peer_causes(Evidence(r, HOME), "turtlebot")[0]
    assert "answers at 203.0.113.5, but port 2222 is dropped" in first.sentence()


def test_node_uris_joins_a_peer_finding_when_ssh_could_not_reach_the_peer():
    r = silent_peer()
    assert peer_check_ids(Evidence(r, HOME), "turtlebot") == [
        "linux.ping", "linux.ssh", "linux.chat_out", "linux.chat_in"]
    put(r, "ros.node_uris", "warn", unreachable=[], nodes=[{"name": "/x"}])
    assert "ros.node_uris" in peer_check_ids(Evidence(r, HOME), "turtlebot")
    r["linux.ssh"].data["peers"]["turtlebot"]["failure"] = "auth"
    assert "ros.node_uris" not in peer_check_ids(Evidence(r, HOME), "turtlebot")


def test_every_observation_that_moves_a_cause_is_said_in_words():
    """Each score change carries its words (the findings quote them): none is left blank."""
    office = laptop_settings(profile="office")
    rounds = [peer_causes(Evidence(silent_peer(dated("settings", age)), HOME), "turtlebot")
              for age in (0.2 * HOUR, 5 * HOUR, 30 * HOUR)]
    rounds.append(peer_causes(Evidence(silent_peer(dated("settings", 0.5 * HOUR),
                                                   dated("sync", 60, "203.0.113.9")), HOME),
                              "turtlebot"))
    r = chat_failed(False, "timeout")
    r["linux.resolve"].data["names"]["turtlebot"].update(resolved="203.0.113.99",
                                                          expected="203.0.113.2")
    rounds += [chat_causes(Evidence(r, office), "turtlebot", False),
               chat_causes(Evidence(chat_failed(True, "refused", True), HOME), "turtlebot", True),
               chat_causes(Evidence(chat_failed(True, "timeout", False), HOME), "turtlebot",
                           True)]
    master = healthy_laptop()
    put(master, "ros.master", "fail", reachable=False, topics=[], nodes=[], tcp="refused")
    rounds.append(master_causes(Evidence(master, laptop_settings(role="master")), "sami"))
    for causes in rounds:
        for c in causes:
            assert all(isinstance(w, str) and w for w in c.seen_for + c.seen_against), c
            assert c.sentence() == "" or c.sentence().endswith(".")
    assert sum(len(c.evidence()) for causes in rounds for c in causes) >= 20


# --------------------------------------------------------------------------- NAT on the way out
def nat(**data) -> Nat:
    r = healthy_laptop()
    if data:
        r["isp.cgnat"].data = data
    else:
        del r["isp.cgnat"]
    return nat_seen(Evidence(r, HOME))


def test_what_isp_cgnat_saw_is_read_as_carrier_inner_far_or_none():
    assert nat() == Nat("")
    assert nat(cgnat=True, wan_ip="100.64.0.2", method="upnp") == \
        Nat("cgnat", "100.64.0.2", "100.64.0.2")
    assert nat(double_nat=True, wan_ip="192.168.0.2", method="upnp") == \
        Nat("inner", "192.168.0.2", "192.168.0.2")
    assert nat(double_nat=True, wan_ip="192.168.0.2", hop="192.168.0.1", method="upnp") == \
        Nat("inner", "192.168.0.1", "192.168.0.2")
    hops = ["192.168.1.254", "10.0.0.1", "10.9.9.9"]
    assert nat(double_nat=True, hop="10.0.0.1", hops=hops, method="traceroute") == \
        Nat("inner", "10.0.0.1", None)
    assert nat(double_nat=True, hop="10.9.9.9", hops=hops, wan_ip="198.51.100.7",
               method="traceroute") == Nat("far", "10.9.9.9", "198.51.100.7")
    assert nat(double_nat=True, hop="100.64.0.1", hops=["192.168.1.254", "100.64.0.1"],
               method="traceroute") == Nat("far", "100.64.0.1", None)


def test_no_nat_is_said_only_from_upnp_or_public_hops():
    up = nat(wan_ip="198.51.100.2", method="upnp")
    assert (up.kind, up.hop, up.wan_ip) == ("", None, "198.51.100.2")
    assert "WAN address is the public IP 198.51.100.2" in up.no_nat
    assert nat(wan_ip="198.51.100.2", method="traceroute") == Nat("")
    tr = nat(method="traceroute", hops=["192.168.1.254", "198.51.100.1"])
    assert (tr.kind, tr.hop, tr.wan_ip) == ("", None, None) and "no carrier NAT" in tr.no_nat
    assert nat(method="traceroute", hops=["192.168.1.254"]) == Nat("")
