"""Linux checks on loopback: hosts files in tmp, the system resolver (localhost only: nothing
here may ask a real DNS server), ping, and a real sshd for the SSH and chat checks."""

from __future__ import annotations

import shutil

import pytest

from rosnet_tui.core.checks import (
    REGISTRY,
    CheckContext,
    linux,
    load_builtin_checks,
    run_check,
)
from rosnet_tui.core.checks.probes import agents as probe_agents
from rosnet_tui.core.config.paths import Paths
from rosnet_tui.core.config.settings_model import (
    Peer,
    ProbeSettings,
    RosSettings,
    Settings,
    ThisComponent,
)
from rosnet_tui.core.files.hosts import HostsEntry
from rosnet_tui.core.results import Status
from rosnet_tui.core.ssh.options import SshOptions
from tests.builders import free_port
from tests.builders import probe_settings as settings

load_builtin_checks()


def ctx(s: Settings, tmp_path, client=None, timeout=2.0, **kw) -> CheckContext:
    if client is not None:
        kw.setdefault("ssh_options", SshOptions(ssh_dir=client.dir, ssh_agent=False,
                                                known_hosts_files=(client.dir / "known_hosts",)))
    kw.setdefault("ssh_options", SshOptions(ssh_agent=False))
    kw.setdefault("upnp", False)
    paths = Paths(state_dir=tmp_path / "state", **{k: kw.pop(k) for k in ("hosts_path",) if k in kw})
    return CheckContext(settings=s, timeout_s=timeout, paths=paths, **kw)


async def run(check_id: str, c: CheckContext):
    return await run_check(REGISTRY[check_id], c)


# --------------------------------------------------------------------------- linux.hosts
GOOD = "127.0.0.1\tlocalhost\n10.10.10.1 turtlebot\n198.51.100.2 sami # the laptop\n"


@pytest.mark.parametrize("text,status,key,value", [
    (GOOD, Status.PASS, None, None),
    (GOOD + "198.51.100.2 SAMI\n", Status.PASS, None, None),  # same address twice: harmless
    ("127.0.0.1 localhost\n10.10.10.1 turtlebot\n", Status.FAIL, "missing", ["sami"]),
    ("10.10.10.1 turtlebot\n203.0.113.99 sami\n", Status.FAIL, "wrong",
     [{"name": "sami", "found": "203.0.113.99", "expected": "198.51.100.2"}]),
    (GOOD + "127.0.1.1 turtlebot\n", Status.FAIL, "loopback", ["turtlebot"]),
    (GOOD + "198.51.100.77 sami\n", Status.FAIL, "duplicates", ["sami"]),
    ("#198.51.100.2 sami\n10.10.10.1 turtlebot\n", Status.FAIL, "missing", ["sami"]),
])
async def test_hosts_file_audit(tmp_path, text, status, key, value):
    hosts = tmp_path / "hosts"
    hosts.write_text(text)
    r = await run("linux.hosts", ctx(settings(), tmp_path, hosts_path=hosts))
    assert r.status is status, r.summary
    assert set(r.data) >= {"missing", "wrong", "duplicates", "loopback"}
    if key:
        assert r.data[key] == value
    else:
        assert not any(r.data[k] for k in ("missing", "wrong", "duplicates", "loopback"))


async def test_hosts_entries_follow_the_profile(tmp_path):
    hosts = tmp_path / "hosts"
    hosts.write_text("10.10.10.1 turtlebot\n192.168.1.10 sami\n")
    r = await run("linux.hosts", ctx(settings(profile="office"), tmp_path, hosts_path=hosts))
    assert r.status is Status.PASS
    r = await run("linux.hosts", ctx(settings(profile="remote"), tmp_path, hosts_path=hosts))
    assert r.status is Status.FAIL and r.data["wrong"][0]["expected"] == "198.51.100.2"


async def test_unreadable_hosts_file_fails(tmp_path):
    r = await run("linux.hosts", ctx(settings(), tmp_path, hosts_path=tmp_path / "nope"))
    assert r.status is Status.FAIL and "cannot read" in r.summary


