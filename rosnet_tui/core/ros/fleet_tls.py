"""The fleet's TLS material for ROS 2's mutual TLS: a CA on the master, a key and certificate on
every component (``~/.config/rosnet-tui/tls/``).

- ``ca.key`` (master only, 0600) never leaves the master; ``ca.crt`` is on every component.
- ``node.key`` (0600) is made on its component and never leaves it; ``node.crt`` is that key's
  certificate, signed by the fleet CA, naming the component (CN and DNS subjectAltName; the
  master's also its public IP when known, since a locator may dial it by address).
- Every certificate has a Common Name (zenoh 1.7.2 panicked on one without) and the extended key
  usages serverAuth and clientAuth (a router that connects with mTLS needs clientAuth).

This module needs only the standard library and ``cryptography``, and runs as a program: the
master's signing step is this file fed on stdin to the interpreter of the rosnet-tui installed on
the master (the same discovery the Zenoh peer program uses), so a member pairs with any master
that has rosnet-tui installed, whatever its version: ``python - sign <member name> <CSR PEM>``
prints one ``ROSNET_TLS {json}`` line.
"""

from __future__ import annotations

import datetime as _dt
import ipaddress
import json
import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

CA_DAYS = 3650              # the fleet CA
CERT_DAYS = 397             # a component's certificate (renewed before expiry)
WARN_DAYS = 30              # checks warn this long before a certificate expires
REPORT_PREFIX = "ROSNET_TLS "
PEM_CERT = "-----BEGIN CERTIFICATE-----"
PEM_CSR = "-----BEGIN CERTIFICATE REQUEST-----"


class TlsError(Exception):
    """A refusal with a reason a user can act on (bad request, wrong CA, missing file...)."""


@dataclass(frozen=True)
class TlsPaths:
    dir: Path
    ca_crt: Path
    ca_key: Path
    node_key: Path
    node_crt: Path


def tls_paths(config_dir: Path | str | None = None) -> TlsPaths:
    """Where this component's TLS files live (under *config_dir*/tls). The product passes
    :func:`rosnet_tui.core.config.paths.default_config_dir`; the default serves this file and
    the outsider probe as programs on a peer, where the installed rosnet-tui may be of another
    version: the same rule, restated here so that the program imports nothing of rosnet-tui
    (tests/test_fleet_tls.py holds the two equal)."""
    base = os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    d = Path(config_dir if config_dir is not None else Path(base) / "rosnet-tui") / "tls"
    return TlsPaths(d, d / "ca.crt", d / "ca.key", d / "node.key", d / "node.crt")


# --------------------------------------------------------------------------- files
def _write(path: Path, data: bytes, mode: int) -> None:
    """Atomic write (temp file in the same folder, fsync, rename) with *mode* from creation."""
    path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}-{os.urandom(4).hex()}")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, mode)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, mode)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise


def _new_key() -> Any:
    from cryptography.hazmat.primitives.asymmetric import ec

    return ec.generate_private_key(ec.SECP256R1())


def _key_pem(key: Any) -> bytes:
    from cryptography.hazmat.primitives import serialization as ser

    return key.private_bytes(ser.Encoding.PEM, ser.PrivateFormat.PKCS8, ser.NoEncryption())


def _load_key(path: Path) -> Any:
    from cryptography.hazmat.primitives import serialization as ser

    return ser.load_pem_private_key(Path(path).read_bytes(), password=None)


def load_cert(path_or_pem: Path | str | bytes) -> Any:
    from cryptography import x509

    data = (path_or_pem if isinstance(path_or_pem, bytes) else
            path_or_pem.encode() if isinstance(path_or_pem, str) and PEM_CERT in path_or_pem
            else Path(path_or_pem).read_bytes())
    try:
        return x509.load_pem_x509_certificate(data)
    except ValueError as exc:
        raise TlsError(f"not a PEM certificate ({exc})") from None


def _cert_pem(cert: Any) -> bytes:
    from cryptography.hazmat.primitives import serialization as ser

    return cert.public_bytes(ser.Encoding.PEM)


def _now() -> _dt.datetime:
    return _dt.datetime.now(_dt.timezone.utc)


def _name(cn: str) -> Any:
    from cryptography import x509
    from cryptography.x509.oid import NameOID

    return x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, cn)])


