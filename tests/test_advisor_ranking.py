"""Causes ranked by the evidence (issue 14): for each situation seen in the field, the results the
checks record (their declared data), and the first advice the technician reads: its rule, what
it says was observed, and the step `g` goes to.

The lab reproduces the same situations end to end (tests/test_advisor_ranking_lab.py).
"""

from __future__ import annotations

from rosnet_tui.core.advisor import T1, first_failure
from rosnet_tui.core.results import CheckResult, Status
from tests.advisor_support import ids, run, ssh_shut_out, text
from tests.builders import (
    healthy_laptop,
    healthy_robot,
    laptop_settings,
    put,
    robot_settings,
)


def closed_port(r: dict[str, CheckResult], answer: str | None, via: str = "peer:sami",
                ping: bool | None = None) -> dict[str, CheckResult]:
    """Table 1's "listener up, checker says Closed", with how the test port answered."""
    put(r, "router.listener", "pass", listening=True)
    put(r, "router.port_open", "fail", test_port=12345, test_port_open=False, public_ip_ping=ping,
        ports=[{"port": 12345, "reachable": False, "listener": True, "via": via,
                "answer": answer}])
    return r


def router_step_only(r: dict[str, CheckResult]) -> dict[str, CheckResult]:
    """What the wizard's Router step runs: no ISP checks in the round."""
    return {k: v for k, v in r.items() if k.startswith("router.")}


def causes(fs) -> list[str]:
    return [f.rule.rsplit(".", 1)[1] for f in fs if f.rule.startswith(T1)]


# --------------------------------------------------------------------------- no forwarding
def test_refused_at_the_public_address_puts_forwarding_before_the_carrier():
    """Seen: the robot's modem without forwarding, the Router step on the robot (telecom), the
    peer's connection refused: the carrier came first. A refusal means the modem answers."""
    r = router_step_only(closed_port(healthy_robot(), "refused"))
    fs = run(r, robot_settings())
    first = first_failure(fs)
    assert first.rule == f"{T1}.forwarding" and first.goto_step == "router"
    assert "was refused" in first.meaning and "the modem is online" in first.meaning
    assert causes(fs) == ["forwarding", "isp", "port_in_use"]
    isp = next(f for f in fs if f.rule == f"{T1}.isp")
    assert "Less likely here: a refusal usually comes from the modem itself" in isp.meaning


def test_silence_with_a_pinging_public_address_puts_forwarding_first_even_on_telecom():
    r = router_step_only(closed_port(healthy_robot(), "timeout", ping=True))
    first = first_failure(run(r, robot_settings()))
    assert first.rule == f"{T1}.forwarding"
    assert "answers ping: the modem is online and drops it" in first.meaning


def test_silence_and_no_ping_on_telecom_puts_the_carrier_first():
    r = router_step_only(closed_port(healthy_robot(), "timeout", ping=False))
    fs = run(r, robot_settings())
    assert causes(fs)[0] == "isp" and first_failure(fs).goto_step == "isp"
    assert "does not answer ping either" in first_failure(fs).meaning


def test_no_forwarding_seen_from_the_laptop_modem_refusing_everything():
    """The other seat: SSH and the master's port both refused at the robot's public IP."""
    r = healthy_laptop()
    ssh_shut_out(r, "refused", address="203.0.113.2")
    put(r, "ros.master", "fail", reachable=False, topics=[], nodes=[], tcp="refused")
    fs = run(r)
    first = first_failure(fs)
    assert first.rule == "linux.ssh.refused", ids(fs)
    assert first.goto_step == "router"
    assert "refuses the ROS master's port 11311 as well" in first.meaning
    assert first.actions[0].startswith("Check that turtlebot's modem forwards TCP 22")
    assert "linux.peer.unreachable" not in ids(fs)
    master = next(f for f in fs if f.rule == "ros.master.unreachable")
    assert master.goto_step == "router"


def test_no_forwarding_seen_from_the_laptop_modem_dropping():
    r = healthy_laptop()
    ssh_shut_out(r, "timeout")
    put(r, "ros.master", "fail", reachable=False, topics=[], nodes=[], tcp="timeout")
    first = first_failure(run(r))
    assert first.rule == "linux.peer.unreachable" and first.goto_step == "router"
    assert "modem is online" in first.meaning
    assert "most likely turtlebot's modem does not forward port 22" in first.meaning


# --------------------------------------------------------------------------- stale DHCP address
def _history(*ips: str) -> list[dict[str, str]]:
    return [{"ip": ip, "first_seen": f"2026-0{i + 1}-01T00:00:00+00:00",
             "last_seen": f"2026-0{i + 1}-02T00:00:00+00:00"} for i, ip in enumerate(ips)]


