"""known_hosts matching: a key listed for one host is never accepted for another whose name
only starts the same (``robot`` / ``robot2``, ``[h]:2`` / ``[h]:22``), and the rest of the
OpenSSH host-field grammar (wildcards, negations, hashed names, markers) as OpenSSH reads it."""

from __future__ import annotations

import base64
import hashlib
import hmac
import os
import stat
import subprocess

import pytest

from rosnet_tui.core.ssh.known_hosts import (
    fingerprint_command,
    host_key_name,
    key_fingerprint,
    known_host_keys,
    trust_host_key,
    verify_commands,
)
from rosnet_tui.core.ssh.options import SshOptions


def _blob(ktype: str = "ssh-ed25519", fill: int = 1) -> bytes:
    t = ktype.encode()
    return len(t).to_bytes(4, "big") + t + (32).to_bytes(4, "big") + bytes([fill]) * 32


def _line(hosts: str, fill: int = 1, ktype: str = "ssh-ed25519", marker: str = "") -> str:
    b64 = base64.b64encode(_blob(ktype, fill)).decode()
    return f"{marker + ' ' if marker else ''}{hosts} {ktype} {b64}"


def _keys(tmp_path, lines: list[str], lookup: str):
    f = tmp_path / "known_hosts"
    f.write_text("\n".join(lines) + "\n")
    return known_host_keys([f], lookup)


def test_a_key_for_robot_is_not_a_key_for_robot2_nor_the_other_way(tmp_path):
    assert _keys(tmp_path, [_line("robot")], "robot2").keys == {}
    assert _keys(tmp_path, [_line("robot2")], "robot").keys == {}
    assert _keys(tmp_path, [_line("robot")], "robot").keys == {"ssh-ed25519": [_blob()]}


def test_a_key_for_port_2_is_not_a_key_for_port_22(tmp_path):
    assert _keys(tmp_path, [_line("[h]:2")], host_key_name("h", 22)).keys == {}
    assert _keys(tmp_path, [_line("[h]:2")], "[h]:22").keys == {}
    assert _keys(tmp_path, [_line("[h]:22")], "[h]:2").keys == {}
    assert _keys(tmp_path, [_line("[h]:2")], host_key_name("h", 2)).keys["ssh-ed25519"]
    assert host_key_name("h", 22) == "h" and host_key_name("h", 2222) == "[h]:2222"


def test_wildcards_match_whole_names_only(tmp_path):
    assert _keys(tmp_path, [_line("rob?t")], "robot").keys
    assert _keys(tmp_path, [_line("rob?t")], "robot2").keys == {}
    assert _keys(tmp_path, [_line("*.lab")], "a.lab").keys
    assert _keys(tmp_path, [_line("*.lab")], "a.lab.example").keys == {}
    assert _keys(tmp_path, [_line("ROBOT")], "robot").keys      # case-insensitive
    assert _keys(tmp_path, [_line("r.bot")], "robot").keys == {}  # '.' is literal


def test_a_negated_pattern_excludes_the_host_whatever_else_matches(tmp_path):
    assert _keys(tmp_path, [_line("*,!robot")], "robot").keys == {}
    assert _keys(tmp_path, [_line("!robot,*")], "robot").keys == {}
    assert _keys(tmp_path, [_line("*,!robot")], "laptop").keys
    assert _keys(tmp_path, [_line("!robot")], "laptop").keys == {}   # only a negation: no match


def test_hashed_names_match_their_own_host_only(tmp_path):
    salt = bytes(range(20))
    digest = hmac.new(salt, b"robot", hashlib.sha1).digest()
    field = f"|1|{base64.b64encode(salt).decode()}|{base64.b64encode(digest).decode()}"
    assert _keys(tmp_path, [_line(field)], "robot").keys
    assert _keys(tmp_path, [_line(field)], "robot2").keys == {}
    assert _keys(tmp_path, [_line(field + "|x")], "robot").keys == {}
    assert _keys(tmp_path, [_line("|1|!!!|" + base64.b64encode(digest).decode())],
                 "robot").keys == {}