def _sans(names: list[str]) -> Any:
    from cryptography import x509

    out: list[Any] = []
    for n in names:
        try:
            out.append(x509.IPAddress(ipaddress.ip_address(n)))
        except ValueError:
            out.append(x509.DNSName(n))
    return x509.SubjectAlternativeName(out)


# --------------------------------------------------------------------------- the CA
def _build_ca(cn: str, key: Any, *, days: int = CA_DAYS, not_before: _dt.datetime | None = None) -> Any:
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes

    start = not_before or _now() - _dt.timedelta(minutes=5)
    pub = key.public_key()
    return (x509.CertificateBuilder().subject_name(_name(cn)).issuer_name(_name(cn))
            .public_key(pub).serial_number(x509.random_serial_number())
            .not_valid_before(start).not_valid_after(start + _dt.timedelta(days=days))
            .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
            .add_extension(x509.KeyUsage(digital_signature=True, key_cert_sign=True, crl_sign=True,
                                         content_commitment=False, key_encipherment=False,
                                         data_encipherment=False, key_agreement=False,
                                         encipher_only=False, decipher_only=False), critical=True)
            .add_extension(x509.SubjectKeyIdentifier.from_public_key(pub), critical=False)
            .sign(key, hashes.SHA256()))


def ensure_ca(paths: TlsPaths, fleet: str) -> bool:
    """Create the fleet CA on the master when it has none (True: created now)."""
    if paths.ca_key.exists() and paths.ca_crt.exists():
        return False
    key = _new_key()
    _write(paths.ca_key, _key_pem(key), 0o600)
    _write(paths.ca_crt, _cert_pem(_build_ca(f"rosnet-tui fleet CA ({fleet})", key)), 0o644)
    return True


def rotate_ca(paths: TlsPaths, fleet: str) -> None:
    """A new fleet CA (removing a member: every certificate of the old one stops being trusted)."""
    for p in (paths.ca_key, paths.ca_crt, paths.node_crt):
        p.unlink(missing_ok=True)
    ensure_ca(paths, fleet)


def issue(ca_crt: Any, ca_key: Any, public_key: Any, cn: str, names: list[str], *,
          days: int = CERT_DAYS, not_before: _dt.datetime | None = None) -> Any:
    """A certificate for *public_key* naming *cn* (and *names* as subjectAltName)."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes
    from cryptography.x509.oid import ExtendedKeyUsageOID as Eku

    start = not_before or _now() - _dt.timedelta(minutes=5)
    ski = ca_crt.extensions.get_extension_for_class(x509.SubjectKeyIdentifier).value
    return (x509.CertificateBuilder().subject_name(_name(cn)).issuer_name(ca_crt.subject)
            .public_key(public_key).serial_number(x509.random_serial_number())
            .not_valid_before(start).not_valid_after(start + _dt.timedelta(days=days))
            .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
            .add_extension(_sans(list(dict.fromkeys([cn, *names]))), critical=False)
            .add_extension(x509.ExtendedKeyUsage([Eku.SERVER_AUTH, Eku.CLIENT_AUTH]), critical=False)
            .add_extension(x509.AuthorityKeyIdentifier.from_issuer_subject_key_identifier(ski),
                           critical=False)
            .sign(ca_key, hashes.SHA256()))


def master_cert_current(paths: TlsPaths, name: str, public_ip: str = "") -> bool:
    """The master's certificate is there, from the CA installed here, names it as members dial
    it (its name; its public IP when known) and is good for a while."""
    if not (paths.node_crt.exists() and paths.ca_crt.exists()):
        return False
    s = cert_summary(paths.node_crt)
    want = [name] + ([public_ip] if public_ip else [])
    return (s["issuer_key_id"] == ca_key_id(paths.ca_crt) and set(want) <= set(s["sans"])
            and s["days_left"] > WARN_DAYS)


def ensure_master_cert(paths: TlsPaths, name: str, public_ip: str = "", *,
                       renew: bool = False) -> bool:
    """The master's own key and certificate, naming it as members dial it (True: made now)."""
    ensure_node_key(paths)
    want = [name] + ([public_ip] if public_ip else [])
    if not renew and master_cert_current(paths, name, public_ip):
        return False
    ca = load_cert(paths.ca_crt)
    cert = issue(ca, _load_key(paths.ca_key), _load_key(paths.node_key).public_key(), name, want)
    _write(paths.node_crt, _cert_pem(cert), 0o644)
    return True