def test_new_dhcp_lease_without_local_ip_in_the_settings_puts_forwarding_first():
    """The documented settings have no local_ip: the check fills in the new address, so only
    the history shows that the modem was set up for the old one."""
    r = closed_port(healthy_robot(), "timeout", ping=True)
    put(r, "router.local_ip", "warn", local_ip="10.10.10.5", expected_ip="10.10.10.5",
        differs=False, previous_ip="10.10.10.1", changed=True,
        history=_history("10.10.10.1", "10.10.10.5"))
    fs = run(r, robot_settings(connection="telecom", local_ip="10.10.10.5"))
    first = first_failure(fs)
    assert first.rule == f"{T1}.forwarding" and first.goto_step == "router"
    assert "from 10.10.10.1 to 10.10.10.5" in text(first)
    assert "the local IP is 10.10.10.5 now, the modem was set up for 10.10.10.1" in first.meaning
    assert "router.local_ip.differs" not in ids(fs)
    # a later run (changed is False again): the history still tells
    put(r, "router.local_ip", "pass", previous_ip="10.10.10.5", changed=False)
    assert first_failure(run(r, robot_settings(local_ip="10.10.10.5"))).rule == f"{T1}.forwarding"


def test_new_dhcp_lease_seen_from_the_laptop_names_the_forwarding_target():
    """The robot's modem forwards to a local address where nobody is: an ICMP error comes back."""
    r = healthy_laptop()
    ssh_shut_out(r, "unreachable")
    first = first_failure(run(r))
    assert first.rule == "linux.peer.unreachable" and first.goto_step == "router"
    assert "local address where no machine answers" in first.meaning


def test_master_seat_own_name_on_the_old_address_points_at_the_hosts_line():
    r = healthy_robot()
    put(r, "router.local_ip", "warn", local_ip="10.10.10.5", differs=True)
    put(r, "ros.master", "fail", reachable=False, topics=[], nodes=[], tcp="timeout")
    f = next(f for f in run(r, robot_settings()) if f.rule == "ros.master.unreachable")
    assert f.goto_step == "linux"
    assert "turtlebot resolves to 10.10.10.1, but this machine's address is 10.10.10.5" \
        in f.meaning
    assert f.actions[0].startswith("Map turtlebot to this machine's address")


# --------------------------------------------------------------------------- private double NAT
def test_travel_router_behind_the_providers_modem_names_the_inner_router_first():
    """The path probe: hop 1 the robot's own (travel) router, hop 2 a private address."""
    r = closed_port(healthy_robot(), "timeout", ping=True)
    put(r, "isp.cgnat", "warn", method="traceroute", cgnat=False, double_nat=True,
        hop="192.168.0.1", hops=["10.10.10.254", "192.168.0.1", "203.0.113.1"])
    fs = run(r, robot_settings())
    first = first_failure(fs)
    assert first.rule == f"{T1}.forwarding" and first.goto_step == "router"
    assert "Two routers of your own" in first.meaning
    assert first.actions[0].startswith("On the inner router (10.10.10.254, turtlebot's gateway)")
    assert "forward TCP (and UDP) 1024-65000 to 10.10.10.1" in first.actions[0]
    assert "bridge" in first.actions[0]
    assert first.actions[1].startswith("On the outer router (192.168.0.1)")
    assert causes(fs)[1] == "isp"
    assert "isp.cgnat" not in ids(fs)       # folded into Table 1


# --------------------------------------------------------------------------- LAN profiles
def test_lan_profile_has_no_table1_and_no_modem_advice():
    r = healthy_laptop()
    r["router.port_open"] = CheckResult(
        "router.port_open", "router", Status.SKIP, "skipped: on the office LAN profile ...", [],
        0.0, 9.0, {"ports": [], "test_port": 12345, "test_port_open": None, "public_ip": None})
    put(r, "linux.chat_in", "fail", peers={"turtlebot": {"ok": False, "failure": "connect",
                                                          "tcp": "refused"}})
    fs = run(r, laptop_settings(profile="office"))
    assert not [f for f in fs if f.rule.startswith("table1.")]
    f = next(f for f in fs if f.rule == "linux.chat.in_fails")
    assert f.goto_step == "linux"
    assert "modem" not in " ".join(f.actions)
    assert "security.exposed" not in ids(fs)


# --------------------------------------------------------------------------- sshd elsewhere
def test_sshd_on_another_port_is_not_blamed_on_forwarding():
    """Port 22 refused, the address answers ping and the robot's master answers through the
    same modem: sshd listens elsewhere (or not at all); ssh_port exists."""
    r = healthy_laptop()
    ssh_shut_out(r, "refused", address="203.0.113.2")
    fs = run(r)
    first = first_failure(fs)
    assert first.rule == "linux.ssh.refused" and first.goto_step == "linux"
    assert "most likely sshd on turtlebot does not listen on port 22" in first.meaning
    assert "ROS master answers at the same address" in first.meaning
    assert "ssh_port = N under the [[peer]] named turtlebot" in first.actions[0]
    assert "forward" not in first.actions[0]
    assert "linux.peer.unreachable" not in ids(fs)
    assert set(first.check_ids) >= {"linux.ssh", "linux.chat_out", "linux.chat_in"}


