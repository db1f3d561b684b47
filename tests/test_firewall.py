"""The ROS 1 peers-only firewall without root: the ruleset, the allowed addresses, the one-
transaction texts, the journal guard, the CLI's refusals (exit 2) and the advisor's rules.
nft itself runs in tests/test_firewall_lab.py (network namespaces, as root)."""

from __future__ import annotations

import copy
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from rosnet_tui.core.addresses import is_lan_network
from rosnet_tui.core.advisor import advise
from rosnet_tui.core.config.settings_model import (
    Peer,
    RosSettings,
    Settings,
    SettingsError,
    ThisComponent,
)
from rosnet_tui.core.exposure import firewall as fw
from rosnet_tui.core.net import netinfo
from rosnet_tui.core.results import CheckResult, Status
from rosnet_tui.core.saved.settings import parse_settings, render_settings
from rosnet_tui.core.ssh import origin
from tests.prompts import run_answering

REPO = Path(__file__).resolve().parents[1]


def robot(**ros) -> Settings:
    s = Settings(this=ThisComponent(name="turtlebot", role="master", local_ip="10.10.10.1",
                                    public_ip="203.0.113.2"),
                 peers=[Peer(name="sami", local_ip="192.168.1.10", public_ip="198.51.100.2",
                             office_ip="172.16.0.9", ssh_user="root"),
                        Peer(name="ops", local_ip="192.168.1.20", public_ip="198.51.100.40")],
                 ros=RosSettings(master="turtlebot", port=11311, version=1))
    for k, v in ros.items():
        setattr(s.ros, k, v)
    return s


SESSION = "203.0.113.50 5555 192.0.2.2 22"     # the issue's technician: no peer


def test_the_ruleset_lets_only_peers_loopback_and_replies_reach_the_forwarded_ports():
    s = robot()
    assert fw.allowed_addresses(s) == ["198.51.100.2", "198.51.100.40"]
    text = fw.render_ruleset(s, fw.Admission(peers=["198.51.100.2", "2001:db8::7"]))
    assert text.startswith("table inet rosnet_tui {\n")
    assert "elements = { 198.51.100.2 }" in text and "elements = { 2001:db8::7 }" in text
    assert "priority filter - 10; policy accept;" in text
    assert 'iif "lo" accept' in text and "ct state established,related accept" in text
    assert "tcp dport { 22, 1024-65000 } ip saddr @peers4 accept" in text
    # Strangers: a reset (bounded: a scan beyond the rate meets silence), then the drop.
    assert text.rstrip().endswith(
        "tcp dport { 22, 1024-65000 } limit rate 20/second burst 40 packets reject with tcp "
        "reset\n\t\ttcp dport { 22, 1024-65000 } drop\n\t}\n}")
    assert fw.only_our_table(text)
    # A master's port outside the range is forwarded too, so it is guarded too.
    assert fw.forwarded_ports(robot(port=80)) == ["22", "1024-65000", "80"]


def _chain(text: str) -> list[str]:
    body = text.split("\tchain input {\n", 1)[1]
    return [ln.strip() for ln in body.splitlines() if ln.strip() not in ("}", "")]


def _set(text: str, name: str) -> list[str]:
    body = text.split(f"\tset {name} {{\n", 1)[1].split("\t}", 1)[0]
    return [ln.strip() for ln in body.splitlines()]


