"""The peers-only firewall at its edges (issue 36's mutation run of core/exposure/firewall.py):
the range's first and last port, every bad peer named (not only the first), networks written
with their host bits, a loaded table read back set by set, the layout-blind comparison, and the
session kept on its own sshd port. No root: nft itself runs in tests/test_firewall_lab.py."""

from __future__ import annotations

import pytest

from rosnet_tui.core.config.settings_model import PORT_MAX, PORT_MIN, Peer
from rosnet_tui.core.exposure import firewall as fw
from rosnet_tui.core.net import netinfo
from rosnet_tui.core.ssh import origin
from tests.test_firewall import robot


@pytest.mark.parametrize(("port", "extra"), [
    (PORT_MIN, []), (PORT_MAX, []), (PORT_MIN - 1, [str(PORT_MIN - 1)]),
    (PORT_MAX + 1, [str(PORT_MAX + 1)]), (22, [])])
def test_the_masters_port_is_guarded_by_the_range_or_a_port_of_its_own(port, extra):
    """The range's ends are inside it (no second entry); just outside, the port is added, so
    strangers are refused there too."""
    s = robot(port=port)
    assert fw.forwarded_ports(s) == ["22", f"{PORT_MIN}-{PORT_MAX}", *extra]
    ports = ", ".join(fw.forwarded_ports(s))
    assert f"tcp dport {{ {ports} }} limit rate" in fw.render_ruleset(
        s, fw.Admission(peers=["198.51.100.2"]))


@pytest.mark.parametrize(("port", "opened"), [
    (PORT_MIN, [PORT_MIN]), (PORT_MAX, [PORT_MAX]), (PORT_MIN - 1, []), (PORT_MAX + 1, [])])
def test_the_probe_port_is_opened_at_the_ends_of_the_range_and_never_outside_it(port, opened):
    s = robot()
    s.probe.port = port
    assert fw.open_ports(s) == opened
    text = fw.render_ruleset(s, fw.Admission(peers=["198.51.100.2"]))
    assert (f"\t\ttcp dport {port} accept\n" in text) is bool(opened)


def test_every_bad_peer_is_named_not_only_the_first():
    """A refusal lists each peer that cannot be let in, whatever is wrong with it, so one
    round of edits fixes all of them."""
    s = robot()
    s.peers = [s.peers[0], s.peers[1], *(Peer(name=n, public_ip=ip) for n, ip in (
        ("a", ""), ("b", "not-an-ip"), ("c", "224.0.0.1"), ("d", ""), ("e", "nope"),
        ("f", "0.0.0.0"), ("g", "203.0.113.7")))]
    s.peers[0].public_ip = "127.0.0.1"
    with pytest.raises(fw.FirewallSettingsError) as e:
        fw.allowed_addresses(s)
    assert [k for k, _ in e.value.problems] == [
        "peers[0] (sami)", "peers[2] (a)", "peers[3] (b)", "peers[4] (c)", "peers[5] (d)",
        "peers[6] (e)", "peers[7] (f)"]
    # the exception's own words carry every key and reason (the CLI prints them)
    said = str(e.value)
    assert said.startswith("peers[0] (sami): 127.0.0.1 cannot be a peer's address")
    assert "; peers[2] (a): no address known for the remote profile; " in said
    assert "peers[3] (b): 'not-an-ip' is not an IP address" in said


def test_networks_written_with_their_host_bits_are_read_as_their_network():
    """An Admission may hold 10.10.10.1/24 (as a person writes it): it is the network
    10.10.10.0/24, for who gets in and for the family its set is in."""
    adm = fw.Admission(peers=[], lan=["10.10.10.1/24", "fd00::1/64"],
                       allow=["192.0.2.9/28"])
    assert fw.admitted(adm, "10.10.10.77", 11311) == "this machine's LAN (10.10.10.1/24)"
    assert fw.admitted(adm, "fd00::77", 11311) == "this machine's LAN (fd00::1/64)"
    assert fw.admitted(adm, "192.0.2.1", 22) == "[firewall] allow (192.0.2.9/28)"
    assert fw.admitted(adm, "10.10.11.1", 11311) == ""
    assert fw.split_families(["10.10.10.1/24", "fd00::1/64", "192.0.2.9 . 22",
                              "2001:db8::5 . 2222"]) == (
        ["10.10.10.1/24", "192.0.2.9 . 22"], ["fd00::1/64", "2001:db8::5 . 2222"])


def test_the_table_lets_in_this_machines_lan_and_the_profiles_peers():
    s = robot()
    adm, why = fw.admission(s, "office")
    assert adm.lan == netinfo.lan_networks()          # whatever this machine has
    assert adm.peers == ["172.16.0.9", "192.168.1.20"] and why == ""
    assert fw.admission(s, "remote")[0].peers == ["198.51.100.2", "198.51.100.40"]
    # the session's address is checked against the profile asked for, not the settings' one
    adm, why = fw.admission(s, "office", session=origin.Session("172.16.0.9", 22))
    assert why == "a peer" and adm.sessions == []