def test_audit_reports_the_lines():
    a = linux.audit_hosts(GOOD, [HostsEntry("198.51.100.2", "sami", "peer")])
    assert a["lines"]["sami"] == ["line 3: 198.51.100.2"]


def test_audit_reads_the_hosts_file_as_the_resolver_and_the_writer_do():
    """Issue 33: hosts-file parsing had two homes with two rules. The audit counted a line whose
    first field is no address ('turtlebot-old sami') as an entry for sami, found at
    'turtlebot-old'; the resolver (glibc) skips such a line, and so did the conflict finder."""
    from rosnet_tui.core.files.hosts import parse_hosts

    text = "127.0.0.1 localhost\nturtlebot-old sami\n198.51.100.2 sami # peer\n"
    assert [(n, ip) for n, ip, _ in parse_hosts(text)] == [(1, "127.0.0.1"), (3, "198.51.100.2")]
    a = linux.audit_hosts(text, [HostsEntry("198.51.100.2", "sami", "peer")])
    assert a["wrong"] == [] and a["lines"]["sami"] == ["line 3: 198.51.100.2"]


# --------------------------------------------------------------------------- linux.resolve
async def test_resolve_flags_a_name_on_loopback(tmp_path):
    s = settings(name="localhost", local_ip="10.1.2.3", peers=[])
    r = await run("linux.resolve", ctx(s, tmp_path))
    assert r.status is Status.FAIL and r.data["loopback"] == ["localhost"]
    assert r.data["names"]["localhost"] == {"resolved": "127.0.0.1", "expected": "10.1.2.3"}


async def test_resolve_passes_when_the_name_gives_the_expected_address(tmp_path):
    s = settings(peers=[Peer(name="localhost", public_ip="127.0.0.1")], local_ip="")
    s.this.name = ""
    r = await run("linux.resolve", ctx(s, tmp_path))
    assert r.status is Status.PASS and r.data["names"]["localhost"]["resolved"] == "127.0.0.1"
    assert r.data["wrong"] == [] and r.data["loopback"] == []


async def test_resolve_names_the_wrong_address(tmp_path):
    s = settings(peers=[Peer(name="localhost", public_ip="127.0.0.2")], local_ip="")
    s.this.name = ""
    r = await run("linux.resolve", ctx(s, tmp_path))
    assert r.status is Status.FAIL and r.data["wrong"] == ["localhost"]
    assert "localhost -> 127.0.0.1 (expected 127.0.0.2)" in r.summary


async def test_resolve_names_sync_pin_for_a_peer_sync_cannot_follow(tmp_path):
    """With [sync] on, a peer without a pinned sync_key never has its records counted (issue
    35): a wrong address for it says which command pins the key."""
    s = settings(peers=[Peer(name="localhost", public_ip="127.0.0.2")], local_ip="")
    s.this.name, s.has_sync = "", True
    r = await run("linux.resolve", ctx(s, tmp_path))
    assert r.status is Status.FAIL and r.data["unpinned"] == ["localhost"]
    assert "no sync key pinned; `rosnet-tui sync pin`" in r.summary, r.summary
    s.has_sync = False
    r = await run("linux.resolve", ctx(s, tmp_path))
    assert "unpinned" not in r.data and "sync pin" not in r.summary


# --------------------------------------------------------------------------- linux.ping
@pytest.mark.skipif(shutil.which("ping") is None, reason="needs ping")
async def test_ping_by_name_with_the_tcp_fallback_reported(tmp_path):
    s = settings(peers=[Peer(name="localhost", public_ip="127.0.0.1", ssh_port=free_port())])
    r = await run("linux.ping", ctx(s, tmp_path))
    assert r.status is Status.PASS, r.evidence
    port = s.peers[0].ssh_port
    # nothing listens on that port: the kernel refuses, and the kind of failure is reported
    assert r.data["peers"]["localhost"] == {"icmp": True, "tcp22": False, "tcp": "refused",
                                            "port": port}
    assert any("ping localhost (127.0.0.1): reply" in e for e in r.evidence)


