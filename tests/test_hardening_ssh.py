"""Issue 15, SSH host keys, against a real sshd on 127.0.0.1 (the fixtures of tests/plugins/ssh.py).

Reproduced: one ``@cert-authority`` or ``@revoked`` line anywhere in known_hosts made paramiko
raise, uncaught: every SSH check then failed as "sshd problem", even for peers whose key was
listed, and an unknown key's fingerprint was no longer shown. Two keys of one type for a host:
only the first counted, the server's (second) key was "CHANGED, refused". Now: lines we cannot
use are skipped (and said in the result's detail), ``@revoked`` is a refusal, and any listed key
of the server's type is accepted, as OpenSSH does.
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import os
import shutil
import subprocess
import time

import pytest

from rosnet_tui.core.ssh.known_hosts import host_key_name, trust_host_key
from rosnet_tui.core.ssh.session import ssh_run
from tests.hardening_tally import tally
from tests.plugins.ssh import SSHD, keygen

pytestmark = pytest.mark.skipif(not os.path.exists(SSHD) or not shutil.which("ssh-keygen"),
                                reason="needs OpenSSH (sshd, ssh-keygen)")
AREA = "ssh host keys"


def key_part(pub_line: str) -> str:
    """'type base64' of a public key line (comment dropped)."""
    return " ".join(pub_line.split()[:2])


def write_kh(client, *lines: str) -> None:
    (client.dir / "known_hosts").write_text("".join(x + "\n" for x in lines))


def host(sshd) -> str:
    return host_key_name("localhost", sshd.port)


async def run(client, **kw):
    return await ssh_run(client.opts(), client.peer(**kw), "echo ok", timeout=10)


def no_login_since(sshd, before: str) -> bool:
    return "publickey" not in sshd.log_until_ended(before)


@pytest.fixture
def other_keys(tmp_path):
    """Public key parts of throwaway keys: two ed25519, one ecdsa, one rsa (a CA)."""
    return {n: key_part(keygen(tmp_path / n, kind))
            for n, kind in (("ed1", "ed25519"), ("ed2", "ed25519"), ("ecdsa", "ecdsa"),
                            ("ca", "ed25519"))}


# --------------------------------------------------------------------------- @cert-authority
async def test_a_cert_authority_line_anywhere_does_not_break_a_listed_host(ssh_client, sshd,
                                                                           other_keys):
    mine = f"{host(sshd)} {key_part(sshd.host_pub)}"
    ca_other = f"@cert-authority *.robots.example {other_keys['ca']}"
    ca_ours = f"@cert-authority {host(sshd)} {other_keys['ca']}"
    for lines in ([ca_other, mine], [mine, ca_other], [ca_ours, mine], [mine, ca_ours],
                  [ca_other, ca_ours, mine, ca_other]):
        write_kh(ssh_client, *lines)
        res = await run(ssh_client)
        assert res.ok and res.stdout == "ok\n", (lines, res.detail)
        if ca_ours in lines:
            assert "@cert-authority" in res.detail and "not used" in res.detail, res.detail
    tally(AREA, 5, 5, "@cert-authority + listed")


async def test_with_only_a_cert_authority_line_the_key_is_unknown_and_its_fingerprint_shown(
        ssh_client, sshd, other_keys):
    write_kh(ssh_client, f"@cert-authority {host(sshd)} {other_keys['ca']}",
             f"@cert-authority * {other_keys['ca']}")
    before = sshd.log.read_text()
    res = await run(ssh_client)
    assert not res.ok and res.failure == "host_key_unknown", res.detail
    assert res.fingerprint == sshd.fingerprint and sshd.fingerprint in res.detail
    assert "@cert-authority" in res.detail
    assert no_login_since(sshd, before)
    tally(AREA, 1, 1, "@cert-authority only")


# --------------------------------------------------------------------------- @revoked
async def test_a_revoked_key_is_refused_even_when_also_listed(ssh_client, sshd):
    mine = f"{host(sshd)} {key_part(sshd.host_pub)}"
    for lines in ([mine, f"@revoked {host(sshd)} {key_part(sshd.host_pub)}"],
                  [f"@revoked * {key_part(sshd.host_pub)}", mine],
                  [f"@revoked other-host {key_part(sshd.host_pub)}", mine]):
        write_kh(ssh_client, *lines)
        before = sshd.log.read_text()
        res = await run(ssh_client)
        assert not res.ok and res.failure == "host_key_changed", (lines, res.detail)
        assert "REVOKED" in res.detail and res.fingerprint == sshd.fingerprint
        assert no_login_since(sshd, before)
    tally(AREA, 3, 3, "@revoked")


async def test_another_revoked_key_does_not_stop_a_listed_one(ssh_client, sshd, other_keys):
    write_kh(ssh_client, f"@revoked {host(sshd)} {other_keys['ed1']}",
             f"{host(sshd)} {key_part(sshd.host_pub)}")
    res = await run(ssh_client)
    assert res.ok, res.detail
    tally(AREA, 1, 1, "@revoked other")


# --------------------------------------------------------------------------- several keys
async def test_any_listed_key_of_the_servers_type_is_accepted(ssh_client, sshd, other_keys):
    mine = f"{host(sshd)} {key_part(sshd.host_pub)}"
    o1 = f"{host(sshd)} {other_keys['ed1']}"
    o2 = f"{host(sshd)} {other_keys['ed2']}"
    ec = f"{host(sshd)} {other_keys['ecdsa']}"
    for lines in ([o1, mine], [mine, o1], [o1, o2, mine], [ec, o1, mine, o2]):
        write_kh(ssh_client, *lines)
        res = await run(ssh_client)
        assert res.ok, (lines, res.detail)
    tally(AREA, 4, 4, "several keys")


async def test_none_of_several_listed_keys_is_still_changed_and_names_them(ssh_client, sshd,
                                                                           other_keys, tmp_path):
    write_kh(ssh_client, f"{host(sshd)} {other_keys['ed1']}", f"{host(sshd)} {other_keys['ed2']}")
    before = sshd.log.read_text()
    res = await run(ssh_client)
    assert not res.ok and res.failure == "host_key_changed" and "CHANGED" in res.detail
    for n in ("ed1", "ed2"):
        pub = tmp_path / f"{n}.pub"
        fp = subprocess.run(["ssh-keygen", "-lf", str(pub)], capture_output=True, text=True,
                            check=True, timeout=10).stdout.split()[1]
        assert fp in res.detail
    assert no_login_since(sshd, before)
    tally(AREA, 1, 1, "several keys, none")


# --------------------------------------------------------------------------- spellings
def _hashed(name: str) -> str:
    salt = os.urandom(20)
    digest = hmac.new(salt, name.encode(), hashlib.sha1).digest()
    return f"|1|{base64.b64encode(salt).decode()}|{base64.b64encode(digest).decode()}"


async def test_hashed_wildcard_case_and_negated_entries(ssh_client, sshd, tmp_path):
    key = key_part(sshd.host_pub)
    kh = ssh_client.dir / "known_hosts"
    # ssh-keygen -H hashes a plain file the way OpenSSH writes HashKnownHosts entries
    kh.write_text(f"{host(sshd)} {key}\n")
    subprocess.run(["ssh-keygen", "-H", "-f", str(kh)], capture_output=True, check=True,
                   timeout=10)
    assert kh.read_text().startswith("|1|")
    assert (await run(ssh_client)).ok
    ok_spellings = [f"{_hashed(host(sshd))} {key}", f"[LOCALHOST]:{sshd.port} {key}",
                    f"[local*]:{sshd.port} {key}", f"[localhos?]:{sshd.port} {key}",
                    f"nothing,{host(sshd)} {key}", f"* {key}",
                    f"{host(sshd)}\t{key}\tcomment with spaces",
                    f"  {host(sshd)}   {key}  "]
    for line in ok_spellings:
        write_kh(ssh_client, line)
        res = await run(ssh_client)
        assert res.ok, (line, res.detail)
    not_ours = [f"*,!{host(sshd)} {key}", f"!{host(sshd)},* {key}", f"{_hashed('other')} {key}",
                f"localhost {key}", f"[localhost]:{sshd.port + 1} {key}"]
    for line in not_ours:
        write_kh(ssh_client, line)
        res = await run(ssh_client)
        assert res.failure == "host_key_unknown", (line, res.detail)
        assert res.fingerprint == sshd.fingerprint
    tally(AREA, 1 + len(ok_spellings) + len(not_ours), 1 + len(ok_spellings) + len(not_ours),
          "spellings")


async def test_malformed_lines_are_skipped_and_the_good_one_counts(ssh_client, sshd, other_keys):
    key = key_part(sshd.host_pub)
    ktype, blob = key.split()
    garbage = [
        f"{host(sshd)} ssh-ed25519 !!!not-base64!!!",
        f"{host(sshd)} ssh-ed25519",
        f"{host(sshd)}",
        f"{host(sshd)} ecdsa-sha2-nistp256 {blob}",        # the blob says another type
        f"{host(sshd)} ssh-ed25519 {base64.b64encode(b'short').decode()}",
        "@revoked",
        "@revoked *",
        f"@cert-authority {host(sshd)}",
        f"@weird-marker {host(sshd)} {other_keys['ed1']}",
        "\x00\x01\x02 binary \xff",
        f"{host(sshd)} ssh-ed25519 " + "A" * 100_000,
        "|1|bad|hash ssh-ed25519 " + blob,
        "|1|" + "=" * 10 + "|" + "x" * 10 + f" {key}",
        "[" * 5000 + f" {key}",
    ]
    write_kh(ssh_client, *garbage, f"{host(sshd)} {key}\r")
    res = await run(ssh_client)
    assert res.ok, res.detail
    tally(AREA, len(garbage), len(garbage), "malformed lines")


async def test_a_known_hosts_that_is_not_a_file_never_hangs(ssh_client, sshd):
    kh = ssh_client.dir / "known_hosts"
    kh.unlink()
    os.mkfifo(kh)
    started = time.monotonic()
    res = await run(ssh_client)
    assert res.failure == "host_key_unknown" and res.fingerprint == sshd.fingerprint
    assert time.monotonic() - started < 10
    tally(AREA, 1, 1, "fifo")


async def test_trust_still_refuses_a_second_key_of_a_type_it_has(ssh_client, sshd, other_keys):
    write_kh(ssh_client, f"@cert-authority * {other_keys['ca']}",
             f"{host(sshd)} {other_keys['ed1']}")
    with pytest.raises(ValueError, match="already has"):
        trust_host_key(ssh_client.opts(), "localhost", sshd.port, key_part(sshd.host_pub))
    tally(AREA, 1, 1, "trust")