def test_every_accept_rule_of_the_ruleset_exactly():
    """Who gets in, rule by rule: dropping or widening any one of them fails here."""
    s = robot()
    adm = fw.Admission(peers=["198.51.100.2", "2001:db8::7"],
                       lan=["10.10.10.0/24", "fe80::/64"],
                       allow=["203.0.113.0/28", "2001:db8:1::/48"],
                       sessions=[origin.Session("203.0.113.50", 22),
                                 origin.Session("2001:db8::50", 2222)])
    text = fw.render_ruleset(s, adm)
    assert _chain(text) == [
        "type filter hook input priority filter - 10; policy accept;",
        'iif "lo" accept',
        "ct state established,related accept",
        "tcp dport { 22, 1024-65000 } ip saddr @peers4 accept",
        "tcp dport { 22, 1024-65000 } ip6 saddr @peers6 accept",
        "tcp dport { 22, 1024-65000 } ip saddr @lan4 accept",
        "tcp dport { 22, 1024-65000 } ip6 saddr @lan6 accept",
        "tcp dport 22 ip saddr @allow4 accept",             # the allow list: SSH only
        "tcp dport 22 ip6 saddr @allow6 accept",
        "ip saddr . tcp dport @session4 accept",            # the session: its sshd port only
        "ip6 saddr . tcp dport @session6 accept",
        "tcp dport 12345 accept",                           # probe.port, for router.port_open
        "tcp dport { 22, 1024-65000 } limit rate 20/second burst 40 packets reject with tcp "
        "reset",                                            # strangers: refused at once
        "tcp dport { 22, 1024-65000 } drop"]                # beyond the rate: silence
    assert _set(text, "peers4") == ["type ipv4_addr", "elements = { 198.51.100.2 }"]
    assert _set(text, "peers6") == ["type ipv6_addr", "elements = { 2001:db8::7 }"]
    assert _set(text, "lan4") == ["type ipv4_addr", "flags interval",
                                  "elements = { 10.10.10.0/24 }"]
    assert _set(text, "lan6") == ["type ipv6_addr", "flags interval", "elements = { fe80::/64 }"]
    assert _set(text, "allow4") == ["type ipv4_addr", "flags interval",
                                    "elements = { 203.0.113.0/28 }"]
    assert _set(text, "allow6") == ["type ipv6_addr", "flags interval",
                                    "elements = { 2001:db8:1::/48 }"]
    assert _set(text, "session4") == ["type ipv4_addr . inet_service",
                                      "elements = { 203.0.113.50 . 22 }"]
    assert _set(text, "session6") == ["type ipv6_addr . inet_service",
                                      "elements = { 2001:db8::50 . 2222 }"]
    assert fw.only_our_table(text)
    # Nothing to keep in: the sets are there, empty (so the sync service and the check find them).
    empty = fw.render_ruleset(s, fw.Admission(peers=["198.51.100.2"]))
    assert _set(empty, "session4") == ["type ipv4_addr . inet_service"]
    assert _set(empty, "allow4") == ["type ipv4_addr", "flags interval"]


def test_the_probe_port_alone_is_open_to_anyone_and_never_the_masters_port():
    """Issue 36: the one port the table opens to strangers is probe.port (router.port_open's
    listener), by a rule of its own; the master's port is never it: settings naming the
    same port for both are refused (the CLI exits 2, test_the_cli_refuses_bad_input_with_exit_2)."""
    s = robot()
    s.probe.port = 23456
    text = fw.render_ruleset(s, fw.Admission(peers=["198.51.100.2"]))
    opened = [ln for ln in _chain(text) if ln.endswith(" accept") and "saddr" not in ln
              and ln.startswith("tcp dport")]
    assert opened == ["tcp dport 23456 accept"], opened
    assert fw.open_ports(s) == [23456]
    s.probe.port = s.ros.port = 20000          # the same port: refused by the settings ...
    assert ("probe.port", "must differ from ros.port (20000): the test port is open to anyone "
            "on the internet, the ROS master's port is not") in s.problems()
    assert fw.open_ports(s) == []              # ... and never opened by the table
    assert "tcp dport 20000 accept" not in fw.render_ruleset(s, fw.Admission(peers=["1.2.3.4"]))
    with pytest.raises(SettingsError, match="must differ from ros.port") as info:
        parse_settings(render_settings(s))
    assert info.value.key == "probe.port"


def test_who_gets_in_peers_everywhere_lan_everywhere_allow_and_session_on_ssh_only():
    adm = fw.Admission(peers=["198.51.100.2"], lan=["10.10.10.0/24"], allow=["192.0.2.0/28"],
                       sessions=[origin.Session("203.0.113.50", 22)])
    assert fw.admitted(adm, "198.51.100.2", 11311) == "a peer"
    assert fw.admitted(adm, "10.10.10.77", 11311) == "this machine's LAN (10.10.10.0/24)"
    assert fw.admitted(adm, "192.0.2.5", 22) == "[firewall] allow (192.0.2.0/28)"
    assert fw.admitted(adm, "192.0.2.5", 11311) == ""              # allow: SSH only
    assert fw.admitted(adm, "203.0.113.50", 22) == "the SSH session that loaded the table"
    assert fw.admitted(adm, "203.0.113.50", 11311) == ""           # session: its port only
    assert fw.admitted(adm, "203.0.113.51", 22) == ""
    assert fw.admitted(adm, "127.0.0.1", 11311) == "loopback"


