"""Competing evidence of equal weight (issue 36): two causes end with the same score and the
tie-break order decides. Each case here is a round the checks can give in which two observations
pointing at different causes weigh exactly the same; a weight moved by even one point (40 to 41),
or a note that should carry no weight given some, changes the ranking here. The weights are
multiples of 5, so only such exact ties can be changed by a one-point move (docs/DEVELOPMENT.md,
"Mutation score")."""

from __future__ import annotations

import pytest

from rosnet_tui.core.advisor.evidence import Evidence
from rosnet_tui.core.advisor.ranking import chat_causes, master_causes, peer_causes, table1_causes
from tests.advisor_support import ssh_shut_out
from tests.builders import healthy_laptop, laptop_settings, put, t1

HOME, TELECOM = laptop_settings(), laptop_settings(connection="telecom")


def scores(causes) -> dict[str, float]:
    return {c.key: c.score for c in causes}


# --------------------------------------------------------------------------- Table 1
def closed(answer=None, *, free: bool | None = True, reach: bool = False, nat: dict | None = None,
           moved: bool = False, token: bool = False):
    """Table 1's closed test port: how it *answer*ed; port_free's verdict (the port is *free*,
    or held by sshd; None: not run);
    another port that got through (*reach*; *token*: answered by our listener); isp.cgnat's
    data (*nat*; None: not run); a local IP the modem was not set up for (*moved*)."""
    r = t1(True, False)
    if free is None:
        del r["router.port_free"]
    else:
        put(r, "router.port_free", "pass" if free else "warn", in_use=not free,
            **({} if free else {"process": "sshd", "pid": 99}))
    ports = [{"port": 12345, "reachable": False, "listener": True, "via": "peer:sami",
              "answer": answer}]
    if reach:
        ports.append({"port": 40000, "reachable": True, "listener": True, "via": "peer:sami",
                      **({"answer": "token"} if token else {})})
    put(r, "router.port_open", "fail", test_port=12345, public_ip_ping=None, ports=ports)
    if nat is None:
        del r["isp.cgnat"]
    else:
        r["isp.cgnat"].data = nat
    if moved:
        put(r, "router.local_ip", "warn", local_ip="192.168.1.23", differs=True,
            expected_ip="192.168.1.10")
    return r


FAR = dict(double_nat=True, method="traceroute", hop="10.20.30.1",
           hops=["192.168.1.254", "198.51.100.1", "10.20.30.1"])
CGNAT = dict(cgnat=True, hop="100.64.0.1", method="traceroute")


@pytest.mark.parametrize(("round_", "tied", "home", "telecom"), [
    # refused (the modem +40, the provider -20) against a private hop far up (the provider +60)
    (closed("refused", nat=FAR), ("forwarding", "isp"),
     ["forwarding", "isp", "port_in_use"], ["isp", "forwarding", "port_in_use"]),
    # refused, and another port gets through (the modem +40 +40), against carrier NAT
    # (the provider +100 -20)
    (closed("refused", reach=True, nat=CGNAT), ("forwarding", "isp"),
     ["forwarding", "isp", "port_in_use"], ["isp", "forwarding", "port_in_use"]),
    # a local IP the modem was not set up for (the modem +60) against a private hop far up
    (closed(moved=True, nat=FAR), ("forwarding", "isp"),
     ["forwarding", "isp", "port_in_use"], ["isp", "forwarding", "port_in_use"]),
    # another program on this port while the others reach our listener (a held port +60;
    # port_free did not run) against a private hop far up (the provider +60)
    (closed("other", free=None, reach=True, token=True, nat=FAR), ("isp", "port_in_use"),
     ["isp", "port_in_use", "forwarding"], ["isp", "port_in_use", "forwarding"]),
    # a held port (+100, -10 for the connection that was not accepted) against unreachable and
    # another port reaching our listener (the modem +50 +40)
    (closed("unreachable", free=False, reach=True, token=True), ("forwarding", "port_in_use"),
     ["forwarding", "port_in_use", "isp"], ["forwarding", "port_in_use", "isp"]),
])
def test_table1_equal_evidence_for_two_causes_leaves_the_order_to_the_connection_type(
        round_, tied, home, telecom):
    got = scores(table1_causes(Evidence(round_, HOME)))
    assert got[tied[0]] == got[tied[1]], got
    assert [c.key for c in table1_causes(Evidence(round_, HOME))] == home
    assert [c.key for c in table1_causes(Evidence(round_, TELECOM))] == telecom


