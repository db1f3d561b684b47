"""The fleet CA's verdicts, run in this process (issue 36: mutation testing sees only code run
here): fleet_tls.py as the program a member runs (``request``, ``install``), the master's
``ros pair --serve`` (pairing.serve), the name and key rules, the removed list, and when a
certificate counts as current."""

from __future__ import annotations

import datetime as dt
import json
import stat
import sys
import threading
import time

import pytest
from cryptography import x509
from cryptography.hazmat.primitives import hashes
from cryptography.hazmat.primitives import serialization as ser
from cryptography.hazmat.primitives.asymmetric import ec, ed25519, rsa
from cryptography.x509.oid import NameOID

from rosnet_tui.core.config.settings_model import Peer
from rosnet_tui.core.ros import fleet_tls, pairing
from rosnet_tui.core.ros.fleet_tls import TlsError
from tests.builders import ros2_master, ros2_member


def master(**ros):
    s = ros2_master(public_ip="203.0.113.2", **ros)
    s.peers.append(Peer(name="Bob", public_ip="198.51.100.3"))
    return s


def csr(*names: str, key=None) -> str:
    key = key or ec.generate_private_key(ec.SECP256R1())
    subject = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, n) for n in names])
    return (x509.CertificateSigningRequestBuilder().subject_name(subject)
            .sign(key, None if isinstance(key, ed25519.Ed25519PrivateKey) else hashes.SHA256())
            .public_bytes(ser.Encoding.PEM).decode())


def read(pem: str, **kw):
    args = {"master": "turtlebot", "members": ["sami", "Bob"], **kw}
    return fleet_tls.read_request(pem, **args)


@pytest.fixture
def ca(tmp_path):
    p = fleet_tls.tls_paths(tmp_path / "m")
    pairing.prepare_master(master(), p)
    return p


# --------------------------------------------------------------------------- the program
def run_main(capsys, *argv):
    rc = fleet_tls.main(list(argv))
    out, err = capsys.readouterr()
    lines = out.splitlines()
    if not lines:
        return rc, None, err
    assert len(lines) == 1 and lines[0].startswith(fleet_tls.REPORT_PREFIX), out
    return rc, json.loads(lines[0][len(fleet_tls.REPORT_PREFIX):]), err


def test_the_program_makes_a_request_and_installs_the_answer(tmp_path, monkeypatch, capsys, ca):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "member"))
    rc, rep, _ = run_main(capsys, "request", "sami")
    assert rc == 0 and set(rep) == {"csr"}
    mine = fleet_tls.tls_paths(tmp_path / "member" / "rosnet-tui")
    assert stat.S_IMODE(mine.node_key.stat().st_mode) == 0o600
    req = x509.load_pem_x509_csr(rep["csr"].encode())
    assert req.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value == "sami"
    san = req.extensions.get_extension_for_class(x509.SubjectAlternativeName)
    assert not san.critical and san.value.get_values_for_type(x509.DNSName) == ["sami"]
    ca_pem, cert = fleet_tls.sign_request(ca, rep["csr"], master="turtlebot", members=["sami"])
    rc, rep, _ = run_main(capsys, "install", ca_pem, cert)
    assert rc == 0 and rep["installed"]["cn"] == "sami"
    assert mine.node_crt.read_text() == cert and mine.ca_crt.read_text() == ca_pem
    for p in (mine.node_crt, mine.ca_crt):
        assert stat.S_IMODE(p.stat().st_mode) == 0o644
    assert not mine.ca_key.exists()
    assert sorted(x.name for x in mine.dir.iterdir()) == ["ca.crt", "node.crt", "node.key"]


def test_the_program_says_when_cryptography_cannot_load(tmp_path, monkeypatch, capsys):
    """A member whose rosnet-tui has a broken cryptography (its import fails): one answer line,
    status 1, not a traceback."""
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "member"))
    monkeypatch.setitem(sys.modules, "cryptography", None)
    rc, rep, _ = run_main(capsys, "request", "sami")
    assert rc == 1 and rep["error"].startswith("rosnet-tui there cannot load cryptography (")