def test_the_session_is_read_from_ssh_connection_or_ssh_client():
    assert origin.session_from_env({"SSH_CONNECTION": SESSION}) == \
        origin.Session("203.0.113.50", 22, "SSH_CONNECTION")
    assert origin.session_from_env({"SSH_CLIENT": "203.0.113.50 5555 2222"}) == \
        origin.Session("203.0.113.50", 2222, "SSH_CLIENT")
    # SSH_CONNECTION first; an IPv6 client with a zone; an IPv4 client on a dual-stack socket.
    both = {"SSH_CONNECTION": "2001:db8::5 1 2001:db8::1 22", "SSH_CLIENT": "192.0.2.9 1 22"}
    assert origin.session_from_env(both).address == "2001:db8::5"
    assert origin.session_from_env({"SSH_CONNECTION": "fe80::5%eth0 1 fe80::1%eth0 22"}
                               ).address == "fe80::5"
    assert origin.session_from_env({"SSH_CONNECTION": "::ffff:203.0.113.50 1 ::ffff:10.0.0.1 22"}
                               ).address == "203.0.113.50"
    assert origin.session_from_env({}) is None and origin.session_from_env({"SSH_CONNECTION": " "}) is None
    with pytest.raises(origin.SessionError, match="not an IP address"):
        origin.session_from_env({"SSH_CONNECTION": "somewhere 1 10.0.0.1 22"})


def test_the_session_gets_an_entry_unless_it_gets_in_already():
    s = robot()
    s.firewall.allow = ["192.0.2.0/28"]
    adm, why = fw.admission(s, session=origin.Session("203.0.113.50", 22, "SSH_CONNECTION"))
    assert why == "" and adm.sessions == [origin.Session("203.0.113.50", 22, "SSH_CONNECTION")]
    adm, why = fw.admission(s, session=origin.Session("198.51.100.2", 22))
    assert why == "a peer" and adm.sessions == []
    adm, why = fw.admission(s, session=origin.Session("192.0.2.3", 22))
    assert why.startswith("[firewall] allow") and adm.sessions == []
    adm, why = fw.admission(s, session=origin.Session("192.0.2.3", 2222))   # allow is SSH (22) only
    assert why == "" and adm.sessions == [origin.Session("192.0.2.3", 2222)]
    adm, why = fw.admission(s, session=None)
    assert why == "" and adm.sessions == []
    assert adm.allow == ["192.0.2.0/28"] and adm.peers == ["198.51.100.2", "198.51.100.40"]


def test_only_private_link_local_and_unique_local_networks_count_as_lan():
    import ipaddress

    lan = ("10.10.10.0/24", "172.16.4.0/22", "192.168.1.0/24", "169.254.0.0/16", "fe80::/64",
           "fd12:3456::/64")
    public = ("203.0.113.0/24", "198.51.100.0/24", "100.64.0.0/10", "100.64.1.0/24",
              "2001:db8::/64", "10.0.0.0/7", "172.32.0.0/16")
    assert all(is_lan_network(ipaddress.ip_network(n)) for n in lan)
    assert not any(is_lan_network(ipaddress.ip_network(n)) for n in public)
    got = netinfo.lan_networks()                       # this machine's own, whatever it has
    assert all(is_lan_network(ipaddress.ip_network(n)) for n in got), got
    assert not any(ipaddress.ip_network(n).network_address.is_loopback for n in got)


def test_allow_entries_are_merged_so_nft_takes_them():
    s = robot()
    s.firewall.allow = ["192.0.2.0/25", "192.0.2.128/25", "192.0.2.7", "2001:db8::1",
                        "203.0.113.9"]
    assert fw.allow_networks(s) == ["192.0.2.0/24", "203.0.113.9", "2001:db8::1"]
    s.firewall.allow = ["192.0.2.0/24", "nope"]
    with pytest.raises(fw.FirewallSettingsError) as e:
        fw.allow_networks(s)
    assert [k for k, _ in e.value.problems] == ["firewall.allow[1]"]


