"""The ROS 1 peers-only firewall without root: the ruleset, the allowed addresses, the one-
transaction texts, the journal guard, the CLI's refusals (exit 2) and the advisor's rules.
nft itself runs in tests/test_firewall_lab.py (network namespaces, as root)."""

from __future__ import annotations

import copy
import subprocess
import sys
from pathlib import Path

import pytest

from rosnet_tui.core import firewall as fw
from rosnet_tui.core.advisor import advise
from rosnet_tui.core.results import CheckResult, Status
from rosnet_tui.core.settings import render_settings
from rosnet_tui.core.settings_model import Peer, RosSettings, Settings, ThisComponent

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


def test_the_ruleset_lets_only_peers_loopback_and_replies_reach_the_forwarded_ports():
    s = robot()
    assert fw.allowed_addresses(s) == ["198.51.100.2", "198.51.100.40"]
    text = fw.render_ruleset(s, ["198.51.100.2", "2001:db8::7"])
    assert text.startswith("table inet rosnet_tui {\n")
    assert "elements = { 198.51.100.2 }" in text and "elements = { 2001:db8::7 }" in text
    assert "priority filter - 10; policy accept;" in text
    assert 'iif "lo" accept' in text and "ct state established,related accept" in text
    assert "tcp dport { 22, 1024-65000 } ip saddr @peers4 accept" in text
    assert text.rstrip().endswith("tcp dport { 22, 1024-65000 } drop\n\t}\n}")
    assert fw.only_our_table(text)
    # A master's port outside the range is forwarded too, so it is guarded too.
    assert fw.forwarded_ports(robot(port=80)) == ["22", "1024-65000", "80"]


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


def test_one_transaction_texts():
    t = fw.transaction_text("table inet rosnet_tui {\n}\n")
    assert t.splitlines()[:2] == ["table inet rosnet_tui", "delete table inet rosnet_tui"]
    u = fw.set_update_text(["198.51.100.9", "2001:db8::1"])
    assert u.splitlines() == ["flush set inet rosnet_tui peers4",
                              "add element inet rosnet_tui peers4 { 198.51.100.9 }",
                              "flush set inet rosnet_tui peers6",
                              "add element inet rosnet_tui peers6 { 2001:db8::1 }"]


def test_a_journal_copy_that_holds_anything_but_our_table_is_not_loaded():
    ours = fw.render_ruleset(robot(), ["198.51.100.2"])
    assert fw.only_our_table(ours)
    assert not fw.only_our_table(ours + "delete table inet filter\n")
    assert not fw.only_our_table("table inet filter {\n}\n")


def test_listing_layout_does_not_count_as_a_change():
    ours = fw.render_ruleset(robot(), ["198.51.100.2", "198.51.100.3"])
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


def _cli(tmp_path, *args, settings: Settings | None = None):
    cfg = tmp_path / "config.toml"
    cfg.write_text(render_settings(settings or robot()))
    return subprocess.run([sys.executable, "-m", "rosnet_tui", "--config", str(cfg), *args],
                          capture_output=True, text=True, cwd=REPO, timeout=60,
                          stdin=subprocess.DEVNULL)


def test_the_cli_refuses_bad_input_with_exit_2(tmp_path):
    s = robot()
    s.peers[0].public_ip = ""
    for args, settings, says in (
            (("firewall", "apply", "--profile", "nowhere"), None, "invalid choice"),
            (("firewall", "apply", "--dry-run"), s, "peers[0] (sami)"),
            (("firewall", "apply", "--dry-run"), robot(version=2), "for ROS 1"),
            (("firewall", "nonsense"), None, "invalid choice"),
            (("firewall",), None, "ACTION")):
        r = _cli(tmp_path, *args, settings=settings)
        assert r.returncode == 2, (args, r.stdout, r.stderr)
        assert says in r.stderr and "Traceback" not in r.stderr, (args, r.stderr)


def test_show_prints_the_ruleset_and_the_addresses(tmp_path):
    r = _cli(tmp_path, "firewall", "show")
    assert r.returncode == 0, r.stderr
    assert "198.51.100.2    sami" in r.stdout and "table inet rosnet_tui {" in r.stdout


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
}


def test_a_stale_set_that_shuts_a_peer_out_is_a_failure_naming_the_address():
    results, s = FIREWALL_CASES["security.firewall.stale"]()
    f = next(f for f in advise(results, s) if f.rule == "security.firewall.stale")
    assert f.severity == "fail" and "198.51.100.2" in f.meaning and "198.51.100.9" in f.meaning


def test_a_loaded_table_with_the_right_set_says_nothing():
    s = robot()
    got = {f.rule for f in advise({"linux.firewall": _fw("pass")}, s)}
    assert not {r for r in got if r.startswith("security.firewall")}