def test_ssh_port_dropped_while_the_master_answers_is_port_22_not_forwarded():
    r = healthy_laptop()
    ssh_shut_out(r, "timeout")
    first = first_failure(run(r))
    assert first.rule == "linux.peer.unreachable" and first.goto_step == "router"
    assert "outside the forwarded range" in first.meaning
    assert "port 22 is outside 1024-65000 and needs a rule of its own" in first.actions[0]


# --------------------------------------------------------------------------- the ROS master
def test_master_refusing_while_ssh_works_is_roscore():
    r = healthy_laptop()
    put(r, "ros.master", "fail", reachable=False, topics=[], nodes=[], tcp="refused")
    f = next(f for f in run(r) if f.rule == "ros.master.unreachable")
    assert f.goto_step == "ros" and f.actions[0].startswith("Is roscore running on turtlebot")
    assert "answers SSH at" in f.meaning


def test_master_silent_while_ssh_works_is_its_forwarding():
    r = healthy_laptop()
    put(r, "ros.master", "fail", reachable=False, topics=[], nodes=[], tcp="timeout")
    f = next(f for f in run(r) if f.rule == "ros.master.unreachable")
    assert f.goto_step == "router" and f.actions[0].startswith("Is TCP 11311 forwarded")


# --------------------------------------------------------------------------- ros.env
def test_master_uri_only_in_this_shell_says_how_to_write_it():
    r = healthy_laptop()
    put(r, "ros.env", "warn", bashrc_uri=None, uri_ok=True)
    fs = run(r)
    f = next(f for f in fs if f.rule == "ros.env.bashrc")
    assert f.severity == "warn" and f.goto_step == "ros"
    assert "not in ~/.bashrc" in f.meaning and "rosnet-tui ros apply" in f.actions[0]
    assert "check.unexplained" not in ids(fs)
    # the reverse: written, this shell opened before
    r = healthy_laptop()
    put(r, "ros.env", "warn", env_uri=None, uri_ok=True)
    f = next(f for f in run(r) if f.rule == "ros.env.bashrc")
    assert "source ~/.bashrc" in f.actions[0]


def test_peer_cannot_register_follows_the_port_test():
    """On the master: the peer's nodes cannot register. The port test of this round tells
    whether the forwarding is the cause."""
    from tests.advisor_support import peer_cannot_register

    r, s = peer_cannot_register()                     # 11311 open from outside
    f = next(f for f in run(r, s) if f.rule == "ros.master.peer_cannot_register")
    assert f.goto_step == "linux" and f.actions[0].startswith("On sami: `getent hosts turtlebot`")
    assert "11311 open from outside" in f.meaning
    closed_port(r, "timeout")                          # the test port closed (Table 1)
    f = next(f for f in run(r, s) if f.rule == "ros.master.peer_cannot_register")
    assert f.goto_step == "router" and f.actions[0].startswith("On turtlebot's modem")


# --------------------------------------------------------------------------- a peer's firewall
def test_refused_by_the_masters_firewall_after_a_new_address_names_that_firewall():
    """Issue 32: ROS 1's peers-only firewall answers an address it does not hold with a TCP
    reset. The laptop's public IP changed (isp.public_ip measures 198.51.100.77; the settings,
    which the robot's table follows, say 198.51.100.2): SSH and the master's port refused at the
    robot's address read as that firewall's doing, not as a forwarding fault."""
    r = healthy_laptop()
    r["isp.public_ip"].data.update(public_ip="198.51.100.77")
    ssh_shut_out(r, "refused", address="203.0.113.2")
    put(r, "ros.master", "fail", reachable=False, topics=[], nodes=[], tcp="refused")
    fs = run(r)
    first = first_failure(fs)
    assert first.rule == "linux.ssh.refused" and first.goto_step == "linux", ids(fs)
    assert ("most likely turtlebot's peers-only firewall does not know this machine's address "
            "yet") in first.meaning
    assert "this machine's public IP is 198.51.100.77 now, not 198.51.100.2" in first.meaning
    assert first.actions[0].startswith("Give turtlebot's firewall this machine's address "
                                       "198.51.100.77"), first.actions
    master = next(f for f in fs if f.rule == "ros.master.unreachable")
    assert master.actions[0].startswith("Give turtlebot's firewall"), master.actions
    # The same refusals with the address the settings give: the modem first, as before.
    r = healthy_laptop()
    ssh_shut_out(r, "refused", address="203.0.113.2")
    put(r, "ros.master", "fail", reachable=False, topics=[], nodes=[], tcp="refused")
    first = first_failure(run(r))
    assert first.actions[0].startswith("Check that turtlebot's modem forwards TCP 22")
    # No peers-only firewall (ROS 1 with security "none"): never named.
    r = healthy_laptop()
    r["isp.public_ip"].data.update(public_ip="198.51.100.77")
    ssh_shut_out(r, "refused", address="203.0.113.2")
    put(r, "ros.master", "fail", reachable=False, topics=[], nodes=[], tcp="refused")
    s = laptop_settings()
    s.ros.security = "none"
    fs = run(r, s)
    assert not any("firewall does not know" in f.meaning or "Give turtlebot's firewall" in a
                   for f in fs for a in f.actions), [f.actions for f in fs]