# --------------------------------------------------------------------------- a member
def ensure_node_key(paths: TlsPaths) -> bool:
    """This component's own private key, made here (True: made now)."""
    if paths.node_key.exists():
        return False
    _write(paths.node_key, _key_pem(_new_key()), 0o600)
    return True


def make_request(paths: TlsPaths, name: str) -> str:
    """A certificate signing request (PEM) for this component's key, naming *name*."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes
    from cryptography.hazmat.primitives import serialization as ser

    ensure_node_key(paths)
    csr = (x509.CertificateSigningRequestBuilder().subject_name(_name(name))
           .add_extension(_sans([name]), critical=False)
           .sign(_load_key(paths.node_key), hashes.SHA256()))
    return csr.public_bytes(ser.Encoding.PEM).decode()


def sign_request(paths: TlsPaths, csr_pem: str, *, master: str = "",
                 days: int = CERT_DAYS) -> tuple[str, str]:
    """On the master: sign a member's request. Returns (CA certificate PEM, certificate PEM).
    Refuses a malformed request, a bad signature, and a request naming the master itself."""
    from cryptography import x509
    from cryptography.x509.oid import NameOID

    if not paths.ca_key.exists():
        raise TlsError(f"no fleet CA here ({paths.ca_key} is missing): run `rosnet-tui ros "
                       "apply` on the master first")
    try:
        csr = x509.load_pem_x509_csr(csr_pem.strip().encode() + b"\n")
    except ValueError:
        raise TlsError("that is not a certificate request (a PEM block starting with "
                       f"{PEM_CSR})") from None
    if not csr.is_signature_valid:
        raise TlsError("the request's signature does not verify")
    cns = csr.subject.get_attributes_for_oid(NameOID.COMMON_NAME)
    cn = str(cns[0].value) if cns else ""
    if not cn or len(cn) > 63 or not all(c.isalnum() or c in "-." for c in cn):
        raise TlsError(f"the request names '{cn}', not a component name")
    if master and cn == master:
        raise TlsError(f"the request names the master ({cn}); a member cannot take its name")
    ca = load_cert(paths.ca_crt)
    cert = issue(ca, _load_key(paths.ca_key), csr.public_key(), cn, [cn], days=days)
    return _cert_pem(ca).decode(), _cert_pem(cert).decode()


def split_pems(text: str) -> list[str]:
    """The PEM certificate blocks in pasted text, in order."""
    out, cur = [], None
    for line in text.splitlines():
        line = line.strip()
        if line == PEM_CERT:
            cur = [line]
        elif cur is not None:
            cur.append(line)
            if line == "-----END CERTIFICATE-----":
                out.append("\n".join(cur) + "\n")
                cur = None
    return out


def install(paths: TlsPaths, ca_pem: str, cert_pem: str) -> dict[str, Any]:
    """Install the CA certificate and this component's certificate after checking that the
    certificate is for this component's key and signed by that CA."""
    from cryptography.hazmat.primitives import serialization as ser

    ca, cert = load_cert(ca_pem), load_cert(cert_pem)
    if not paths.node_key.exists():
        raise TlsError(f"{paths.node_key} is missing: make the request on this component")
    spki = ser.PublicFormat.SubjectPublicKeyInfo
    if (cert.public_key().public_bytes(ser.Encoding.PEM, spki)
            != _load_key(paths.node_key).public_key().public_bytes(ser.Encoding.PEM, spki)):
        raise TlsError("that certificate is not for this component's key (was the request "
                       "made here, and not replaced since?)")
    try:
        cert.verify_directly_issued_by(ca)
    except Exception:
        raise TlsError("that certificate was not signed by the CA certificate given") from None
    _write(paths.ca_crt, _cert_pem(ca), 0o644)
    _write(paths.node_crt, _cert_pem(cert), 0o644)
    return cert_summary(paths.node_crt)


# --------------------------------------------------------------------------- reading
def ca_key_id(path: Path) -> str:
    """The subject key identifier of a CA certificate (hex; '' when none)."""
    from cryptography import x509

    try:
        return load_cert(path).extensions.get_extension_for_class(
            x509.SubjectKeyIdentifier).value.digest.hex()
    except (x509.ExtensionNotFound, OSError, TlsError):
        return ""


