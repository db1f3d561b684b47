"""This machine's sshd host keys as sshd finds them (core/ssh/sshd_keys.py): the HostKey lines of
sshd_config and of the files it Includes (relative to the config folder, globbed, in order),
``sshd -T``'s answer agreeing with them, and sshd's default keys when the config names none.
relay.tunnel against a real sshd that keeps its keys elsewhere: tests/test_ssh_jump.py."""

from __future__ import annotations

import base64
import os

import pytest

from rosnet_tui.core.ssh.sshd_keys import own_host_keys
from tests.plugins.ssh import SSHD, keygen


def blob(pub: str) -> bytes:
    return base64.b64decode(pub.split()[1])


@pytest.fixture
def etc_ssh(tmp_path):
    """A config folder whose sshd_config keeps its keys in /srv-like places, one by Include."""
    d = tmp_path / "etc_ssh"
    (d / "sshd_config.d").mkdir(parents=True)
    keys = tmp_path / "keys"
    keys.mkdir()
    pubs = {n: keygen(keys / n) for n in ("main", "inc a", "inc_b")}
    (d / "sshd_config").write_text(
        "# HostKey /nowhere/commented\n"
        f"HostKey {keys / 'main'}\n"
        f"Include {d}/sshd_config.d/*.conf\n"
        "PasswordAuthentication no\n")
    (d / "sshd_config.d" / "20-b.conf").write_text(f"hostkey={keys / 'inc_b'}\n")
    (d / "sshd_config.d" / "10-a.conf").write_text(f'HostKey "{keys / "inc a"}"  # spaces\n')
    (d / "sshd_config.d" / "ignored.txt").write_text("HostKey /nowhere/else\n")
    return d, keys, pubs


def test_hostkey_lines_and_includes_name_the_keys(etc_ssh):
    d, keys, pubs = etc_ssh
    got = own_host_keys(d, ask_sshd=False)
    assert list(got.keys) == [blob(pubs[n]) for n in ("main", "inc a", "inc_b")]
    assert list(got.keys.values()) == [keys / f"{n}.pub" for n in ("main", "inc a", "inc_b")]
    assert "HostKey lines" in got.source and not got.unread
    assert f"{keys / 'inc_b'}.pub (SHA256:" in got.words()
    # A relative Include is read from the config folder (sshd's /etc/ssh), as sshd does.
    cfg = d / "sshd_config"
    cfg.write_text(cfg.read_text().replace(f"Include {d}/", "Include "))
    assert own_host_keys(d, ask_sshd=False).keys == got.keys


@pytest.mark.skipif(not os.path.exists(SSHD) or os.geteuid() != 0,
                    reason="sshd -T loads the private keys: root only")
def test_sshd_t_agrees_with_the_config_lines(etc_ssh):
    d, _keys, _pubs = etc_ssh     # (its Include is absolute: sshd reads relative ones in /etc/ssh)
    asked = own_host_keys(d, ask_sshd=True)
    assert "sshd -T" in asked.source, asked.source
    assert asked.keys == own_host_keys(d, ask_sshd=False).keys


def test_a_named_key_without_its_public_half_is_said(etc_ssh):
    d, keys, pubs = etc_ssh
    (keys / "inc_b.pub").unlink()
    got = own_host_keys(d, ask_sshd=False)
    assert set(got.keys) == {blob(pubs["main"]), blob(pubs["inc a"])}
    assert got.unread == [keys / "inc_b.pub"] and "not readable" in got.words()


def test_no_hostkey_line_means_sshd_s_defaults(tmp_path):
    d = tmp_path / "etc_ssh"
    d.mkdir()
    pub = keygen(d / "ssh_host_ed25519_key")
    (d / "sshd_config").write_text("Port 22\n")
    got = own_host_keys(d, ask_sshd=False)
    assert set(got.keys) == {blob(pub)} and "default keys" in got.source
    assert not got.unread                         # no rsa/ecdsa key here: no news
    (d / "sshd_config").unlink()                  # no config at all: the same defaults
    assert set(own_host_keys(d, ask_sshd=False).keys) == {blob(pub)}