def test_a_lan_profile_allows_the_peers_lan_addresses():
    assert fw.allowed_addresses(robot(), "office") == ["172.16.0.9", "192.168.1.20"]
    assert fw.allowed_addresses(robot(), "portable") == ["192.168.1.10", "192.168.1.20"]


def test_bad_or_missing_addresses_are_refused_with_the_key():
    s = robot()
    s.peers[0].public_ip = "not-an-ip"
    s.peers[1].public_ip = ""
    with pytest.raises(fw.FirewallSettingsError) as e:
        fw.allowed_addresses(s)
    keys = [k for k, _ in e.value.problems]
    assert keys == ["peers[0] (sami)", "peers[1] (ops)"]
    s.peers = []
    with pytest.raises(fw.FirewallSettingsError):
        fw.allowed_addresses(s)


@pytest.mark.parametrize("ip", ["0.0.0.0", "224.0.0.1", "255.255.255.255", "127.0.0.1"])
def test_a_special_address_is_never_a_peer_the_firewall_lets_in(ip):
    s = robot()
    s.peers[0].public_ip = ip
    with pytest.raises(fw.FirewallSettingsError) as e:
        fw.allowed_addresses(s)
    assert [k for k, _ in e.value.problems] == ["peers[0] (sami)"]


def test_one_transaction_texts():
    t = fw.transaction_text("table inet rosnet_tui {\n}\n")
    assert t.splitlines()[:2] == ["table inet rosnet_tui", "delete table inet rosnet_tui"]
    u = fw.set_update_text(["198.51.100.9", "2001:db8::1"])
    assert u.splitlines() == ["flush set inet rosnet_tui peers4",
                              "add element inet rosnet_tui peers4 { 198.51.100.9 }",
                              "flush set inet rosnet_tui peers6",
                              "add element inet rosnet_tui peers6 { 2001:db8::1 }"]


def test_a_journal_copy_that_holds_anything_but_our_table_is_not_loaded():
    ours = fw.render_ruleset(robot(), fw.Admission(peers=["198.51.100.2"]))
    assert fw.only_our_table(ours)
    assert not fw.only_our_table(ours + "delete table inet filter\n")
    assert not fw.only_our_table("table inet filter {\n}\n")
    # the verdict "reject with tcp reset" (strangers get a reset) is ours; a bare "reset" is not
    assert "reject with tcp reset" in ours
    rule = "\t\ttcp dport { 22, 1024-65000 } drop\n"
    assert rule in ours
    assert not fw.only_our_table(ours.replace(rule, rule + "\t\treset counters\n"))
    assert not fw.only_our_table(ours.replace("reject with tcp reset", "reset"))


def test_undo_to_a_table_that_shuts_this_session_out_says_so_before_it_asks(monkeypatch):
    """A sibling of the lock-out: `undo` puts back the table loaded before, which may not let
    the SSH session running the undo in again. Its description (printed before the question)
    says so."""
    old = fw.render_ruleset(robot(), fw.Admission(peers=["198.51.100.2"]))
    listed = old.replace("\t}\n\tset", "\t}\n\n\tset")       # as nft lists it
    kept = fw.render_ruleset(robot(), fw.Admission(peers=["198.51.100.2"],
                                                   sessions=[origin.Session("203.0.113.50", 22)]))
    assert fw.sets_in_text(kept)["session4"] == ["203.0.113.50 . 22"]
    monkeypatch.setenv("SSH_CONNECTION", SESSION)
    said = fw.describe({"kind": fw.KIND, "before": listed})
    assert said == ("the firewall table inet rosnet_tui: put back as it was before; it does not "
                    "let in this SSH session's address, 203.0.113.50: once this session drops, "
                    "SSH from there is refused (add it to [firewall] allow, then rosnet-tui "
                    "firewall apply)")
    assert fw.describe({"kind": fw.KIND, "before": kept}) == \
        "the firewall table inet rosnet_tui: put back as it was before"
    monkeypatch.setenv("SSH_CONNECTION", "198.51.100.2 1 10.10.10.1 22")     # a peer: in
    assert fw.describe({"kind": fw.KIND, "before": listed}).endswith("as it was before")
    assert fw.describe({"kind": fw.KIND, "before": None}) == \
        "the firewall table inet rosnet_tui: removed (rosnet-tui created it)"


