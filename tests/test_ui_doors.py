"""Issue 33's string side doors: the UI and the CLI read what the core declares, never raw check
data by key, never a message's words to learn a fact."""

from __future__ import annotations

import ast
import re
from pathlib import Path

from rosnet_tui.core.config.paths import Paths
from rosnet_tui.core.wizard.session import UnknownHostKey, WizardSession
from rosnet_tui.core.wizard.write_plans import Said, Severity, after_ros2_write
from tests.builders import complete_settings, result, ros2_master, ros2_member

ROOT = Path(__file__).resolve().parents[1]
SHELLS = ("rosnet_tui/ui", "rosnet_tui/cli")


def _trees():
    for folder in SHELLS:
        for path in sorted((ROOT / folder).rglob("*.py")):
            yield path.relative_to(ROOT).as_posix(), ast.parse(path.read_text(encoding="utf-8"))


# --------------------------------------------------------------------------- raw check data
def test_the_ui_and_the_cli_never_read_a_check_results_raw_data():
    """A check's data is read through the session's typed accessors (which read it through its
    declaration, rosnet_tui.core.checks.data), so a renamed key fails a test instead of silently
    emptying a screen."""
    pokes = [f"{rel}:{node.lineno}" for rel, tree in _trees() for node in ast.walk(tree)
             if isinstance(node, ast.Attribute) and node.attr == "data"]
    assert pokes == [], "raw check data read by the UI or the CLI: " + ", ".join(pokes)


def _session(tmp_path: Path, settings=None) -> WizardSession:
    return WizardSession(settings or complete_settings(),
                         Paths(config_path=tmp_path / "config.toml", state_dir=tmp_path / "state"))


def test_unknown_host_keys_come_typed_from_linux_ssh(tmp_path):
    session = _session(tmp_path)
    assert session.unknown_host_keys() == []
    session.set_check_state("linux.ssh", "fail", result("linux.ssh", "fail", data={"peers": {
        "sami": {"ok": False, "failure": "host_key_unknown", "fingerprint": "SHA256:abc",
                 "host_key": "ssh-ed25519 AAAA", "address": "198.51.100.2"},
        "other": {"ok": False, "failure": "auth", "host_key": "ssh-ed25519 BBBB"},
        "bare": {"ok": False, "failure": "host_key_unknown", "host_key": "ssh-rsa CCCC"},
    }}))
    assert session.unknown_host_keys() == [
        UnknownHostKey("sami", "ssh-ed25519 AAAA", "SHA256:abc", "198.51.100.2"),
        UnknownHostKey("bare", "ssh-rsa CCCC", "?", "")]


def test_the_modems_word_comes_from_router_upnps_declared_data(tmp_path):
    session = _session(tmp_path)
    assert session.modem_said() == []
    session.set_check_state("router.upnp", "warn", result("router.upnp", "warn", data={
        "protocols": ["upnp"], "gateway": "192.168.1.1", "external_ip": "203.0.113.9",
        "wan": "public", "missing": [12345], "cgnat": False,
        "forwards": [{"protocol": "TCP", "external_port": 22, "description": "ssh"}]}))
    said = session.modem_said()
    assert said[0].startswith("The modem 192.168.1.1 speaks")
    assert "It forwards TCP 22 here ('ssh')." in said
    assert any("TCP 12345" in line for line in said)


# --------------------------------------------------------------------------- severities
PHRASE = re.compile(r"[A-Za-z]+ [A-Za-z]+")


def test_the_ui_and_the_cli_learn_no_fact_from_a_messages_words():
    """`said.startswith("Pairing failed")` and `"is required" in why`: a fact the core knows
    comes as a field (Said.severity...), not read back from its own words."""
    found = []
    for rel, tree in _trees():
        for node in ast.walk(tree):
            words: list[ast.AST] = []
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) \
                    and node.func.attr in ("startswith", "endswith") and node.args:
                arg = node.args[0]
                words = list(arg.elts) if isinstance(arg, ast.Tuple) else [arg]
            elif isinstance(node, ast.Compare) and any(isinstance(op, ast.In | ast.NotIn)
                                                       for op in node.ops):
                words = [node.left]
            found += [f"{rel}:{node.lineno}" for w in words
                      if isinstance(w, ast.Constant) and isinstance(w.value, str)
                      and PHRASE.search(w.value)]
    assert found == [], "a fact read from a message's words: " + ", ".join(found)


async def test_after_a_ros2_write_the_core_says_how_bad_it_is(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    assert await after_ros2_write(ros2_member(security="none")) is None
    member = ros2_member(security="mtls")
    member.peers[0].ssh_user = ""          # pairing cannot even start: a failure, in red
    said = await after_ros2_write(member)
    assert isinstance(said, Said) and said.severity is Severity.ERROR
    assert said.text.startswith("Pairing failed: no SSH user for the master turtlebot")
    said = await after_ros2_write(ros2_master(security="mtls"))   # the CA made: news
    assert said is not None and said.severity is Severity.INFO and said.text.startswith("Made ")