# --------------------------------------------------------------------------- a peer
def peer_round(kind: str, *, icmp: bool | None, master: str, dated: list | None = None,
               moved: bool = False):
    """turtlebot's SSH port answered *kind*, ping *icmp* (None: not asked), its master's port
    *master*; linux.resolve's dated rows and a name that resolves elsewhere (*moved*)."""
    r = healthy_laptop()
    r["linux.resolve"].data["names"]["turtlebot"]["dated"] = dated or []
    ssh_shut_out(r, kind, icmp=bool(icmp), address="203.0.113.2")
    if icmp is None:
        r["linux.ping"].data["peers"]["turtlebot"].pop("icmp")
    put(r, "ros.master", "fail", reachable=master == "connected", topics=[], nodes=[],
        tcp=master)
    if moved:
        r["linux.resolve"].data["names"]["turtlebot"].update(resolved="203.0.113.99",
                                                              expected="203.0.113.2")
    return r


def row(by: str, age_s: float, ip: str = "203.0.113.2") -> dict:
    return {"ip": ip, "by": by, "at": "2026-01-01T00:00:00+00:00", "age_s": age_s}


@pytest.mark.parametrize(("round_", "tied", "order"), [
    # SSH silent, the master's port refused at that address (the modem +30, the address -20)
    # against turtlebot's own newer sync record with another address (the address +50)
    (peer_round("timeout", icmp=None, master="refused",
                dated=[row("settings", 1800), row("sync", 60, "203.0.113.9")]),
     ("forwarding", "address"), ["forwarding", "address", "sshd", "offline", "firewall"]),
    # SSH silent and no ping (off-line +20) while the master's port refuses (off-line -20):
    # off-line cancels out, level with sshd
    (peer_round("timeout", icmp=False, master="refused"), ("sshd", "offline"),
     ["forwarding", "address", "sshd", "offline", "firewall"]),
    # ping not asked: the refusal alone counts against off-line (-20) and the address (-20)
    (peer_round("timeout", icmp=None, master="refused"), ("offline", "address"),
     ["forwarding", "sshd", "offline", "address", "firewall"]),
    # no ping (the address +25), the master refusing (the address -20, the modem +30), a
    # day-old address (the address -10, the modem +15), and a name that resolves elsewhere
    # (the address +50)
    (peer_round("timeout", icmp=False, master="refused", dated=[row("settings", 5 * 3600)],
                moved=True),
     ("forwarding", "address"), ["forwarding", "address", "sshd", "offline", "firewall"]),
    # SSH silent, ping answered, the master's port refused (the address -20), the address
    # confirmed minutes ago (-30) and the name resolving elsewhere (+50): the address at 0,
    # level with sshd
    (peer_round("timeout", icmp=True, master="refused", dated=[row("settings", 600)],
                moved=True),
     ("sshd", "address"), ["forwarding", "sshd", "address", "offline", "firewall"]),
    # SSH and the master's port refused (sshd +30; the address -20) and the name resolves
    # elsewhere (the address +50)
    (peer_round("refused", icmp=True, master="refused", moved=True), ("sshd", "address"),
     ["forwarding", "sshd", "address", "firewall", "offline"]),
])
def test_a_peer_equal_evidence_for_two_causes_leaves_the_order_to_the_tie_break(
        round_, tied, order):
    causes = peer_causes(Evidence(round_, HOME), "turtlebot")
    got = scores(causes)
    assert got[tied[0]] == got[tied[1]], got
    assert [c.key for c in causes] == order


def test_an_undated_address_is_a_note_with_no_weight():
    """Nothing says when the address was confirmed: said, and the address's score stays where
    the other observations put it."""
    plain = peer_causes(Evidence(peer_round("timeout", icmp=True, master="timeout"), HOME),
                        "turtlebot")
    got = {c.key: c for c in plain}
    assert any(w.startswith("nothing here says when 203.0.113.2 was last confirmed")
               for w in got["address"].seen_for)
    assert got["address"].score == got["sshd"].score == 0
    assert [c.key for c in plain] == ["forwarding", "offline", "sshd", "address", "firewall"]