def test_the_program_refuses_with_a_reason_and_a_status(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "member"))
    for argv in ([], ["request"], ["request", "a", "b"], ["install", "x"], ["sign", "x"],
                 ["install", "x", "y", "z"]):
        rc, rep, err = run_main(capsys, *argv)
        assert rc == 2 and rep is None and "usage: request NAME" in err, argv
    junk = fleet_tls.PEM_CERT + "\njunk\n"
    rc, rep, _ = run_main(capsys, "install", junk, junk)
    assert rc == 1 and "not a PEM certificate" in rep["error"]
    (tmp_path / "ca.pem").write_text(junk)
    for ca_arg in (str(tmp_path / "ca.pem"), "", "."):    # text is never read as a file name
        rc, rep, _ = run_main(capsys, "install", ca_arg, junk)
        assert rc == 1 and "not a PEM certificate" in rep["error"], ca_arg
    (tmp_path / "file").write_text("")
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "file"))   # cannot hold a folder
    rc, rep, _ = run_main(capsys, "request", "sami")
    assert rc == 1 and rep["error"]


# --------------------------------------------------------------------------- the master's serve
def test_serve_signs_only_the_member_it_was_asked_for(tmp_path):
    p, s = fleet_tls.tls_paths(tmp_path / "m"), master()
    out = pairing.serve(s, p, "SAMI", csr("sami"))           # makes the CA on first use
    assert set(out) == {"ca", "cert"} and p.ca_key.exists()
    assert fleet_tls.cert_summary(out["cert"].encode())["sans"] == ["sami"]
    fleet_tls.load_cert(out["cert"]).verify_directly_issued_by(fleet_tls.load_cert(out["ca"]))
    assert "signs only for sami" in pairing.serve(s, p, "sami", csr("bob"))["error"]
    assert "names the master" in pairing.serve(s, p, "turtlebot", csr("turtlebot"))["error"]
    assert "not a member" in pairing.serve(s, p, "relay.example", csr("relay.example"))["error"]
    s.relay.host = "Relay.Example"
    assert "cert" in pairing.serve(s, p, "relay.example", csr("RELAY.example"))
    fleet_tls.set_removed(p, "bob")
    assert "taken out" in pairing.serve(s, p, "bob", csr("bob"))["error"]
    assert "not the master" in pairing.serve(ros2_member(), p, "sami", csr("sami"))["error"]
    assert "signature does not verify" in pairing.serve(s, p, "sami", _broken(csr("sami")))["error"]


def _broken(pem: str) -> str:
    der = x509.load_pem_x509_csr(pem.encode()).public_bytes(ser.Encoding.DER)
    bad = x509.load_der_x509_csr(der.replace(b"sami", b"samj"))
    return bad.public_bytes(ser.Encoding.PEM).decode()


# --------------------------------------------------------------------------- read_request
def test_a_request_that_passes_says_who_and_which_key():
    key = ec.generate_private_key(ec.SECP256R1())
    req = read("\n\n  " + csr("SaMi", key=key).strip() + "  \n")      # pasted, trimmed
    assert (req.name, req.role) == ("sami", "member")
    assert req.fingerprint == fleet_tls.key_fingerprint(key.public_key())
    assert len(req.fingerprint) == 95 and req.fingerprint.count(":") == 31
    rel = read(csr("relay.example"), relay="RELAY.example")
    assert (rel.name, rel.role) == ("relay.example", "relay")
    assert read(csr("bob"), relay="relay.example").role == "member"


@pytest.mark.parametrize("pem, kw, why", [
    ("\udcff", {}, "not a certificate request"),
    ("", {}, "not a certificate request"),
    (None, {"master": ""}, "master's own name is not known"),
    (None, {"removed": ["SAMI"]}, "taken out of the fleet"),
    (None, {"members": []}, "not a member"),
    (None, {"relay": "", "members": ["bob"]}, "not a member"),
])
def test_read_request_refusals(pem, kw, why):
    with pytest.raises(TlsError, match=why):
        read(csr("sami") if pem is None else pem, **kw)


def test_a_request_with_two_names_or_a_foreign_key_type_is_refused():
    with pytest.raises(TlsError, match="empty name"):
        read(csr("sami", "bob"))
    with pytest.raises(TlsError, match="Ed25519PublicKey; the fleet uses EC P-256"):
        read(csr("sami", key=ed25519.Ed25519PrivateKey.generate()))
    assert fleet_tls.key_problem(ec.generate_private_key(ec.SECP256R1()).public_key()) is None
    assert fleet_tls.key_problem(rsa.generate_private_key(65537, 2048).public_key()) is None
    assert "secp521r1" in fleet_tls.key_problem(
        ec.generate_private_key(ec.SECP521R1()).public_key())