def cert_summary(path: Path | str | bytes, now: _dt.datetime | None = None) -> dict[str, Any]:
    """What a certificate says: cn, sans, issuer, issuer_key_id (which CA signed it), not_after
    (ISO 8601, UTC), days_left, fingerprint (SHA-256 of the certificate)."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes
    from cryptography.x509.oid import NameOID

    cert = load_cert(path)
    cns = cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)
    try:
        sans = [str(v.value) for v in cert.extensions.get_extension_for_class(
            x509.SubjectAlternativeName).value]
    except x509.ExtensionNotFound:
        sans = []
    try:
        aki = cert.extensions.get_extension_for_class(
            x509.AuthorityKeyIdentifier).value.key_identifier or b""
    except x509.ExtensionNotFound:
        aki = b""
    if not aki:   # a CA certificate names itself
        try:
            aki = cert.extensions.get_extension_for_class(x509.SubjectKeyIdentifier).value.digest
        except x509.ExtensionNotFound:
            aki = b""
    end = cert.not_valid_after_utc
    left = (end - (now or _now())).total_seconds() / 86400
    return {"cn": str(cns[0].value) if cns else "", "sans": sans,
            "issuer": cert.issuer.rfc4514_string(), "issuer_key_id": aki.hex(),
            "not_after": end.isoformat(), "days_left": round(left, 1),
            "fingerprint": cert.fingerprint(hashes.SHA256()).hex()}


def make_test_ca(directory: Path, cn: str = "test CA", *, days: int = CA_DAYS,
                 not_before: _dt.datetime | None = None) -> TlsPaths:
    """A CA under *directory*/tls (ca.key, ca.crt), for tests (a foreign CA, an expired one)."""
    paths = tls_paths(directory)
    key = _new_key()
    _write(paths.ca_key, _key_pem(key), 0o600)
    _write(paths.ca_crt, _cert_pem(_build_ca(cn, key, days=days, not_before=not_before)), 0o644)
    return paths


def issue_test_cert(ca: TlsPaths, into: TlsPaths, name: str, *, days: int = CERT_DAYS,
                    not_before: _dt.datetime | None = None) -> None:
    """For tests: a key and a certificate naming *name* under *into*, signed by *ca*."""
    ensure_node_key(into)
    cert = issue(load_cert(ca.ca_crt), _load_key(ca.ca_key),
                 _load_key(into.node_key).public_key(), name, [name], days=days,
                 not_before=not_before)
    _write(into.node_crt, _cert_pem(cert), 0o644)
    if into.ca_crt != ca.ca_crt:
        _write(into.ca_crt, ca.ca_crt.read_bytes(), 0o644)


# --------------------------------------------------------------------------- as a program
def main(argv: list[str]) -> int:
    """Run over SSH, one ``ROSNET_TLS`` line out: ``sign MASTER CSR_PEM`` (on the master);
    ``request NAME`` and ``install CA_PEM CERT_PEM`` (on a member the master re-pairs)."""
    cmd, rest = (argv[0], argv[1:]) if argv else ("", [])
    arity = {"sign": 2, "request": 1, "install": 2}
    if arity.get(cmd) != len(rest):
        print("usage: sign MASTER CSR_PEM | request NAME | install CA_PEM CERT_PEM",
              file=sys.stderr)
        return 2
    out: dict[str, Any]
    try:
        if cmd == "sign":
            ca_pem, cert_pem = sign_request(tls_paths(), rest[1], master=rest[0])
            out = {"ca": ca_pem, "cert": cert_pem}
        elif cmd == "request":
            out = {"csr": make_request(tls_paths(), rest[0])}
        else:
            out = {"installed": install(tls_paths(), rest[0], rest[1])}
    except (TlsError, OSError) as exc:
        out = {"error": str(exc)}
    except ImportError as exc:
        out = {"error": f"rosnet-tui there cannot load cryptography ({exc})"}
    print(REPORT_PREFIX + json.dumps(out), flush=True)
    return 1 if "error" in out else 0


if __name__ == "__main__":   # fed on stdin to the master's interpreter
    sys.exit(main(sys.argv[1:]))
