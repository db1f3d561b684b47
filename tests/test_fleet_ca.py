"""The fleet CA signs only the members it knows (issue 35, finding 3): a request is signed only
when its signature verifies, its key is EC P-256 or RSA >= 2048, and it names a member in the
master's own settings (a host name, compared case-insensitively; never the master, an address,
a stranger or a removed member). `ros pair --sign` shows the name and key fingerprint and asks;
`--serve NAME`, a member's forced command, signs only NAME; `--remove` ends NAME's way in."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from cryptography import x509
from cryptography.hazmat.primitives import hashes
from cryptography.hazmat.primitives import serialization as ser
from cryptography.hazmat.primitives.asymmetric import ec, rsa
from cryptography.x509.oid import NameOID

from rosnet_tui.core.config.settings_model import Peer
from rosnet_tui.core.ros import fleet_tls, pair_access, pairing
from rosnet_tui.core.ros.fleet_tls import TlsError
from rosnet_tui.core.saved.settings import render_settings
from tests.builders import ros2_master

REPO = Path(__file__).resolve().parents[1]


def master():
    s = ros2_master(public_ip="203.0.113.2")
    s.peers.append(Peer(name="Bob", public_ip="198.51.100.3"))
    return s


def csr(name: str | None, key=None) -> str:
    key = key or ec.generate_private_key(ec.SECP256R1())
    subject = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)] if name else [])
    return (x509.CertificateSigningRequestBuilder().subject_name(subject)
            .sign(key, hashes.SHA256()).public_bytes(ser.Encoding.PEM).decode())


def tampered(pem: str, old: bytes, new: bytes) -> str:
    """The request with *old* replaced by *new* in its signed part: its signature breaks."""
    der = x509.load_pem_x509_csr(pem.encode()).public_bytes(ser.Encoding.DER)
    assert der.count(old) == 1
    bad = x509.load_der_x509_csr(der.replace(old, new))
    return bad.public_bytes(ser.Encoding.PEM).decode()


@pytest.fixture
def ca(tmp_path):
    p = fleet_tls.tls_paths(tmp_path / "m")
    pairing.prepare_master(master(), p)
    return p


def sign(paths, pem):
    s = master()
    return fleet_tls.sign_request(paths, pem, master=s.this.name,
                                  members=pairing.member_names(s))


@pytest.mark.parametrize("name, why", [
    ("turtlebot", "names the master"), ("TURTLEBOT", "names the master"),
    ("TurtleBot", "names the master"),
    ("203.0.113.2", "never an address"), ("127.0.0.1", "never an address"),
    ("::1", "never an address"),
    ("relay", "not a member"), ("sami.example", "not a member"),
    ("türtlebot", "not a host name"), ("sami\x00", "not a host name"), ("-sami", "not a host name"),
    ("1234", "only digits"), (None, "empty name"),
])
def test_the_ca_refuses_every_name_that_is_no_member(ca, name, why):
    with pytest.raises(TlsError, match=why):
        sign(ca, csr(name))


def test_the_ca_signs_a_member_in_any_case_and_names_it_as_the_settings_do(ca):
    for name in ("sami", "SAMI", "bob"):
        _, cert = sign(ca, csr(name))
        assert fleet_tls.cert_summary(cert.encode())["sans"] == [name.lower()]
    # a member whose settings spell its name otherwise is paired all the same
    from tests.builders import ros2_member
    me = ros2_member()
    me.this.name = "SAMI"
    sp = fleet_tls.tls_paths(ca.dir.parent.parent / "s")
    ca_pem, mine = sign(ca, fleet_tls.make_request(sp, "SAMI"))
    fleet_tls.install(sp, ca_pem, mine)
    assert pairing.needs_pairing(me, sp) is None
    leaf = fleet_tls.load_cert(cert.encode())
    ku = leaf.extensions.get_extension_for_class(x509.KeyUsage)
    assert ku.critical and ku.value.digital_signature and not ku.value.key_cert_sign
    master_cert = fleet_tls.load_cert(ca.node_crt)
    assert master_cert.extensions.get_extension_for_class(x509.KeyUsage).value.digital_signature


def test_weak_or_foreign_keys_are_refused(ca):
    with pytest.raises(TlsError, match="RSA of 1024 bits"):
        sign(ca, csr("sami", rsa.generate_private_key(65537, 1024)))
    with pytest.raises(TlsError, match="secp384r1"):
        sign(ca, csr("sami", ec.generate_private_key(ec.SECP384R1())))
    _, cert = sign(ca, csr("sami", rsa.generate_private_key(65537, 2048)))
    ku = fleet_tls.load_cert(cert.encode()).extensions.get_extension_for_class(x509.KeyUsage)
    assert ku.value.key_encipherment


def test_a_tampered_request_is_refused(ca):
    """Issue 36's survivors: dropping the signature check or the name check fails here."""
    good = csr("sami")
    with pytest.raises(TlsError, match="signature does not verify"):
        sign(ca, tampered(good, b"sami", b"samj"))
    with pytest.raises(TlsError, match="signature does not verify"):   # now names the master
        sign(ca, tampered(csr("turtlebob"), b"turtlebob", b"turtlebot"))