def test_every_listed_key_counts_and_a_repeat_counts_once(tmp_path):
    k = _keys(tmp_path, [_line("robot", 1), _line("robot", 2), _line("robot", 1),
                         _line("robot", 3, "ecdsa-sha2-nistp256")], "robot")
    assert k.keys["ssh-ed25519"] == [_blob(fill=1), _blob(fill=2)]
    assert list(k.keys) == ["ssh-ed25519", "ecdsa-sha2-nistp256"]
    assert k.fingerprints("ssh-ed25519")[0].startswith("SHA256:")
    assert len(k.fingerprints()) == 3 and k.notes == []


def test_markers_revoked_for_any_host_and_cert_authority_noted(tmp_path):
    k = _keys(tmp_path, [_line("other", 7, marker="@revoked"), _line("robot", 7),
                         _line("robot", 8, marker="@cert-authority")], "robot")
    assert k.revoked == {_blob(fill=7)}
    assert k.keys == {"ssh-ed25519": [_blob(fill=7)]}     # the checker refuses it as revoked
    assert len(k.notes) == 1 and "1 @cert-authority line(s)" in k.notes[0]
    k = _keys(tmp_path, [_line("other", 8, marker="@cert-authority")], "robot")
    assert k.notes == [] and k.keys == {}


def test_malformed_lines_for_this_host_are_counted_and_skipped(tmp_path):
    wrong_type = base64.b64encode(_blob("ssh-rsa")).decode()
    lines = ["robot ssh-ed25519",                           # too few fields
             "robot ssh-ed25519 not-base64!",
             f"robot ssh-ed25519 {wrong_type}",             # blob of another type
             "robot ssh-ed25519 " + base64.b64encode(b"\0\0").decode(),   # too short
             "robot ssh-ed25519 " + base64.b64encode(_blob()[:15]).decode(),  # type, no key
             "other ssh-ed25519",                           # malformed, other host: not counted
             "# robot ssh-ed25519 comment", "", _line("robot", 4)]
    k = _keys(tmp_path, lines, "robot")
    assert k.keys == {"ssh-ed25519": [_blob(fill=4)]}
    assert k.notes == ["5 malformed line(s) for this host skipped"]


def test_missing_files_are_skipped_and_later_files_still_read(tmp_path):
    f = tmp_path / "kh2"
    f.write_text(_line("robot", 5) + "\n")
    k = known_host_keys([tmp_path / "missing", tmp_path, f], "robot")
    assert k.keys == {"ssh-ed25519": [_blob(fill=5)]}


def test_base64_with_stray_characters_is_not_a_key_nor_a_hashed_name(tmp_path):
    b64 = base64.b64encode(_blob()).decode()
    stray = b64[:8] + "!" + b64[8:]            # lenient base64 would drop the "!" and read it
    assert _keys(tmp_path, [f"robot ssh-ed25519 {stray}"], "robot").keys == {}
    salt = bytes(range(20))
    digest = base64.b64encode(hmac.new(salt, b"robot", hashlib.sha1).digest()).decode()
    salt64 = base64.b64encode(salt).decode()
    assert _keys(tmp_path, [_line(f"|1|{salt64}|{digest}")], "robot").keys
    assert _keys(tmp_path, [_line(f"|1|{salt64[:4]}!{salt64[4:]}|{digest}")], "robot").keys == {}


def test_a_blob_is_taken_when_anything_follows_its_type_name(tmp_path):
    t = b"ssh-ed25519"
    blob = len(t).to_bytes(4, "big") + t + b"\0"
    line = f"robot ssh-ed25519 {base64.b64encode(blob).decode()}"
    assert _keys(tmp_path, [line], "robot").keys == {"ssh-ed25519": [blob]}