async def test_ping_says_a_name_that_does_not_resolve(tmp_path):
    """A fresh install: the peer's name is in no hosts file yet. That is no silent peer."""
    s = settings(peers=[Peer(name="turtlebot.invalid", public_ip="203.0.113.2")])
    r = await run("linux.ping", ctx(s, tmp_path))
    assert r.status is Status.FAIL, r.evidence
    assert "turtlebot.invalid does not resolve" in r.summary, r.summary
    assert "no answer" not in r.summary
    assert r.data["peers"]["turtlebot.invalid"]["tcp"] == "resolve"


async def test_ping_skips_without_peers(tmp_path):
    r = await run("linux.ping", ctx(settings(peers=[]), tmp_path))
    assert r.status is Status.SKIP and "no peers" in r.summary


# --------------------------------------------------------------------------- linux.ssh
async def test_ssh_passes_with_a_verified_key(ssh_client, sshd, tmp_path):
    s = settings(peers=[ssh_client.peer(), Peer(name="nouser", public_ip="198.51.100.9")])
    r = await run("linux.ssh", ctx(s, tmp_path, ssh_client))
    assert r.status is Status.PASS, r.evidence
    p = r.data["peers"]["localhost"]
    assert p["ok"] and p["failure"] is None and p["fingerprint"] == sshd.fingerprint
    assert r.data["peers"]["nouser"]["failure"] == "no_user"


async def test_ssh_unknown_host_key_fails_with_the_fingerprint(ssh_client, sshd, tmp_path):
    (ssh_client.dir / "known_hosts").write_text("")
    r = await run("linux.ssh", ctx(settings(peers=[ssh_client.peer()]), tmp_path, ssh_client))
    assert r.status is Status.FAIL
    p = r.data["peers"]["localhost"]
    assert p["failure"] == "host_key_unknown" and p["fingerprint"] == sshd.fingerprint
    assert p["host_key"].startswith("ssh-ed25519 ")
    assert sshd.fingerprint in " ".join(r.evidence)


async def test_ssh_skips_without_an_ssh_user(tmp_path):
    r = await run("linux.ssh", ctx(settings(), tmp_path))
    assert r.status is Status.SKIP and "ssh_user" in r.summary
    assert r.data["peers"]["sami"]["failure"] == "no_user"


# --------------------------------------------------------------------------- chats
async def test_chat_out_by_name(ssh_client, tmp_path):
    r = await run("linux.chat_out", ctx(settings(peers=[ssh_client.peer()]), tmp_path, ssh_client))
    assert r.status is Status.PASS, r.evidence
    assert r.data["peers"]["localhost"] == {"ok": True, "failure": None, "tcp": "connected"}
    assert any("python3" in e for e in r.evidence)


async def test_chat_in_by_name(ssh_client, tmp_path):
    c = ctx(settings(name="localhost", local_ip="127.0.0.1", peers=[ssh_client.peer()]),
            tmp_path, ssh_client)
    r = await run("linux.chat_in", c)
    assert r.status is Status.PASS, r.evidence
    assert r.data["peers"]["localhost"] == {"ok": True, "failure": None, "tcp": "connected"}
    assert any("localhost resolves localhost -> 127.0.0.1" in e for e in r.evidence)
    assert not c.listeners.holds(c.settings.probe.port)


@pytest.mark.skipif(shutil.which("nc") is None, reason="needs nc")
async def test_chats_fall_back_to_nc_without_python3(ssh_client, tmp_path, monkeypatch):
    # no python3 on the peer: neither the round's agent nor the chats' own command finds one
    monkeypatch.setattr(probe_agents, "PEER_PYTHON", "no-such-python3")
    out = await run("linux.chat_out", ctx(settings(peers=[ssh_client.peer()]), tmp_path,
                                          ssh_client, timeout=3.0))
    assert out.status is Status.PASS, out.evidence
    assert any("(over SSH, nc)" in e for e in out.evidence)
    c = ctx(settings(name="localhost", local_ip="127.0.0.1", peers=[ssh_client.peer()]),
            tmp_path, ssh_client, timeout=3.0)
    inn = await run("linux.chat_in", c)
    assert inn.status is Status.PASS, inn.evidence