@pytest.mark.parametrize("name, why", [
    ("a" * 63, None), ("a" * 64, "not a host name"),
    (".".join(["a" * 63] * 3 + ["a" * 61]), None),
    (".".join(["a" * 63] * 3 + ["a" * 62]), "not a host name"),
    ("sami.example", None), ("SAMI", None), ("r2-d2", None), ("a", None),
    ("a..b", "not a host name"), ("a-", "not a host name"), ("a_b", "not a host name"),
    ("a.", "not a host name"), ("[::1]", "address"), ("1.2.3", "only digits"),
    ("12.34.x", None), ("0", "only digits"), ("", "empty name"),
])
def test_host_names(name, why):
    got = fleet_tls.host_name_problem(name)
    assert (got is None) if why is None else (why in got), (name, got)


def test_a_bad_name_is_shown_escaped_and_cut():
    assert "'t\\xfcr'" in fleet_tls.host_name_problem("tür")
    long = fleet_tls.host_name_problem("b" * 300)
    assert "b" * 60 in long and "b" * 61 not in long


# --------------------------------------------------------------------------- removed, pems
def test_the_removed_list(tmp_path):
    p = fleet_tls.tls_paths(tmp_path)
    assert fleet_tls.removed_members(p) == []
    fleet_tls.set_removed(p, "Bob")
    fleet_tls.set_removed(p, "BOB")
    fleet_tls.set_removed(p, "eve")
    assert fleet_tls.removed_members(p) == ["bob", "eve"]
    assert (p.dir / fleet_tls.REMOVED_FILE).read_text() == "bob\neve\n"
    assert stat.S_IMODE((p.dir / fleet_tls.REMOVED_FILE).stat().st_mode) == 0o644
    fleet_tls.set_removed(p, "bOb", removed=False)
    assert fleet_tls.removed_members(p) == ["eve"]
    (p.dir / fleet_tls.REMOVED_FILE).write_text("  Eve \n\n\t\nx\n")
    assert fleet_tls.removed_members(p) == ["eve", "x"]
    (p.dir / fleet_tls.REMOVED_FILE).write_text("".join(f"m{i}\n" for i in range(10001)))
    got = fleet_tls.removed_members(p)
    assert len(got) == 10000 and got[-1] == "m9999"         # read up to a bound
    (p.dir / fleet_tls.REMOVED_FILE).write_bytes(b"\xffbob\n")
    assert fleet_tls.removed_members(p) == ["\ufffdbob"]


def test_split_pems_takes_whole_blocks_in_order(ca):
    a, b = ca.ca_crt.read_text(), ca.node_crt.read_text()
    half = b.splitlines()[:3]
    text = "words\n" + "\n".join(half) + "\n  " + a.replace("\n", "  \n") + "more\n" + b
    assert fleet_tls.split_pems(text) == [a, b]
    assert fleet_tls.split_pems("\n".join(half)) == []


