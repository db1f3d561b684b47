"""The hosts writer: each profile's set from the settings, our block only, conflicts, bad input."""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rosnet_tui.core.config.settings_model import Peer, RosSettings, Settings, ThisComponent
from rosnet_tui.core.files import managed_file as mf
from rosnet_tui.core.files import managed_text as mt
from rosnet_tui.core.files.hosts import (
    WriterSettingsError,
    active_profile,
    apply_hosts,
    find_hosts_conflicts,
    hosts_problems,
    preview_hosts,
    render_hosts_block,
)


def robot(**this) -> Settings:
    t = dict(name="turtlebot", role="master", connection="telecom", profile="remote",
             local_ip="10.10.10.1", public_ip="203.0.113.2", office_ip="172.16.0.5")
    t.update(this)
    return Settings(this=ThisComponent(**t),
                    peers=[Peer(name="sami", local_ip="192.168.1.10", public_ip="198.51.100.2",
                                office_ip="172.16.0.6", portable_ip="192.168.43.20")],
                    ros=RosSettings(master="turtlebot"))


def active_entries(block: list[str]) -> list[tuple[str, str]]:
    return [tuple(line.split("#")[0].split()[:2]) for line in block
            if line and not line.startswith("#")]


# --------------------------------------------------------------------------- the sets
def test_remote_set_own_name_local_ip_peers_public_ip():
    block = render_hosts_block(robot(), "remote")
    assert active_entries(block) == [("10.10.10.1", "turtlebot"), ("198.51.100.2", "sami")]
    assert "# Active set: remote" in "\n".join(block)


def test_office_and_portable_sets_use_lan_addresses():
    assert active_entries(render_hosts_block(robot(), "office")) == \
        [("172.16.0.5", "turtlebot"), ("172.16.0.6", "sami")]
    # no portable_ip for this component: its local IP stands in
    assert active_entries(render_hosts_block(robot(), "portable")) == \
        [("10.10.10.1", "turtlebot"), ("192.168.43.20", "sami")]


def test_inactive_sets_are_kept_as_comments_for_switching_by_hand():
    text = "\n".join(render_hosts_block(robot(), "remote"))
    assert "# Inactive set: office" in text and "#  172.16.0.6" in text
    assert "# Inactive set: portable" in text


def test_default_profile_is_the_one_in_the_settings():
    assert active_entries(render_hosts_block(robot(profile="office"))) == \
        [("172.16.0.5", "turtlebot"), ("172.16.0.6", "sami")]


@pytest.mark.parametrize("change, key", [
    ({"local_ip": "10.10.10.300"}, "this.local_ip"),
    ({"local_ip": ""}, "this.local_ip"),
    ({"local_ip": "127.0.1.1"}, "this.local_ip"),
    ({"name": "turtle bot"}, "this.name"),
    ({"office_ip": "fe80::1"}, "this.office_ip"),
])
def test_bad_settings_write_nothing_and_say_why(tmp_path, change, key):
    f, sd = tmp_path / "hosts", tmp_path / "state"
    f.write_bytes(b"127.0.0.1 localhost\n")
    s = robot(**change)
    profile = "office" if key == "this.office_ip" else "remote"
    with pytest.raises(WriterSettingsError) as info:
        apply_hosts(s, profile, f, state_dir=sd)
    assert key in [k for k, _ in info.value.problems]
    assert "nothing was written" in str(info.value)
    assert f.read_bytes() == b"127.0.0.1 localhost\n"
    assert not sd.exists()


def test_bad_peer_address_is_named():
    s = robot()
    s.peers[0].public_ip = "198.51.100.999"
    assert [k for k, _ in hosts_problems(s, "remote")] == ["peer[1].public_ip"]


def test_peer_without_an_address_for_the_profile_is_left_out():
    s = robot()
    s.peers.append(Peer(name="ops", local_ip="192.168.1.11"))  # no public IP
    assert ("192.168.1.11", "ops") not in active_entries(render_hosts_block(s, "remote"))
    assert ("192.168.1.11", "ops") in active_entries(render_hosts_block(s, "office"))


# --------------------------------------------------------------------------- writing
STOCK = (b"127.0.0.1\tlocalhost\n127.0.1.1\tturtlebot\n\n"
         b"# The following lines are desirable for IPv6 capable hosts\n"
         b"::1     ip6-localhost ip6-loopback\nfe00::0 ip6-localnet\n")


def test_apply_puts_the_block_on_top_and_keeps_the_rest(tmp_path):
    f, sd = tmp_path / "hosts", tmp_path / "state"
    f.write_bytes(STOCK)
    r = apply_hosts(robot(), "remote", f, state_dir=sd)
    out = f.read_bytes()
    assert r.changed and out.startswith(mt.BEGIN_MARKER.encode()) and out.endswith(STOCK)
    assert active_profile(out.decode()) == "remote"
    assert not apply_hosts(robot(), "remote", f, state_dir=sd).changed  # idempotent


def test_switching_profile_changes_only_the_block(tmp_path):
    f, sd = tmp_path / "hosts", tmp_path / "state"
    f.write_bytes(STOCK)
    apply_hosts(robot(), "remote", f, state_dir=sd)
    apply_hosts(robot(), "office", f, state_dir=sd)
    text = f.read_text()
    assert active_profile(text) == "office" and text.endswith(STOCK.decode())
    mf.undo_last(sd)
    assert active_profile(f.read_text()) == "remote"
    mf.undo_last(sd)
    assert f.read_bytes() == STOCK