def test_a_loaded_table_is_read_back_set_by_set_and_a_missing_set_is_empty():
    sets = {"peers4": ["198.51.100.2"], "peers6": ["2001:db8::7"],
            "lan4": ["10.10.10.0/24"], "lan6": ["fe80::/64"],
            "allow4": ["192.0.2.0/28"], "allow6": ["2001:db8:1::/48"],
            "session4": ["203.0.113.50 . 22"], "session6": ["2001:db8::50 . 2222"]}
    got = fw.loaded_admission(sets)
    assert got.peers == ["198.51.100.2", "2001:db8::7"]
    assert got.lan == ["10.10.10.0/24", "fe80::/64"]
    assert got.allow == ["192.0.2.0/28", "2001:db8:1::/48"]
    assert got.sessions == [origin.Session("203.0.113.50", 22, "the loaded table"),
                            origin.Session("2001:db8::50", 2222, "the loaded table")]
    assert fw.loaded_admission({}) == fw.Admission(peers=[])
    # an element that is not "address . port" is no session (nor a made-up address)
    assert fw.loaded_admission({"session4": ["192.0.2.1 . 10 . 22", "192.0.2.1"]}).sessions == []
    for name in sets:                       # each set alone: the others read as empty
        one = fw.loaded_admission({name: sets[name]})
        assert len(one.peers + one.lan + one.allow + one.sessions) == 1, name


def test_a_listed_table_compares_equal_to_its_ruleset_and_a_different_one_does_not():
    ours = fw.render_ruleset(robot(), fw.Admission(peers=["198.51.100.2"]))
    other = fw.render_ruleset(robot(), fw.Admission(peers=["198.51.100.3"]))
    assert fw.normalize(None) == "" and fw.normalize("") == ""
    assert fw.normalize(ours) and fw.normalize(ours) != fw.normalize(other)
    pv = fw.FirewallPreview(ours, None, ["198.51.100.2"])
    assert pv.changed                                   # no table yet: a change
    assert not fw.FirewallPreview(ours, ours.replace("\t", "  "), []).changed
    assert fw.FirewallPreview(ours, other, []).changed
    assert fw.FirewallPreview(ours, ours, [], readable=False).changed


def test_undo_keeps_a_session_on_its_own_sshd_port(monkeypatch):
    """The table put back holds this session on port 2222: the undo does not warn of a lock-out
    (it would if the session's port were taken for 22)."""
    kept = fw.render_ruleset(robot(), fw.Admission(
        peers=["198.51.100.2"], sessions=[origin.Session("203.0.113.50", 2222)]))
    monkeypatch.setenv("SSH_CONNECTION", "203.0.113.50 5555 192.0.2.2 2222")
    assert fw.locks_out_this_session(kept) == ""
    monkeypatch.setenv("SSH_CONNECTION", "203.0.113.50 5555 192.0.2.2 22")
    assert "203.0.113.50" in fw.locks_out_this_session(kept)
    # a journal entry whose copy is no text (a damaged journal) is described, not read
    assert fw.describe({"kind": fw.KIND, "before": ["table"]}) == \
        "the firewall table inet rosnet_tui: put back as it was before"


def test_the_preview_says_who_gets_in_by_name_and_for_how_long():
    """who_gets_in in this process (the CLI tests run it in a child): the peers by name, what
    is empty said so, and the session's three cases."""
    s = robot()
    adm = fw.Admission(peers=["198.51.100.2", "198.51.100.99"], lan=["10.10.10.0/24"])
    out = fw.who_gets_in(s, adm)
    assert out[0] == "On TCP 22, 1024-65000 only these get in (the rest is refused there):"
    assert out[1] == "  the peers (remote profile; SSH and ROS): 198.51.100.2 (sami), 198.51.100.99"
    assert out[2] == "  this machine's LAN (SSH and ROS): 10.10.10.0/24"
    assert out[3] == "  [firewall] allow (SSH): none"
    assert out[4].startswith("  no SSH session runs this")
    assert out[-1] == "  loopback, and replies to this machine's own connections"
    office = fw.who_gets_in(s, fw.Admission(peers=["172.16.0.9"]), "office")
    assert office[1] == "  the peers (office profile; SSH and ROS): 172.16.0.9 (sami)"
    assert office[2] == "  this machine's LAN (SSH and ROS): none found"
    assert fw.who_gets_in(s, fw.Admission(peers=[]))[1].endswith(": none")
    kept = origin.Session("203.0.113.50", 2222, "SSH_CONNECTION")
    assert fw.who_gets_in(s, adm, session=kept)[4] == (
        "  this SSH session, 203.0.113.50 (to sshd port 2222; SSH_CONNECTION): SSH only, "
        + fw.SESSION_STAYS)
    assert fw.who_gets_in(s, adm, session=kept, session_in="a peer")[4] == \
        "  this SSH session, 203.0.113.50: gets in already (a peer)"


def test_the_privileged_rerun_gets_the_very_session_previewed(tmp_path):
    assert fw.session_args(None) == ["--session-ip", "none"]
    assert fw.session_args(origin.Session("203.0.113.50", 2222)) == \
        ["--session-ip", "203.0.113.50", "--session-port", "2222"]
    argv = fw.apply_command(config=tmp_path / "c.toml", profile="office", digest="ab12",
                            state_dir=tmp_path / "st", session=origin.Session("192.0.2.9", 22))
    tail = argv[argv.index("--config"):]
    assert tail == ["--config", str(tmp_path / "c.toml"), "firewall", "apply", "--profile",
                    "office", "--expect-digest", "ab12", "--session-ip", "192.0.2.9",
                    "--session-port", "22", "--yes", "--state-dir", str(tmp_path / "st"),
                    "--no-checks"]