# --------------------------------------------------------------------------- certificates
def test_the_ca_and_a_leaf_say_what_they_are(ca, tmp_path):
    c = fleet_tls.load_cert(ca.ca_crt)
    bc = c.extensions.get_extension_for_class(x509.BasicConstraints)
    assert bc.critical and bc.value.ca and bc.value.path_length == 0
    ku = c.extensions.get_extension_for_class(x509.KeyUsage)
    assert ku.critical and ku.value == x509.KeyUsage(
        digital_signature=True, key_cert_sign=True, crl_sign=True, content_commitment=False,
        key_encipherment=False, data_encipherment=False, key_agreement=False,
        encipher_only=False, decipher_only=False)
    ski = c.extensions.get_extension_for_class(x509.SubjectKeyIdentifier)
    assert not ski.critical
    assert ski.value == x509.SubjectKeyIdentifier.from_public_key(c.public_key())
    days = (c.not_valid_after_utc - c.not_valid_before_utc).days
    assert days == fleet_tls.CA_DAYS
    assert c.subject == c.issuer and "turtlebot" in c.subject.rfc4514_string()
    leaf = fleet_tls.load_cert(ca.node_crt)
    bc = leaf.extensions.get_extension_for_class(x509.BasicConstraints)
    assert bc.critical and not bc.value.ca
    ku = leaf.extensions.get_extension_for_class(x509.KeyUsage)
    assert ku.critical and ku.value == x509.KeyUsage(
        digital_signature=True, key_cert_sign=False, crl_sign=False, content_commitment=False,
        key_encipherment=False, data_encipherment=False, key_agreement=False,
        encipher_only=False, decipher_only=False)
    for ext in (x509.SubjectAlternativeName, x509.ExtendedKeyUsage,
                x509.AuthorityKeyIdentifier):
        assert not leaf.extensions.get_extension_for_class(ext).critical, ext
    aki = leaf.extensions.get_extension_for_class(x509.AuthorityKeyIdentifier).value
    assert aki.key_identifier == ski.value.digest
    san = leaf.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert san.get_values_for_type(x509.DNSName) == ["turtlebot"]
    assert [str(a) for a in san.get_values_for_type(x509.IPAddress)] == ["203.0.113.2"]
    assert list(leaf.extensions.get_extension_for_class(x509.ExtendedKeyUsage).value) == [
        x509.oid.ExtendedKeyUsageOID.SERVER_AUTH, x509.oid.ExtendedKeyUsageOID.CLIENT_AUTH]
    assert (leaf.not_valid_after_utc - leaf.not_valid_before_utc).days == fleet_tls.CERT_DAYS
    now = dt.datetime.now(dt.timezone.utc)
    for cert in (c, leaf):          # back-dated a few minutes (clocks differ a little)
        assert now - dt.timedelta(minutes=15) < cert.not_valid_before_utc \
            < now - dt.timedelta(minutes=4)
    assert leaf.issuer == c.subject
    leaf.verify_directly_issued_by(c)
    s = fleet_tls.cert_summary(ca.node_crt, now=leaf.not_valid_after_utc
                               - dt.timedelta(seconds=0.95 * 86400 + 0.5))
    assert s["days_left"] == 1.0            # 0.950006 days, to one decimal
    s = fleet_tls.cert_summary(ca.node_crt, now=leaf.not_valid_after_utc - dt.timedelta(days=2))
    assert s["days_left"] == 2.0 and s["not_after"] == leaf.not_valid_after_utc.isoformat()
    assert s["fingerprint"] == leaf.fingerprint(hashes.SHA256()).hex()
    assert s["issuer"] == c.subject.rfc4514_string()
    assert fleet_tls.cert_summary(ca.ca_crt)["issuer_key_id"] == fleet_tls.ca_key_id(ca.ca_crt)
    assert len(fleet_tls.ca_key_id(ca.ca_crt)) == 40
    assert fleet_tls.ca_key_id(tmp_path / "none") == ""
    (tmp_path / "junk").write_text("junk")
    assert fleet_tls.ca_key_id(tmp_path / "junk") == ""
    assert fleet_tls.load_cert(ca.ca_crt.read_text()).subject == c.subject
    assert fleet_tls.load_cert(ca.ca_crt.read_bytes()).subject == c.subject


def test_when_the_masters_certificate_counts_as_current(ca):
    name, ip = "turtlebot", "203.0.113.2"
    assert fleet_tls.master_cert_current(ca, name, ip)
    assert fleet_tls.master_cert_current(ca, name)
    assert not fleet_tls.master_cert_current(ca, name, "203.0.113.9")
    assert not fleet_tls.master_cert_current(ca, "robot", ip)
    assert fleet_tls.ensure_master_cert(ca, name, ip) is False
    before = ca.node_crt.read_bytes()
    assert fleet_tls.ensure_master_cert(ca, name, ip, renew=True) is True
    assert ca.node_crt.read_bytes() != before
    assert fleet_tls.ensure_master_cert(ca, name, "203.0.113.9") is True     # a new address
    assert fleet_tls.cert_summary(ca.node_crt)["sans"] == [name, "203.0.113.9"]
    for days, current in ((31, True), (30, False)):
        fleet_tls.issue_test_cert(ca, ca, name, days=days)
        assert fleet_tls.master_cert_current(ca, name) is current, days
    assert pairing.master_plan(master(), ca)                     # expiring: a new one planned
    fleet_tls.ensure_master_cert(ca, name)
    assert pairing.master_plan(ros2_master(), ca) == []
    ca.node_crt.write_text("junk")
    plan = pairing.master_plan(ros2_master(), ca)
    assert len(plan) == 1 and "certificate" in plan[0] and "its key" not in plan[0]
    ca.node_crt.unlink()
    assert not fleet_tls.master_cert_current(ca, name)
    old_ca = fleet_tls.ca_key_id(ca.ca_crt)
    fleet_tls.rotate_ca(ca, "turtlebot")
    assert not ca.node_crt.exists() and fleet_tls.ca_key_id(ca.ca_crt) != old_ca
    assert "fleet CA (turtlebot)" in fleet_tls.load_cert(ca.ca_crt).subject.rfc4514_string()
    other = fleet_tls.tls_paths(ca.dir.parent / "o")
    fleet_tls.issue_test_cert(fleet_tls.make_test_ca(ca.dir.parent / "f"), other, name)
    ca.node_crt.write_bytes(other.node_crt.read_bytes())
    assert not fleet_tls.master_cert_current(ca, name)          # from another CA