def test_fingerprints_are_openssh_sha256_and_filtered_by_type(tmp_path):
    fp = key_fingerprint(_blob())
    want = base64.b64encode(hashlib.sha256(_blob()).digest()).decode()
    assert want.endswith("=") and fp == "SHA256:" + want.rstrip("=") and len(fp) == 50
    k = _keys(tmp_path, [_line("robot", 1), _line("robot", 3, "ecdsa-sha2-nistp256")], "robot")
    assert k.fingerprints("ecdsa-sha2-nistp256") == [key_fingerprint(_blob("ecdsa-sha2-nistp256",
                                                                           3))]
    assert k.fingerprints("ssh-rsa") == []
    assert k.fingerprints() == [key_fingerprint(_blob()),
                                key_fingerprint(_blob("ecdsa-sha2-nistp256", 3))]


def _host_key(fill: int = 1, comment: str = "") -> str:
    return f"ssh-ed25519 {base64.b64encode(_blob(fill=fill)).decode()}" + (
        f" {comment}" if comment else "")


def test_trusting_a_key_writes_one_private_line_in_a_private_folder(tmp_path):
    opts = SshOptions(ssh_dir=tmp_path / "a" / "ssh")
    path = trust_host_key(opts, "robot", 2222, _host_key(comment="root@robot"))
    assert path == tmp_path / "a" / "ssh" / "known_hosts"
    assert path.read_text() == f"[robot]:2222 {_host_key()}\n"   # the comment is not kept
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o600
    assert stat.S_IMODE(os.stat(path.parent).st_mode) == 0o700
    assert known_host_keys([path], "[robot]:2222").keys == {"ssh-ed25519": [_blob()]}
    trust_host_key(opts, "robot", 22, _host_key(2))               # appended, port 22 plain
    assert path.read_text().splitlines()[1] == f"robot {_host_key(2)}"


def test_trusting_appends_after_a_last_line_without_newline(tmp_path):
    (tmp_path / "known_hosts").write_text(_line("other"))
    trust_host_key(SshOptions(ssh_dir=tmp_path), "robot", 22, _host_key())
    assert (tmp_path / "known_hosts").read_text() == f"{_line('other')}\nrobot {_host_key()}\n"


def test_trusting_refuses_garbage_a_second_key_and_what_is_not_a_file(tmp_path):
    opts = SshOptions(ssh_dir=tmp_path)
    with pytest.raises(ValueError):
        trust_host_key(opts, "robot", 22, "ssh-ed25519 not*base64")
    trust_host_key(opts, "robot", 22, _host_key(1))
    with pytest.raises(ValueError, match="already has a ssh-ed25519 key for robot; remove it "
                                         "first .ssh-keygen -R robot."):
        trust_host_key(opts, "robot", 22, _host_key(2))
    assert (tmp_path / "known_hosts").read_text().count("\n") == 1
    fifo = tmp_path / "f"
    fifo.mkdir()
    os.mkfifo(fifo / "known_hosts")
    with pytest.raises(ValueError, match=r"not a regular file \(a FIFO\?\); nothing was written"):
        trust_host_key(SshOptions(ssh_dir=fifo), "robot", 22, _host_key())
    dev = tmp_path / "d"
    dev.mkdir()
    (dev / "known_hosts").symlink_to("/dev/null")
    with pytest.raises(ValueError, match="not a regular file; nothing was written"):
        trust_host_key(SshOptions(ssh_dir=dev), "robot", 22, _host_key())