def test_listing_layout_does_not_count_as_a_change():
    ours = fw.render_ruleset(robot(), fw.Admission(peers=["198.51.100.2", "198.51.100.3"]))
    listed = ours.replace("elements = { 198.51.100.2, 198.51.100.3 }",
                          "elements = { 198.51.100.3,\n\t\t\t     198.51.100.2 }"
                          ).replace("\t}\n\tset", "\t}\n\n\tset")
    assert fw.normalize(listed) == fw.normalize(ours)


def test_security_is_read_in_one_place_with_the_versions_default():
    assert robot().ros.security == "firewall" and fw.wanted(robot())
    s = robot()
    s.ros.security = "none"     # the setting S1 adds; read through getattr until then
    assert s.ros.security == "none" and not fw.wanted(s)
    assert robot(version=2).ros.security == "mtls" and not fw.wanted(robot(version=2))


def _env(**extra: str) -> dict[str, str]:
    """This environment without an SSH session of the one running the tests, plus *extra*."""
    env = {k: v for k, v in os.environ.items() if k not in ("SSH_CONNECTION", "SSH_CLIENT")}
    env.update(extra)
    return env


def _cli(tmp_path, *args, settings: Settings | None = None, text: str | None = None,
         env: dict[str, str] | None = None):
    cfg = tmp_path / "config.toml"
    cfg.write_text(text if text is not None else render_settings(settings or robot()))
    return subprocess.run([sys.executable, "-m", "rosnet_tui", "--config", str(cfg), *args],
                          capture_output=True, text=True, cwd=REPO, timeout=60,
                          stdin=subprocess.DEVNULL, env=env or _env())


def _probe_on_master_port() -> Settings:
    s = robot()
    s.probe.port = s.ros.port
    return s


def test_the_cli_refuses_bad_input_with_exit_2(tmp_path):
    s = robot()
    s.peers[0].public_ip = ""
    for args, settings, says in (
            (("firewall", "apply", "--profile", "nowhere"), None, "invalid choice"),
            (("firewall", "apply", "--dry-run"), s, "peers[0] (sami)"),
            (("firewall", "apply", "--dry-run"), robot(version=2), "for ROS 1"),
            (("firewall", "apply", "--dry-run"), _probe_on_master_port(), "must differ from "
                                                                          "ros.port (11311)"),
            (("firewall", "nonsense"), None, "invalid choice"),
            (("firewall",), None, "ACTION")):
        r = _cli(tmp_path, *args, settings=settings)
        assert r.returncode == 2, (args, r.stdout, r.stderr)
        assert says in r.stderr and "Traceback" not in r.stderr, (args, r.stderr)


def test_show_prints_the_ruleset_and_the_addresses(tmp_path):
    r = _cli(tmp_path, "firewall", "show")
    assert r.returncode == 0, r.stderr
    assert "198.51.100.2    sami" in r.stdout and "table inet rosnet_tui {" in r.stdout
    assert "this machine's LAN (SSH and ROS):" in r.stdout
    assert "[firewall] allow (SSH): none" in r.stdout