def test_the_master_plans_what_it_would_make(tmp_path):
    p = fleet_tls.tls_paths(tmp_path)
    plan = pairing.master_plan(ros2_master(), p)
    assert len(plan) == 2 and "fleet CA" in plan[0] and "its key" in plan[1]
    assert not p.dir.exists()                                  # a preview makes nothing
    pairing.prepare_master(ros2_master(), p)                   # no public IP known yet
    assert pairing.master_plan(ros2_master(), p) == []
    plan = pairing.master_plan(master(), p)                    # now it is: a new certificate
    assert len(plan) == 1 and "this router's certificate" in plan[0]
    p.ca_key.unlink()                                          # a CA without its key: anew
    assert "fleet CA" in pairing.master_plan(ros2_master(), p)[0]
    p.ca_crt.unlink()
    p.node_crt.unlink()
    p.node_key.unlink()
    assert fleet_tls.ensure_ca(p, "x") is True and fleet_tls.ensure_ca(p, "x") is False
    p.ca_crt.unlink()
    assert fleet_tls.ensure_ca(p, "x") is True                  # a key without its CA: anew
    p.ca_key.unlink()
    assert fleet_tls.ensure_ca(p, "x") is True                  # a CA without its key: anew
    assert stat.S_IMODE(p.ca_key.stat().st_mode) == 0o600
    assert stat.S_IMODE(p.ca_crt.stat().st_mode) == 0o644
    assert stat.S_IMODE(p.dir.stat().st_mode) == 0o700


def test_install_refuses_without_the_members_own_key(ca, tmp_path):
    sp = fleet_tls.tls_paths(tmp_path / "s")
    ca_pem, cert = fleet_tls.sign_request(ca, fleet_tls.make_request(sp, "sami"),
                                          master="turtlebot", members=["sami"])
    sp.node_key.unlink()
    with pytest.raises(TlsError, match="is missing"):
        fleet_tls.install(sp, ca_pem, cert)
    assert not sp.node_crt.exists() and not sp.ca_crt.exists()
    empty = fleet_tls.tls_paths(tmp_path / "e")
    with pytest.raises(TlsError, match="no fleet CA here"):
        fleet_tls.sign_request(empty, csr("sami"), master="turtlebot", members=["sami"])


def test_the_program_finds_the_config_folder_as_the_product_does(tmp_path, monkeypatch):
    monkeypatch.delenv("XDG_CONFIG_HOME", raising=False)
    monkeypatch.setenv("HOME", str(tmp_path))
    assert fleet_tls.tls_paths().dir == tmp_path / ".config" / "rosnet-tui" / "tls"
    monkeypatch.setenv("XDG_CONFIG_HOME", "")
    assert fleet_tls.tls_paths().dir == tmp_path / ".config" / "rosnet-tui" / "tls"
    assert fleet_tls.tls_paths(tmp_path / "c").node_key == tmp_path / "c" / "tls" / "node.key"


