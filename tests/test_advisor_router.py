"""The advisor's Router rules: Table 1 (listener x port test) and its causes, the local
address, the ports."""

from __future__ import annotations

from rosnet_tui.core import advisor
from rosnet_tui.core.advisor import first_failure
from tests.advisor_support import ids, local_differs, no_link, only, partial, run, text
from tests.builders import laptop_settings, put, t1


def test_table1_listener_up_open_proceeds():
    fs = run(t1(True, True))
    f = only(fs, "table1.open")
    assert f.severity == "info" and f.goto_step == "linux"
    assert "198.51.100.2:12345" in f.meaning
    assert not [x for x in fs if x.rule.startswith("table1.") and x.rule != "table1.open"]


def test_table1_listener_down_closed_starts_listener():
    fs = run(t1(False, False))
    f = only(fs, "table1.no_listener")
    assert f.severity == "fail" and f.goto_step == "router"
    assert "nc -l 12345" in text(f)
    assert not [x for x in fs if x.rule.startswith(advisor.T1)]
    assert "table1.open" not in ids(fs)


def test_table1_listener_down_closed_names_the_process_holding_the_port():
    r = t1(False, False)
    put(r, "router.port_free", "fail", in_use=True, process="python3", pid=4242)
    f = only(run(r), "table1.no_listener")
    assert "python3 (pid 4242)" in text(f)
    assert "router.port_free" in f.check_ids


def test_table1_listener_down_open_means_another_program():
    r = t1(False, True)
    put(r, "router.port_free", "fail", in_use=True, process="nginx", pid=7)
    f = only(run(r), "table1.no_listener_open")
    assert "nginx" in f.meaning and f.severity == "warn"


def test_table1_listener_up_closed_three_causes_the_connection_type_breaks_the_tie():
    r = t1(True, False)
    del r["isp.cgnat"], r["router.port_free"]          # no evidence at all
    fs = run(r)                                        # sami: a home connection
    causes = [f for f in fs if f.rule.startswith(advisor.T1)]
    assert ids(causes) == [f"{advisor.T1}.forwarding", f"{advisor.T1}.isp",
                           f"{advisor.T1}.port_in_use"]
    assert [f.order for f in causes] == [0, 1, 2]
    assert [f.goto_step for f in causes] == ["router", "isp", "router"]
    assert all(f.severity == "fail" for f in causes)
    assert "another port between 1024 and 65000" in text(causes[2])
    assert "forward TCP (and UDP if needed) 1024-65000 to 192.168.1.10" in text(causes[0])
    # the first failure of the whole list is Table 1's first cause
    assert first_failure(fs) is causes[0]
    # a carrier's line: the carrier first, when nothing else was seen
    causes = [f for f in run(r, laptop_settings(connection="telecom"))
              if f.rule.startswith(advisor.T1)]
    assert ids(causes)[:2] == [f"{advisor.T1}.isp", f"{advisor.T1}.forwarding"]


def test_table1_port_in_use_cause_names_the_process_and_comes_first():
    r = t1(True, False)
    put(r, "router.port_free", "warn", in_use=True, process="sshd", pid=99)
    put(r, "isp.cgnat", "pass", cgnat=False, double_nat=False, method="traceroute")
    # competing evidence: another port gets through (forwarding +), on a carrier's line (the
    # tie-break puts the carrier first): the held port still outweighs both
    r["router.port_open"].data["ports"].append(
        {"port": 40000, "reachable": True, "listener": True, "via": "echoip"})
    fs = run(r, laptop_settings(connection="telecom"))
    assert [f.rule for f in fs if f.rule.startswith(advisor.T1)][1] == f"{advisor.T1}.forwarding"
    f = first_failure(fs)
    assert f.rule == f"{advisor.T1}.port_in_use"
    assert "sshd (pid 99)" in f.meaning
    assert "router.port_free" in f.check_ids
    # the standalone port-in-use rule is superseded by Table 1's cause (a)
    assert "router.port_in_use" not in ids(fs)


def test_table1_cgnat_makes_isp_first_and_explains_why():
    r = t1(True, False)
    put(r, "isp.cgnat", "warn", cgnat=True, wan_ip="100.64.0.2", method="upnp", hop="100.64.0.2")
    fs = run(r)
    f = first_failure(fs)
    assert f.rule == f"{advisor.T1}.isp" and f.order == 0 and f.goto_step == "isp"
    assert "Carrier-grade NAT" in f.meaning and "100.64.0.2" in f.meaning
    assert "not the public address 198.51.100.2" in f.meaning
    assert "never reaches this modem" in f.meaning
    assert any("public IP" in a for a in f.actions)
    assert any("another connection" in a for a in f.actions)
    assert "isp.cgnat" in f.check_ids
    # the standalone carrier-NAT warning is folded into it
    assert "isp.cgnat" not in ids(fs)


def test_table1_cgnat_beats_a_changed_local_ip():
    r = t1(True, False)
    put(r, "isp.cgnat", "warn", cgnat=True, hop="100.64.0.1", method="traceroute")
    put(r, "router.local_ip", "warn", local_ip="192.168.1.23", differs=True)
    assert first_failure(run(r)).rule == f"{advisor.T1}.isp"