def test_a_removed_member_is_never_signed_again(ca):
    sign(ca, csr("bob"))
    fleet_tls.set_removed(ca, "BOB")
    with pytest.raises(TlsError, match="taken out of the fleet"):
        sign(ca, csr("bob"))
    fleet_tls.rotate_ca(ca, "turtlebot")        # a new CA keeps the list
    pairing.prepare_master(master(), ca)
    with pytest.raises(TlsError, match="taken out of the fleet"):
        sign(ca, csr("Bob"))
    sign(ca, csr("sami"))


# --------------------------------------------------------------------------- the command line
def _home(tmp_path: Path) -> Path:
    home = tmp_path / "home"
    (home / ".config" / "rosnet-tui").mkdir(parents=True)
    (home / ".config" / "rosnet-tui" / "config.toml").write_text(render_settings(master()))
    return home


def _cli(home: Path, *args: str, stdin: str = "") -> subprocess.CompletedProcess:
    env = {**os.environ, "HOME": str(home), "XDG_CONFIG_HOME": str(home / ".config"),
           "PYTHONPATH": str(REPO)}
    return subprocess.run([sys.executable, "-m", "rosnet_tui", *args], input=stdin, env=env,
                          capture_output=True, text=True, timeout=60, cwd=REPO)


def test_ros_pair_sign_yes_signs_members_and_refuses_the_rest_with_the_reason(tmp_path):
    home = _home(tmp_path)
    key = ec.generate_private_key(ec.SECP256R1())
    good = _cli(home, "ros", "pair", "--sign", "--yes", stdin=csr("sami", key))
    assert good.returncode == 0 and good.stdout.count(fleet_tls.PEM_CERT) == 2, good.stderr
    assert "sami" in good.stderr and fleet_tls.key_fingerprint(key.public_key()) in good.stderr
    asked = _cli(home, "ros", "pair", "--sign", stdin=csr("sami", key))   # no terminal: no
    assert asked.returncode == 2 and "--yes" in asked.stderr and fleet_tls.PEM_CERT not in \
        asked.stdout and fleet_tls.key_fingerprint(key.public_key()) in asked.stderr
    fleet_tls.set_removed(fleet_tls.tls_paths(home / ".config" / "rosnet-tui"), "bob")
    for name, why in (("TurtleBot", "names the master"), ("203.0.113.2", "never an address"),
                      ("relay", "not a member"), ("bob", "taken out of the fleet"),
                      ("tür", "not a host name")):
        r = _cli(home, "ros", "pair", "--sign", "--yes", stdin=csr(name))
        assert r.returncode == 2 and why in r.stderr, (name, r.stderr)
        assert "Traceback" not in r.stderr and fleet_tls.PEM_CERT not in r.stdout