def test_apply_over_ssh_names_the_session_and_keeps_it_in(tmp_path):
    """The issue's reproduction: ROS 1, one peer, SSH_CONNECTION from an address that is no
    peer. The preview names the session, says how long it stays, and the ruleset lets it in."""
    s = robot()
    s.peers = s.peers[:1]
    r = _cli(tmp_path, "firewall", "apply", "--dry-run", settings=s,
             env=_env(SSH_CONNECTION=SESSION))
    assert r.returncode == 0, r.stderr
    out = r.stdout
    assert ("  this SSH session, 203.0.113.50 (to sshd port 22; SSH_CONNECTION): SSH only, until "
            "the next `rosnet-tui firewall apply` replaces the table; to keep it for good, add it "
            "to [firewall] allow") in out
    assert "elements = { 203.0.113.50 . 22 }" in out
    assert "ip saddr . tcp dport @session4 accept" in out
    for line in ("On TCP 22, 1024-65000 only these get in (the rest is refused there):",
                 "  the peers (remote profile; SSH and ROS): 198.51.100.2 (sami)",
                 "  this machine's LAN (SSH and ROS): ",
                 "  [firewall] allow (SSH): none",
                 "  loopback, and replies to this machine's own connections"):
        assert line in out, line
    # All of it before the ruleset (and so before the question).
    assert out.index("this SSH session") < out.index("table inet rosnet_tui {")
    # SSH_CLIENT when SSH_CONNECTION is not there (and its port).
    r = _cli(tmp_path, "firewall", "apply", "--dry-run", settings=s,
             env=_env(SSH_CLIENT="203.0.113.50 5555 2222"))
    assert "elements = { 203.0.113.50 . 2222 }" in r.stdout, r.stdout + r.stderr
    # From a peer's address: in already, no entry of its own.
    r = _cli(tmp_path, "firewall", "apply", "--dry-run", settings=s,
             env=_env(SSH_CONNECTION="198.51.100.2 5555 192.0.2.2 22"))
    assert "this SSH session, 198.51.100.2: gets in already (a peer)" in r.stdout
    assert " . 22 }" not in r.stdout
    # Not over SSH: said so.
    r = _cli(tmp_path, "firewall", "apply", "--dry-run", settings=s)
    assert "no SSH session runs this (no SSH_CONNECTION)" in r.stdout, r.stdout + r.stderr


def test_the_allow_list_is_in_the_ruleset_and_the_preview(tmp_path):
    s = robot()
    s.firewall.allow = ["192.0.2.0/28", "2001:db8::9"]
    r = _cli(tmp_path, "firewall", "apply", "--dry-run", settings=s)
    assert r.returncode == 0, r.stderr
    assert "  [firewall] allow (SSH): 192.0.2.0/28, 2001:db8::9" in r.stdout
    assert "elements = { 192.0.2.0/28 }" in r.stdout and "elements = { 2001:db8::9 }" in r.stdout


def test_under_sudo_the_session_of_the_shell_that_ran_it_is_kept(tmp_path):
    """`sudo rosnet-tui firewall apply` typed by hand: sudo's env_reset drops SSH_CONNECTION;
    the shell that ran sudo still has it, and root reads it there."""
    sudo = shutil.which("sudo")
    if sudo is None or subprocess.run([sudo, "-n", "true"], capture_output=True,
                                      timeout=10).returncode != 0:
        pytest.skip("sudo cannot run here without a password")
    cfg = tmp_path / "config.toml"
    cfg.write_text(render_settings(robot()))
    # The shell stays (`; true`): it is sudo's parent, as a login shell is.
    line = (f"{sudo} -n {sys.executable} -m rosnet_tui --config {cfg} firewall apply --dry-run"
            "; true")
    r = subprocess.run(["sh", "-c", line], capture_output=True, text=True, cwd=REPO,
                       timeout=60, env=_env(SSH_CONNECTION=SESSION), stdin=subprocess.DEVNULL)
    assert ("this SSH session, 203.0.113.50 (to sshd port 22; SSH_CONNECTION of the shell that "
            "ran sudo): SSH only") in r.stdout, r.stdout + r.stderr
    assert "elements = { 203.0.113.50 . 22 }" in r.stdout


def test_a_session_that_cannot_be_told_is_refused_with_the_way_out(tmp_path):
    for env, args, says in (
            (_env(SSH_CONNECTION="somewhere 1 10.0.0.1 22"), (), "--session-ip ADDR"),
            (_env(), ("--session-ip", "somewhere"), "is not an IP address"),
            (_env(), ("--session-ip", "192.0.2.1", "--session-port", "0"), "is not a port")):
        r = _cli(tmp_path, "firewall", "apply", "--dry-run", *args, env=env)
        assert r.returncode == 2, (args, r.stdout, r.stderr)
        assert says in r.stderr and "[firewall] allow" in r.stderr, r.stderr
        assert "Traceback" not in r.stderr
    # Named by hand, or none at all.
    r = _cli(tmp_path, "firewall", "apply", "--dry-run", "--session-ip", "192.0.2.77",
             env=_env(SSH_CONNECTION="somewhere 1 10.0.0.1 22"))
    assert r.returncode == 0 and "elements = { 192.0.2.77 . 22 }" in r.stdout, r.stderr
    r = _cli(tmp_path, "firewall", "apply", "--dry-run", "--session-ip", "none",
             env=_env(SSH_CONNECTION=SESSION))
    assert r.returncode == 0 and "203.0.113.50" not in r.stdout, r.stderr