# --------------------------------------------------------------------------- the chats
def test_an_inbound_refusal_weighs_the_same_for_the_modem_and_a_firewall_here():
    """turtlebot's connection to us was refused and the port test gave no verdict: the modem
    that rejects the port and a firewall here that rejects it weigh the same; the modem first."""
    r = healthy_laptop()
    put(r, "linux.chat_in", "fail", peers={"turtlebot": {"ok": False, "tcp": "refused"}})
    put(r, "router.port_open", "fail", test_port_open=None)
    causes = chat_causes(Evidence(r, HOME), "turtlebot", True)
    got = scores(causes)
    assert got["forwarding"] == got["firewall"] == 15
    assert [c.key for c in causes] == ["forwarding", "firewall", "hosts"]


def test_on_a_lan_a_refused_chat_rules_out_the_modem_and_the_peers_only_table_alike():
    r = healthy_laptop()
    put(r, "linux.chat_out", "fail", peers={"turtlebot": {"ok": False, "tcp": "refused"}})
    causes = chat_causes(Evidence(r, laptop_settings(profile="office")), "turtlebot", False)
    got = scores(causes)
    assert got["forwarding"] == got["firewall"] < got["hosts"] == 0
    assert [c.key for c in causes] == ["hosts", "forwarding", "firewall"]


# --------------------------------------------------------------------------- the master
def test_on_the_master_itself_the_modem_the_peer_and_the_firewall_are_ruled_out_alike():
    r = healthy_laptop()
    put(r, "ros.master", "fail", reachable=False, topics=[], nodes=[], tcp="refused")
    causes = master_causes(Evidence(r, laptop_settings(role="master")), "sami")
    got = scores(causes)
    assert got["forwarding"] == got["peer"] == got["firewall"] == -100
    assert [c.key for c in causes] == ["roscore", "address", "forwarding", "peer", "firewall"]


def test_a_refused_master_with_nothing_said_of_this_machines_address_gives_the_firewall_no_weight():
    r = healthy_laptop()
    put(r, "ros.master", "fail", reachable=False, topics=[], nodes=[], tcp="refused")
    ssh_shut_out(r, "refused", icmp=False)
    r["isp.public_ip"].data.pop("public_ip")
    causes = master_causes(Evidence(r, HOME), "turtlebot")
    got = {c.key: c for c in causes}
    assert got["firewall"].score == 0 and got["firewall"].seen_for
    assert [c.key for c in causes] == ["forwarding", "roscore", "peer", "address", "firewall"]


def test_another_program_answering_after_a_local_ip_change_outweighs_a_held_port():
    """A held port on this machine (+100) against another program answering at the public
    address (the modem +50) after the local IP changed (the modem +60): the forwarding that
    points at the old address first. Cutting either of the modem's weights to half (or zero)
    puts the held port first."""
    causes = table1_causes(Evidence(closed("other", free=False, moved=True), HOME))
    got = scores(causes)
    assert got["forwarding"] > got["port_in_use"] > got["isp"]
    assert [c.key for c in causes] == ["forwarding", "port_in_use", "isp"]


@pytest.mark.parametrize(("round_", "order"), [
    # silent SSH and master, ping answered, the address last confirmed 30 h ago (+10)
    (peer_round("timeout", icmp=True, master="timeout", dated=[row("settings", 30 * 3600)]),
     ["forwarding", "offline", "address", "sshd", "firewall"]),
    # SSH refused while the master answers: the peer is up (off-line -30), its table knows us
    (peer_round("refused", icmp=True, master="connected"),
     ["sshd", "forwarding", "address", "offline", "firewall"]),
    # SSH and the master's port refused alike: the modem first (+25 +35 against sshd's +30)
    (peer_round("refused", icmp=True, master="refused"),
     ["forwarding", "sshd", "firewall", "address", "offline"]),
    # SSH unreachable while the master answers: the modem's target, then the peer off (+30)
    (peer_round("unreachable", icmp=True, master="connected"),
     ["forwarding", "offline", "sshd", "address", "firewall"]),
    # SSH silent, ping answered, the master's port refused; the address 30 h old or undated
    (peer_round("timeout", icmp=True, master="refused", dated=[row("settings", 30 * 3600)]),
     ["forwarding", "sshd", "offline", "address", "firewall"]),
    (peer_round("timeout", icmp=True, master="refused"),
     ["forwarding", "sshd", "offline", "address", "firewall"]),
])
def test_a_peers_causes_in_full_order_with_their_competing_evidence(round_, order):
    """Every cause's place, not only the first: a weight zeroed or cut to half moves one of
    them here (found by zeroing and halving each weight over every round)."""
    assert [c.key for c in peer_causes(Evidence(round_, HOME), "turtlebot")] == order