def test_stale_digest_is_refused(tmp_path):
    f = tmp_path / "hosts"
    f.write_bytes(STOCK)
    p = preview_hosts(robot(), "remote", f)
    with open(f, "ab") as fh:
        fh.write(b"10.1.1.1 other\n")
    with pytest.raises(mt.StalePreviewError):
        apply_hosts(robot(), "remote", f, expect_digest=p.digest, state_dir=tmp_path / "s")
    assert f.read_bytes() == STOCK + b"10.1.1.1 other\n"


def test_conflicting_lines_are_reported_and_fixed_only_when_asked(tmp_path):
    f, sd = tmp_path / "hosts", tmp_path / "state"
    f.write_bytes(b"127.0.0.1 localhost turtlebot\r\n127.0.1.1\tturtlebot\n"
                  b"203.0.113.99 sami # stale\n10.10.10.1 turtlebot\n")
    conflicts = find_hosts_conflicts(f.read_text(), robot(), "remote")
    assert [c.lineno for c in conflicts] == [1, 2, 3]  # same address on line 4: no conflict
    p = preview_hosts(robot(), "remote", f)
    assert sum("conflict" in n or "--comment-conflicts" in n for n in p.notes) == 3
    assert p.new.endswith(f.read_bytes())  # not asked: outside lines untouched
    apply_hosts(robot(), "remote", f, fix_conflicts=True, state_dir=sd)
    lines = f.read_bytes().split(b"\n")
    i = lines.index(mt.END_MARKER.encode()) + 1
    assert lines[i] == b"127.0.0.1\tlocalhost # rosnet-tui took out: turtlebot\r"
    assert lines[i + 1] == b"# rosnet-tui: 127.0.1.1\tturtlebot"
    assert lines[i + 2] == b"# rosnet-tui: 203.0.113.99 sami # stale"
    assert lines[i + 3] == b"10.10.10.1 turtlebot"
    mf.undo_last(sd)
    assert f.read_bytes().startswith(b"127.0.0.1 localhost turtlebot\r\n")


@pytest.mark.skipif(os.geteuid() != 0 or not shutil.which("unshare")
                    or not shutil.which("getent"), reason="needs root, unshare and getent")
def test_the_system_resolver_returns_our_address(tmp_path):
    """glibc, with Debian's 'multi on', sorts 127.0.1.1 first: fixing the conflict matters."""
    f, sd = tmp_path / "hosts", tmp_path / "state"
    f.write_bytes(STOCK)

    def resolve() -> str:
        r = subprocess.run(["unshare", "-m", "sh", "-c",
                            f"mount --bind {f} /etc/hosts && getent ahostsv4 turtlebot"],
                           capture_output=True, text=True, timeout=10)
        if r.returncode not in (0, 2):
            pytest.skip(f"cannot bind-mount in a private mount namespace: {r.stderr.strip()}")
        return r.stdout.split()[0] if r.stdout.split() else ""

    apply_hosts(robot(), "remote", f, state_dir=sd)
    with open("/etc/host.conf", errors="replace") if Path("/etc/host.conf").exists() \
            else open(os.devnull) as hc:
        multi = "multi on" in hc.read()
    if multi:
        assert resolve() == "127.0.1.1"  # the stock 127.0.1.1 line still wins
    apply_hosts(robot(), "remote", f, fix_conflicts=True, state_dir=sd)
    assert resolve() == "10.10.10.1"


# --------------------------------------------------------------------------- properties
_HOSTS_LINES = st.sampled_from([
    "127.0.0.1\tlocalhost", "127.0.1.1 turtlebot.example turtlebot", "::1 localhost ip6-localhost",
    "fe80::1%eth0\trouter6", "# comment", "", "  \t", "192.168.7.7  nas # note",
    "10.0.0.8\tsami-old", "ff02::1 ip6-allnodes", "not an address line",
])


@st.composite
def hosts_files(draw) -> bytes:
    lines = draw(st.lists(_HOSTS_LINES, max_size=12))
    endings = [draw(st.sampled_from(["\n", "\r\n"])) for _ in lines]
    text = "".join(x + e for x, e in zip(lines, endings, strict=True))
    if text and draw(st.booleans()):
        text = text.rstrip("\r\n")
    return text.encode()


@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=hosts_files(), profile=st.sampled_from(["remote", "office", "portable"]),
       fix=st.booleans())
def test_generated_hosts_files_apply_undo_and_idempotence(data, profile, fix):
    with tempfile.TemporaryDirectory() as d:
        f, sd = Path(d) / "hosts", Path(d) / "state"
        f.write_bytes(data)
        first = apply_hosts(robot(), profile, f, fix_conflicts=fix, state_dir=sd)
        once = f.read_bytes()
        assert not apply_hosts(robot(), profile, f, fix_conflicts=fix, state_dir=sd).changed
        assert f.read_bytes() == once
        if not fix:  # everything after our top block is the old file, byte for byte
            assert once.endswith(data)
        else:
            changed = {c.index for c in find_hosts_conflicts(data.decode(), robot(), profile)}
            old = [mt.line_content(x) for x in mt.split_lines(data.decode())]
            new = mt.split_lines(once.decode())
            end = next(i for i, x in enumerate(new) if x.startswith(mt.END_MARKER))
            new = [mt.line_content(x) for x in new[end + 1:]]
            assert len(new) == len(old)
            for i, (a, b) in enumerate(zip(old, new, strict=True)):
                assert a == b or (i in changed and "rosnet-tui" in b)
        if first.changed:
            mf.undo_last(sd)
        assert f.read_bytes() == data