def test_verify_commands_ask_the_machine_itself_for_the_key_of_the_type_shown():
    """Its own sshd is asked on the machine itself (wherever it keeps its keys); the check from
    here it also offered proved nothing (a man in the middle answers it too)."""
    v = verify_commands("robot", 2222, "ecdsa-sha2-nistp256", "ops")
    assert "`ssh-keyscan -t ecdsa -p 2222 127.0.0.1 2>/dev/null | ssh-keygen -lf -`" in v
    assert "prints on robot itself" in v and "`ssh -p 2222 ops@robot`" in v
    assert "from here" not in v and "ssh-keyscan -p 2222 robot" not in v
    v = verify_commands("robot", 22, "ssh-rsa")
    assert "`ssh-keyscan -t rsa 127.0.0.1 2>/dev/null" in v and "`ssh robot`" in v
    assert "ssh-keyscan 127.0.0.1 2>" in verify_commands("robot", 22, "ssh-unknown")   # all types
    assert fingerprint_command(22, "ssh-dss").startswith("ssh-keyscan -t dsa 127.0.0.1")


def test_the_fingerprint_command_finds_keys_sshd_keeps_outside_etc_ssh(sshd):
    """The advice used to name /etc/ssh/ssh_host_ed25519_key.pub: a real sshd whose only host key
    is elsewhere (this one's, in its own folder) is asked, and prints that key's fingerprint."""
    cmd = fingerprint_command(sshd.port, "ssh-ed25519")
    r = subprocess.run(["sh", "-c", cmd], capture_output=True, text=True, timeout=30)
    assert sshd.fingerprint in r.stdout, (cmd, r.stdout, r.stderr)
    assert not str(sshd.host_key).startswith("/etc/ssh")


def test_lines_after_markers_other_hosts_and_bad_bytes_are_still_read(tmp_path):
    f = tmp_path / "known_hosts"
    f.write_bytes(b"\xff\xfe not utf-8\n" + "\n".join([
        _line("robot", 1, marker="@cert-authority"), _line("robot", 2, marker="@cert-authority"),
        _line("robot", 3), _line("other", 4), _line("robot", 5, marker="@revoked"),
        _line("robot", 6, marker="@unknown"), "robot", "robot ssh-ed25519", _line("robot", 7),
    ]).encode() + b"\n")
    k = known_host_keys([f], "robot")
    assert k.keys == {"ssh-ed25519": [_blob(fill=3), _blob(fill=7)]}   # revoked: never a key
    assert k.revoked == {_blob(fill=5)}
    assert k.notes == ["2 @cert-authority line(s) for this host not used (host certificates are "
                       "not checked; the server's own key must be listed)",
                       "3 malformed line(s) for this host skipped"]


def test_a_hashed_name_with_stray_characters_in_its_digest_matches_nothing(tmp_path):
    salt = bytes(range(20))
    digest = base64.b64encode(hmac.new(salt, b"robot", hashlib.sha1).digest()).decode()
    field = f"|1|{base64.b64encode(salt).decode()}|{digest[:4]}!{digest[4:]}"
    assert _keys(tmp_path, [_line(field)], "robot").keys == {}


def test_trusting_refuses_lenient_base64_and_ends_a_one_byte_file_first(tmp_path):
    b64 = base64.b64encode(_blob()).decode()
    with pytest.raises(ValueError):
        trust_host_key(SshOptions(ssh_dir=tmp_path), "robot", 22,
                       f"ssh-ed25519 {b64[:8]}!{b64[8:]}")
    assert not (tmp_path / "known_hosts").exists()
    (tmp_path / "known_hosts").write_text("#")
    trust_host_key(SshOptions(ssh_dir=tmp_path), "robot", 22, _host_key())
    assert (tmp_path / "known_hosts").read_text() == f"#\nrobot {_host_key()}\n"


def test_a_key_type_that_is_not_ascii_is_a_malformed_line_not_a_crash(tmp_path):
    b64 = base64.b64encode(_blob()).decode()
    k = _keys(tmp_path, [f"robot ssh-ed25519\u00e9 {b64}", _line("robot", 2)], "robot")
    assert k.keys == {"ssh-ed25519": [_blob(fill=2)]}
    assert k.notes == ["1 malformed line(s) for this host skipped"]