def test_the_prompt_names_the_session_it_keeps(tmp_path):
    """On a terminal: everything before the question, and the question says it; "n" loads
    nothing. As root, in a network namespace of its own (nothing of this machine touched)."""
    cfg = tmp_path / "config.toml"
    cfg.write_text(render_settings(robot()))
    own_netns = ["unshare", "--net"] if os.geteuid() == 0 and shutil.which("unshare") else []
    argv = [*own_netns, sys.executable, "-m", "rosnet_tui", "--config", str(cfg), "firewall",
            "apply", "--no-checks"]
    rc, out = run_answering(argv, ["n"], env=_env(SSH_CONNECTION=SESSION, PYTHONPATH=str(REPO)),
                            cwd=REPO, timeout=60)
    before = out.split("[y/N]")[0]
    assert "this SSH session, 203.0.113.50 (to sshd port 22; SSH_CONNECTION): SSH only" in before
    assert "elements = { 203.0.113.50 . 22 }" in before
    assert ("Load this table (one nft transaction; this SSH session, 203.0.113.50, keeps SSH)? "
            "[y/N]") in out
    assert rc == 1 and "Cancelled" in out, out


def test_settings_firewall_allow_is_read_saved_and_refused_when_bad(tmp_path):
    from rosnet_tui.core.saved.settings import load_settings, save_settings

    base = render_settings(robot())
    good = base + '\n[firewall]\nallow = ["192.0.2.0/28", "2001:db8::/48", " 203.0.113.9 "]\n'
    cfg = tmp_path / "c.toml"
    cfg.write_text(good)
    s = load_settings(cfg)
    assert s.firewall.allow == ["192.0.2.0/28", "2001:db8::/48", " 203.0.113.9 "]
    save_settings(s, cfg)
    assert load_settings(cfg).firewall.allow == s.firewall.allow
    s.firewall.allow = []
    save_settings(s, cfg)                   # the user's table stays, now empty
    assert "[firewall]" in cfg.read_text() and load_settings(cfg).firewall.allow == []
    assert "[firewall]" not in render_settings(robot())   # never added unasked
    for entry, says in (('"nope"', "is not an address or a network"),
                        ('"192.0.2.5/24"', "write the network 192.0.2.0/24"),
                        ('"0.0.0.0/0"', "the whole internet"),
                        ('"::/0"', "the whole internet"),
                        ('"127.0.0.1"', "cannot be where a login comes from"),
                        ('"224.0.0.0/4"', "cannot be where a login comes from"),
                        ('"fe80::1%eth0"', "without its zone"),
                        ("5", "each entry is an address or a network"),
                        ('""', "each entry is an address or a network")):
        text = base + f'\n[firewall]\nallow = ["192.0.2.1", {entry}]\n'
        cfg.write_text(text)
        with pytest.raises(SettingsError) as e:
            load_settings(cfg)
        assert says in str(e.value) and "firewall.allow" in str(e.value), (entry, str(e.value))
        assert f"line {len(text.splitlines())}" in str(e.value), str(e.value)
    cfg.write_text(base + '\n[firewall]\nallow = "192.0.2.1"\n')
    with pytest.raises(SettingsError, match="must be a list"):
        load_settings(cfg)
    cfg.write_text(base + '\n[firewall]\nalow = ["192.0.2.1"]\n')
    with pytest.raises(SettingsError, match="unknown key"):
        load_settings(cfg)


def test_a_bad_allow_entry_is_refused_by_the_cli_with_exit_2(tmp_path):
    text = render_settings(robot()) + '\n[firewall]\nallow = ["192.0.2.300"]\n'
    for args in (("firewall", "apply", "--dry-run"), ("firewall", "show"), ("check",)):
        r = _cli(tmp_path, *args, text=text)
        assert r.returncode == 2, (args, r.stdout, r.stderr)
        assert "firewall.allow" in r.stderr and "'192.0.2.300' is not an address" in r.stderr
        assert "Traceback" not in r.stderr