def chat_round(inbound: bool, *, port_open: bool | None, moved: bool = False):
    r = healthy_laptop()
    put(r, "linux.chat_in" if inbound else "linux.chat_out", "fail",
        peers={"turtlebot": {"ok": False, "tcp": "refused"}})
    put(r, "router.port_open", "pass" if port_open else "fail", test_port_open=port_open)
    if moved:
        r["linux.resolve"].data["names"]["turtlebot"].update(resolved="203.0.113.99",
                                                              expected="203.0.113.2")
    return r


@pytest.mark.parametrize(("inbound", "round_", "order"), [
    # turtlebot reached our test port from outside (the modem -40, the name +30), then was
    # refused by name: the name, then a firewall here (+15), the modem last
    (True, chat_round(True, port_open=True), ["hosts", "firewall", "forwarding"]),
    # our connection refused (the modem +15, a firewall there +15 -10: this machine's address
    # is the one its table holds) and the name resolves elsewhere (+50)
    (False, chat_round(False, port_open=True, moved=True), ["hosts", "forwarding", "firewall"]),
])
def test_a_chats_causes_in_full_order_with_their_competing_evidence(inbound, round_, order):
    assert [c.key for c in chat_causes(Evidence(round_, HOME), "turtlebot", inbound)] == order


def master_round(tcp: str, ssh: str | None, *, public_ip: str | None = None):
    """sami's round: turtlebot's master port answered *tcp*; SSH ok (None) or its port 22
    answering *ssh*; this machine's public IP as isp.public_ip saw it."""
    r = healthy_laptop()
    put(r, "ros.master", "fail", reachable=False, topics=[], nodes=[], tcp=tcp)
    if ssh is not None:
        ssh_shut_out(r, ssh, icmp=False)
    if public_ip:
        r["isp.public_ip"].data.update(public_ip=public_ip)
    return r


@pytest.mark.parametrize(("round_", "order"), [
    # SSH gets in, the master's port refused: nothing listens (+50); this machine's address
    # moved, but SSH got in, so the peer's table knows it (the firewall -100 +70)
    (master_round("refused", None, public_ip="198.51.100.77"),
     ["roscore", "forwarding", "peer", "address", "firewall"]),
    # SSH's port refused too: the modem (+40) before roscore
    (master_round("refused", "refused"), ["forwarding", "roscore", "peer", "address", "firewall"]),
    # SSH silent: roscore (+20) before the modem (+10)
    (master_round("refused", "timeout"), ["roscore", "forwarding", "peer", "address", "firewall"]),
    # SSH gets in, the master's port silent: the forwarded range (+40)
    (master_round("timeout", None), ["forwarding", "roscore", "peer", "address", "firewall"]),
    # nothing gets through at all: the peer itself (+40) before the modem (+10)
    (master_round("timeout", "refused"), ["peer", "forwarding", "roscore", "address", "firewall"]),
])
def test_the_masters_causes_in_full_order_with_their_competing_evidence(round_, order):
    assert [c.key for c in master_causes(Evidence(round_, HOME), "turtlebot")] == order


def test_on_the_master_a_name_on_the_old_address_outweighs_a_refused_port():
    r = healthy_laptop()
    put(r, "ros.master", "fail", reachable=False, topics=[], nodes=[], tcp="refused")
    put(r, "router.local_ip", "warn", local_ip="192.168.1.77")
    causes = master_causes(Evidence(r, laptop_settings(role="master")), "sami")
    assert [c.key for c in causes] == ["address", "roscore", "forwarding", "peer", "firewall"]