def test_serve_signs_only_its_own_member(tmp_path):
    home = _home(tmp_path)
    r = _cli(home, "ros", "pair", "--serve", "sami", stdin=csr("sami"))
    rep = pairing.report_of(r.stdout)
    assert r.returncode == 0 and rep and "cert" in rep, r.stdout + r.stderr
    for asked, name, why in (("sami", "bob", "signs only for sami"),
                             ("sami", "TURTLEBOT", "names the master"),
                             ("relay", "relay", "not a member")):
        r = _cli(home, "ros", "pair", "--serve", asked, stdin=csr(name))
        rep = pairing.report_of(r.stdout)
        assert r.returncode == 1 and rep and why in rep["error"], r.stdout + r.stderr


PUB = "ssh-ed25519 AAAAC3NzaC1lZDI1NTE5AAAAIHrA3QJtC1qB1v0q5l1b2Yy0lF0nY8pP3yZzq3X2o9/T sami@x"


def test_admit_writes_a_forced_command_and_remove_ends_it(tmp_path):
    home = _home(tmp_path)
    keys = home / ".ssh" / "authorized_keys"
    keys.parent.mkdir()
    keys.write_text("ssh-ed25519 AAAAother me@laptop\n")
    r = _cli(home, "ros", "pair", "--admit", "sami", stdin=PUB)
    assert r.returncode == 0, r.stderr
    lines = keys.read_text().splitlines()
    assert lines[0] == "ssh-ed25519 AAAAother me@laptop"
    assert lines[1].startswith('restrict,command="') and "--serve sami" in lines[1]
    assert lines[1].endswith(" rosnet-tui-pair:sami") and " -I -m rosnet_tui " in lines[1]
    bad = _cli(home, "ros", "pair", "--admit", "relay", stdin=PUB)
    assert bad.returncode == 2 and "not a peer" in bad.stderr
    bad = _cli(home, "ros", "pair", "--admit", "bob", stdin=PUB)      # one key, one member
    assert bad.returncode == 2 and "a key of its own" in bad.stderr
    bad = _cli(home, "ros", "pair", "--admit", "sami", stdin="not a key")
    assert bad.returncode == 2 and "public key" in bad.stderr
    r = _cli(home, "ros", "pair", "--remove", "sami", "--yes", "--timeout", "1")
    assert "Removed 1 pairing key(s) of sami" in r.stdout, r.stdout + r.stderr
    assert "holds other keys too" in r.stdout
    assert keys.read_text() == "ssh-ed25519 AAAAother me@laptop\n"
    again = _cli(home, "ros", "pair", "--serve", "sami", stdin=csr("sami"))
    assert "taken out of the fleet" in pairing.report_of(again.stdout)["error"]


def test_forced_line_refuses_what_authorized_keys_cannot_hold():
    with pytest.raises(pair_access.AccessError):
        pair_access.forced_line("sami", PUB, python='/opt/"x"/python')
    with pytest.raises(pair_access.AccessError):
        pair_access.parse_public_key("ssh-dss AAAA")


def test_an_authorized_keys_that_is_no_regular_file_is_refused_not_waited_on(tmp_path):
    """A FIFO at ~/.ssh/authorized_keys: --admit and --remove say so (no hang, no traceback)."""
    import os

    home = _home(tmp_path)
    keys = home / ".ssh" / "authorized_keys"
    keys.parent.mkdir()
    os.mkfifo(keys)
    r = _cli(home, "ros", "pair", "--admit", "sami", stdin=PUB)
    assert r.returncode == 2 and "cannot read" in r.stderr and "Traceback" not in r.stderr, r
    r = _cli(home, "ros", "pair", "--remove", "sami", "--yes", "--timeout", "1")
    assert r.returncode == 1 and "were not removed" in r.stderr, r.stdout + r.stderr
    assert "Traceback" not in r.stderr