# ---- the advisor's rules (cases for tests/test_advisor.py's every-rule tests)
def _fw(status: str, **data) -> CheckResult:
    base = {"security": "firewall", "wanted": True, "present": True, "readable": True,
            "allowed": ["198.51.100.2"], "expected": ["198.51.100.2"], "missing": [],
            "extra": [], "rules_match": True}
    base.update(data)
    return CheckResult("linux.firewall", "linux", Status(status), "s", [], 0.1, 3.0, base)


def _case(result: CheckResult):
    def make():
        s = robot()
        s.ros.security = result.data["security"]
        return {result.id: copy.deepcopy(result)}, s   # each case its own (tests mutate them)
    return make


FIREWALL_CASES = {
    "security.firewall.missing": _case(_fw("warn", present=False, allowed=[])),
    "security.firewall.stale": _case(_fw("fail", allowed=["198.51.100.9"],
                                         missing=["198.51.100.2"], extra=["198.51.100.9"])),
    "security.firewall.off": _case(_fw("warn", security="none", wanted=False, present=False)),
    "security.firewall.lockout": _case(_fw("warn", client="203.0.113.50", client_in="")),
}


def test_an_ssh_client_the_table_would_not_let_in_again_is_named_with_the_way_in():
    results, s = FIREWALL_CASES["security.firewall.lockout"]()
    f = next(f for f in advise(results, s) if f.rule == "security.firewall.lockout")
    assert f.severity == "warn" and "203.0.113.50" in f.meaning
    assert any('"203.0.113.50"' in a and "[firewall]" in a and "firewall apply" in a
               for a in f.actions)
    for client, client_in in ((None, None), ("203.0.113.50", "a peer")):
        got = {f.rule for f in advise({"linux.firewall": _fw("pass", client=client,
                                                              client_in=client_in)}, s)}
        assert "security.firewall.lockout" not in got


def test_a_lan_or_allow_network_left_out_is_stale_too():
    s = robot()
    for data, says in (({"expected_lan": ["10.10.10.0/24"], "lan": []}, "LAN 10.10.10.0/24"),
                       ({"expected_allow": ["192.0.2.0/28"], "allow": []}, "192.0.2.0/28 of "
                                                                           "[firewall] allow"),
                       ({"rules_match": False}, "an older table")):
        f = [f for f in advise({"linux.firewall": _fw("warn", **data)}, s)
             if f.rule == "security.firewall.stale"]
        assert f and f[0].severity == "warn" and says in f[0].meaning, (data, f)


def test_the_checks_words_for_who_gets_in_and_for_the_ssh_client():
    from rosnet_tui.core.checks.firewall import client_words, who_evidence

    sets = {"peers4": ["198.51.100.2"], "peers6": [], "lan4": ["10.10.10.0/24"], "lan6": [],
            "allow4": ["192.0.2.0/28"], "allow6": [], "session4": ["203.0.113.50 . 22"],
            "session6": []}
    loaded = fw.loaded_admission(sets)
    assert loaded.sessions == [origin.Session("203.0.113.50", 22, "the loaded table")]
    assert who_evidence(loaded) == [
        "peers (SSH and ROS): 198.51.100.2",
        "this machine's LAN (SSH and ROS): 10.10.10.0/24",
        "[firewall] allow (SSH): 192.0.2.0/28",
        "the SSH session that loaded it (SSH, until the next firewall apply): "
        "203.0.113.50 (port 22)"]
    assert client_words(loaded, origin.Session("203.0.113.50", 22))[0] == \
        "the SSH session that loaded the table"
    why, line = client_words(loaded, origin.Session("203.0.113.51", 22))
    assert why == "" and line == ("this check runs over SSH from 203.0.113.51 (sshd port 22): "
                                  "would NOT get in once this session drops")


def test_a_stale_set_that_shuts_a_peer_out_is_a_failure_naming_the_address():
    results, s = FIREWALL_CASES["security.firewall.stale"]()
    f = next(f for f in advise(results, s) if f.rule == "security.firewall.stale")
    assert f.severity == "fail" and "198.51.100.2" in f.meaning and "198.51.100.9" in f.meaning


def test_a_loaded_table_with_the_right_set_says_nothing():
    s = robot()
    got = {f.rule for f in advise({"linux.firewall": _fw("pass")}, s)}
    assert not {r for r in got if r.startswith("security.firewall")}
