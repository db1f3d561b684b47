"""known_hosts matching: a key listed for one host is never accepted for another whose name
only starts the same (``robot`` / ``robot2``, ``[h]:2`` / ``[h]:22``), and the rest of the
OpenSSH host-field grammar (wildcards, negations, hashed names, markers) as OpenSSH reads it."""

from __future__ import annotations

import base64
import hashlib
import hmac

from rosnet_tui.core.ssh.known_hosts import host_key_name, known_host_keys


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