async def test_chat_in_fails_when_the_peer_cannot_reach_us(ssh_client, tmp_path):
    c = ctx(settings(name="localhost", local_ip="127.0.0.1", peers=[ssh_client.peer()]),
            tmp_path, ssh_client)
    # Something else holds our test port: the peer reaches it, but not our listener.
    import socket

    with socket.socket() as other:
        other.bind(("0.0.0.0", c.settings.probe.port))
        other.listen(4)
        r = await run("linux.chat_in", c)
    assert r.status is Status.FAIL
    assert r.data["peers"]["localhost"]["failure"] == "local_listen"


async def test_chat_out_reports_ssh_trouble(ssh_client, tmp_path):
    s = settings(peers=[ssh_client.peer(ssh_port=free_port())])
    r = await run("linux.chat_out", ctx(s, tmp_path, ssh_client))
    assert r.status is Status.FAIL and r.data["peers"]["localhost"]["failure"] == "ssh:network"


def ros2_settings(role: str, peers: list[Peer], port: int) -> Settings:
    """ROS 2 on loopback: the master is "localhost", its router port *port*."""
    return Settings(this=ThisComponent(name="localhost" if role == "master" else "sami",
                                       role=role, local_ip="127.0.0.1"),
                    peers=peers, probe=ProbeSettings(port=free_port()),
                    ros=RosSettings(master="localhost", version=2, zenoh_port=port))


async def test_ros2_chat_out_says_how_the_connection_to_the_masters_router_went(tmp_path):
    """Under ROS 2 a member's chat is its TCP connection to the master's router port; the kind
    of a failed connection is recorded as for ROS 1's chats (the advisor ranks by it)."""
    import socket

    port = free_port()
    s = ros2_settings("member", [Peer(name="localhost", public_ip="127.0.0.1")], port)
    r = await run("linux.chat_out", ctx(s, tmp_path))
    assert r.status is Status.FAIL
    assert r.data["peers"]["localhost"] == {"ok": False, "failure": "connect", "tcp": "refused"}
    with socket.socket() as router:
        router.bind(("127.0.0.1", port))
        router.listen(4)
        r = await run("linux.chat_out", ctx(s, tmp_path))
    assert r.status is Status.PASS, r.evidence
    assert r.data["peers"]["localhost"]["tcp"] == "connected"
    inn = await run("linux.chat_in", ctx(s, tmp_path))
    assert inn.status is Status.SKIP and "accepts no connections" in inn.summary


async def test_ros2_chat_in_on_the_master_records_the_members_connection(ssh_client, tmp_path):
    s = ros2_settings("master", [ssh_client.peer()], free_port())
    r = await run("linux.chat_in", ctx(s, tmp_path, ssh_client))
    assert r.status is Status.PASS, r.evidence
    assert r.data["peers"]["localhost"] == {"ok": True, "failure": None, "tcp": "connected"}


async def test_chats_skip_without_an_ssh_user(tmp_path):
    for cid in ("linux.chat_out", "linux.chat_in"):
        r = await run(cid, ctx(settings(), tmp_path))
        assert r.status is Status.SKIP and r.data["peers"]["sami"]["failure"] == "no_user"


@pytest.mark.skipif(shutil.which("nc") is None, reason="needs nc")
def test_the_nc_listener_says_it_is_nc_before_it_says_listening(monkeypatch):
    """chat_out reads the peer's output up to LISTENING and decides from what it read whether nc
    listens (slow to start: connect tried again) or python3 (once). nc's NC came after LISTENING:
    when the two lines arrived apart, the check took nc for python3, tried once, was refused
    (test_chats_fall_back_to_nc_without_python3 failed about 1 run in 5)."""
    import subprocess

    from rosnet_tui.core.checks.linux_chat import listen_command

    monkeypatch.setattr(probe_agents, "PEER_PYTHON", "no-such-python3")
    cmd = listen_command(free_port(), "t0ken", 1.0)
    with subprocess.Popen(["sh", "-c", cmd], stdout=subprocess.PIPE, text=True) as p:
        try:
            before = []
            for line in p.stdout:      # bounded: nc gives up after the chat's wait (1 s)
                before.append(line)
                if line.startswith("LISTENING"):
                    break
        finally:
            p.kill()
    assert "NC\n" in before, before