# --------------------------------------------------------------------------- a member's verdicts
def test_why_a_member_needs_pairing(ca, tmp_path):
    sp, me = fleet_tls.tls_paths(tmp_path / "s"), ros2_member()
    assert pairing.needs_pairing(me, sp) == "no fleet certificate here yet"
    fleet_tls.issue_test_cert(ca, sp, "sami", days=31)              # with the CA's certificate
    assert pairing.needs_pairing(me, sp) is None
    fleet_tls.issue_test_cert(ca, sp, "sami", days=30)
    assert pairing.needs_pairing(me, sp) == "the certificate expires in 30 days"
    fleet_tls.issue_test_cert(ca, sp, "bob")
    assert pairing.needs_pairing(me, sp) == "the certificate names bob, not sami"
    sp.node_crt.write_text("junk")
    assert "cannot be read" in pairing.needs_pairing(me, sp)
    sp.node_key.unlink()
    assert pairing.needs_pairing(me, sp) == "no fleet certificate here yet"


def test_the_answer_line_is_the_last_one_that_parses():
    pre = fleet_tls.REPORT_PREFIX
    assert pairing.report_of(f'{pre}{{"a": 1}}\nnoise\n{pre}{{"b": 2}}\n') == {"b": 2}
    assert pairing.report_of(f"{pre}[1]\n") is None
    assert pairing.report_of(f"{pre}{{nope\n") is None
    assert pairing.report_of("") is None and pairing.report_of(None) is None
    assert pairing.report_of('ROSNET_ZENOH {"error": "no_install"}\n') == {"error": "no_install"}
    assert pairing.report_of('ROSNET_ZENOH {"ok": 1}\n') is None
    assert pairing.report_of(f' {pre}{{"a": 1}}') is None


def test_commands_the_master_and_members_run():
    cmd = pairing.serve_command("sami")
    assert "'ros' 'pair' '--serve' 'sami'" in cmd or "ros pair --serve sami" in cmd
    assert pairing.member_names(master()) == ["sami", "Bob"]
    assert pairing.master_peer(ros2_member()).name == "turtlebot"
    assert "request" in pairing.tls_command("request", "sami")


def test_renewal_turns_only_where_it_should(tmp_path, monkeypatch):
    p = fleet_tls.tls_paths(tmp_path)
    six_h = 6 * 3600.0
    assert pairing.renew_due(ros2_member(security="none"), p) == ([], six_h)
    assert pairing.renew_due(master(security="mtls"), p) == ([], six_h)     # no CA: not made
    assert not p.dir.exists()
    fleet_tls.ensure_ca(p, "turtlebot")
    said, nxt = pairing.renew_due(master(security="mtls"), p)
    assert nxt == six_h and len(said) == 1 and said[0].startswith("TLS: made ")
    assert pairing.renew_due(master(security="mtls"), p) == ([], six_h)
    assert pairing.renew_due(ros2_member(security="mtls"), fleet_tls.tls_paths(tmp_path / "s")) \
        == ([], six_h)                                            # never paired: not here
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "cfg"))
    lines = []

    class Log:
        def info(self, fmt, *a):
            lines.append(fmt % a)

    r = pairing.CertRenewer(Log())
    r.tick(None, background=False)
    assert r.next_at == 0.0
    r.tick(ros2_member(security="none"), background=False)
    assert r.next_at > six_h - 60 and lines == []


def test_a_write_that_fails_leaves_no_temporary_file(ca, tmp_path):
    sp = fleet_tls.tls_paths(tmp_path / "s")
    ca_pem, cert = fleet_tls.sign_request(ca, fleet_tls.make_request(sp, "sami"),
                                          master="turtlebot", members=["sami"], days=10)
    leaf = fleet_tls.load_cert(cert)
    assert (leaf.not_valid_after_utc - leaf.not_valid_before_utc).days == 10
    sp.node_crt.mkdir()                                   # cannot be replaced by a file
    with pytest.raises(OSError):
        fleet_tls.install(sp, ca_pem, cert)
    assert sorted(x.name for x in sp.dir.iterdir()) == ["ca.crt", "node.crt", "node.key"]


def test_the_master_renews_its_certificate_when_asked(ca):
    before = ca.node_crt.read_bytes()
    assert pairing.prepare_master(master(), ca) == []
    made = pairing.prepare_master(master(), ca, renew=True)
    assert len(made) == 1 and "this router's certificate" in made[0]
    assert ca.node_crt.read_bytes() != before


class Lines:
    """A logger that keeps the lines and says when one came."""

    def __init__(self):
        self.lines, self.came, self.threads = [], threading.Event(), []

    def info(self, fmt, *a):
        self.lines.append(fmt % a)
        t = threading.current_thread()
        self.threads.append((t.name, t.daemon))
        self.came.set()