def test_table1_double_nat_behind_our_own_router_puts_the_inner_router_first():
    r = t1(True, False)
    put(r, "isp.cgnat", "warn", double_nat=True, wan_ip="192.168.0.2", method="upnp",
        hop="192.168.0.2")
    fs = run(r)
    f = first_failure(fs)
    assert f.rule == f"{advisor.T1}.forwarding" and f.goto_step == "router"
    assert "inner router (192.168.1.254" in f.actions[0] and "bridge" in f.actions[0]
    assert "WAN address (192.168.0.2)" in f.actions[1]
    second = [x for x in fs if x.rule.startswith(advisor.T1)][1]
    assert second.rule == f"{advisor.T1}.isp" and "provider" in second.meaning
    # the evidence, not the tie-break: on a carrier's line (tie: the carrier first) the inner
    # router still comes first
    assert first_failure(run(r, laptop_settings(connection="telecom"))).rule == \
        f"{advisor.T1}.forwarding"


def test_table1_private_nat_far_up_the_provider_puts_isp_first():
    r = t1(True, False)
    put(r, "isp.cgnat", "warn", double_nat=True, method="traceroute", hop="10.20.30.1",
        hops=["192.168.1.254", "198.51.100.1", "10.20.30.1"])
    f = first_failure(run(r))
    assert f.rule == f"{advisor.T1}.isp" and f.goto_step == "isp"
    assert "Double NAT" in f.meaning and "bridge mode" in text(f)


def test_table1_changed_local_ip_makes_forwarding_first():
    r = t1(True, False)
    put(r, "router.local_ip", "warn", local_ip="192.168.1.23", expected_ip="192.168.1.10",
        differs=True)
    fs = run(r)
    f = first_failure(fs)
    assert f.rule == f"{advisor.T1}.forwarding" and f.order == 0
    assert "from 192.168.1.10 to 192.168.1.23" in text(f)
    assert any("Reserve 192.168.1.23" in a and "DHCP" in a for a in f.actions)
    assert "router.local_ip" in f.check_ids
    assert "router.local_ip.differs" not in ids(fs)   # folded into the cause


def test_table1_no_carrier_nat_on_home_puts_forwarding_before_isp():
    r = t1(True, False)   # the path probe's hops after the modem are public: no carrier NAT
    put(r, "isp.cgnat", "pass", cgnat=False, double_nat=False, method="traceroute", hop=None,
        hops=["192.168.1.254", "198.51.100.1", "203.0.113.9"])
    causes = [f for f in run(r) if f.rule.startswith(advisor.T1)]
    # the provider moves down, below even the free port's "nothing else listens"
    assert ids(causes) == [f"{advisor.T1}.forwarding", f"{advisor.T1}.port_in_use",
                           f"{advisor.T1}.isp"]
    assert "Less likely here: the path probe's hops after the modem are public (no carrier " \
        "NAT)" in causes[2].meaning
    # the evidence, not the tie-break: on a carrier's line (tie: the carrier first) it still
    # moves the provider down
    causes = [f for f in run(r, laptop_settings(connection="telecom"))
              if f.rule.startswith(advisor.T1)]
    assert ids(causes)[0] == f"{advisor.T1}.forwarding"
    assert ids(causes)[2] == f"{advisor.T1}.isp"
    # without hop data nothing says "no carrier NAT": the tie-break alone, the carrier first
    put(r, "isp.cgnat", "pass", hops=[])
    causes = [f for f in run(r, laptop_settings(connection="telecom"))
              if f.rule.startswith(advisor.T1)]
    assert ids(causes)[0] == f"{advisor.T1}.isp" and "no carrier NAT" not in causes[0].meaning


def test_table1_corporate_keeps_the_administrator_before_forwarding():
    r = t1(True, False)   # public hops: no carrier NAT, which does not clear a corporate firewall
    put(r, "isp.cgnat", "pass", cgnat=False, double_nat=False, method="traceroute", hop=None,
        hops=["192.168.1.254", "198.51.100.1", "203.0.113.9"])
    fs = run(r, laptop_settings(connection="corporate"))
    assert "no carrier NAT" not in text(first_failure(fs))
    causes = [f for f in fs if f.rule.startswith(advisor.T1)]
    assert ids(causes)[0] == f"{advisor.T1}.isp"
    assert "network administrator" in text(causes[0])


def test_table1_other_ports_open_points_at_the_forwarding_rule():
    r = t1(True, False)
    del r["isp.cgnat"]
    r["router.port_open"].data["ports"].append(
        {"port": 40000, "reachable": True, "listener": True, "via": "echoip"})
    f = first_failure(run(r, laptop_settings(connection="telecom")))   # tie: carrier first
    assert f.rule == f"{advisor.T1}.forwarding"
    assert "40000" in f.meaning


def test_local_ip_differs_alone():
    f = only(run(local_differs()[0]), "router.local_ip.differs")
    assert "192.168.1.23" in text(f) and "DHCP" in text(f)


def test_port_partial_says_which_ports_and_ssh_separately():
    r, s = partial()
    r["router.port_open"].data["ports"][2]["reachable"] = False   # 22
    f = only(run(r, s), "router.port_open.partial")
    assert "23456" in f.meaning and "22" in f.meaning
    assert any("TCP 22" in a for a in f.actions)
    assert any("1024-65000" in a for a in f.actions)


def test_link_down_comes_first_and_explains_the_offline_checks():
    fs = run(*no_link())
    f = first_failure(fs)
    assert f.rule == "router.local_ip.no_link"
    assert "no IPv4 address on eth0" in f.meaning and "ip addr show eth0" in text(f)
    assert set(f.check_ids) == {"router.local_ip", "isp.internet", "isp.public_ip",
                                "router.port_open"}
    assert [x.rule for x in fs if x.severity == "fail"] == ["router.local_ip.no_link"]
    r, s = no_link()
    put(r, "router.local_ip", "fail", local_ip="192.168.1.10", gateway="")
    assert "no default route" in only(run(r, s), "router.local_ip.no_link").meaning