def test_the_renewer_logs_what_it_made_and_waits_its_turn(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path))
    p = fleet_tls.tls_paths(tmp_path / "rosnet-tui")
    fleet_tls.ensure_ca(p, "turtlebot")
    log = Lines()
    r = pairing.CertRenewer(log)
    t0 = time.monotonic()
    r.tick(master(security="mtls"), background=False)
    assert len(log.lines) == 1 and log.lines[0].startswith("TLS: made this router's certificate")
    assert t0 + 6 * 3600 <= r.next_at <= time.monotonic() + 6 * 3600
    p.node_crt.unlink()
    r.tick(master(security="mtls"), background=False)          # not its turn yet
    assert len(log.lines) == 1 and not p.node_crt.exists()
    r.next_at = 0.0
    log.came.clear()
    r.tick(master(security="mtls"), background=True)           # on a thread of its own
    assert log.came.wait(30) and len(log.lines) == 2 and p.node_crt.exists()
    # a daemon thread (it never holds the service's exit), named for ps and the logs
    assert log.threads == [(threading.current_thread().name, False),
                           ("certificate renewal", True)]


def test_the_renewer_logs_a_failure_and_tries_again_in_10_minutes(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path))
    p = fleet_tls.tls_paths(tmp_path / "rosnet-tui")
    fleet_tls.ensure_ca(p, "turtlebot")
    p.ca_crt.write_text("damaged")
    log = Lines()
    r = pairing.CertRenewer(log)
    t0 = time.monotonic()
    r.tick(master(security="mtls"), background=False)
    assert log.lines == ["TLS: renewing the certificate failed: not a PEM certificate "
                         + log.lines[0].split("not a PEM certificate ", 1)[1]]
    assert t0 + 600 <= r.next_at <= time.monotonic() + 600


def test_the_renewer_never_runs_twice_at_once(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path))
    fleet_tls.ensure_ca(fleet_tls.tls_paths(tmp_path / "rosnet-tui"), "turtlebot")
    go = threading.Event()

    class Held(Lines):
        def info(self, fmt, *a):
            super().info(fmt, *a)
            go.wait(30)                    # the renewal is still at work until released

    log = Held()
    r = pairing.CertRenewer(log)
    r.tick(master(security="mtls"), background=True)
    assert log.came.wait(30)
    r.tick(master(security="mtls"), background=True)   # at work: nothing more, no error
    r.tick(master(security="mtls"), background=False)
    go.set()
    deadline = time.monotonic() + 30
    while r.next_at == float("inf") and time.monotonic() < deadline:
        time.sleep(0.01)
    assert len(log.lines) == 1 and r.next_at < float("inf")


def test_keys_are_the_owners_alone_and_certificates_readable_and_nothing_is_made_twice(tmp_path):
    """Files fleet_tls writes have exact modes (a private key 0600, a certificate 0644: no other
    bit, execute included), and it says what it made: a second call makes nothing."""
    def mode(p):
        return stat.S_IMODE(p.stat().st_mode)

    ca = fleet_tls.make_test_ca(tmp_path / "ca")
    assert (mode(ca.ca_key), mode(ca.ca_crt)) == (0o600, 0o644)
    into = fleet_tls.tls_paths(tmp_path / "node")
    fleet_tls.issue_test_cert(ca, into, "sami")
    assert (mode(into.node_key), mode(into.node_crt), mode(into.ca_crt)) == (0o600, 0o644, 0o644)
    m = fleet_tls.tls_paths(tmp_path / "master")
    assert fleet_tls.ensure_node_key(m) is True and fleet_tls.ensure_node_key(m) is False
    fleet_tls.make_test_ca(tmp_path / "master")             # the master's CA in its own folder
    assert fleet_tls.ensure_master_cert(m, "turtlebot", "203.0.113.5") is True
    assert mode(m.node_crt) == 0o644 and mode(m.node_key) == 0o600
    assert fleet_tls.ensure_master_cert(m, "turtlebot", "203.0.113.5") is False   # still current
    assert fleet_tls.ensure_master_cert(m, "turtlebot") is False     # its name is still on it
    assert fleet_tls.ensure_master_cert(m, "robot") is True          # another name: made anew
