"""The fleet's TLS material for ROS 2's mutual TLS: a CA on the master, a key and certificate on
every component (``~/.config/rosnet-tui/tls/``).

- ``ca.key`` (master only, 0600) never leaves the master; ``ca.crt`` is on every component.
- ``node.key`` (0600) is made on its component and never leaves it; ``node.crt`` is that key's
  certificate, signed by the fleet CA, naming the component (CN and DNS subjectAltName; the
  master's also its public IP when known, since a locator may dial it by address).
- Every certificate has a Common Name (zenoh 1.7.2 panicked on one without), a critical key usage
  (digitalSignature; keyEncipherment too for RSA) and the extended key usages serverAuth and
  clientAuth (a router that connects with mTLS needs clientAuth).
- The CA signs only a request whose signature verifies, whose key is EC P-256 (or RSA of 2048
  bits up), and which names a member in the master's own settings, or the relay its ``[relay]
  host`` names: a host name, compared case-insensitively, never an address, the master's name or
  a removed member's (:func:`read_request`).

This module needs only the standard library and ``cryptography``, and runs as a program: the
master re-pairing its members feeds it on stdin to each member's installed rosnet-tui
(``python - request NAME``, ``python - install CA_PEM CERT_PEM``; one ``ROSNET_TLS {json}`` line
out). Signing never runs on code a member sent: a member has its request signed by the master's
own ``rosnet-tui ros pair --serve NAME`` (core/ros/pairing.py), with the master's settings.
"""

from __future__ import annotations

import datetime as _dt
import ipaddress
import json
import os
import re
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


def preload() -> None:
    """Import the parts of cryptography the certificates here use (for a process that is to
    read and make certificates later without waiting for the import: about 50 ms)."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes
    from cryptography.hazmat.primitives import serialization as ser
    from cryptography.hazmat.primitives.asymmetric import ec, rsa
    from cryptography.x509.oid import NameOID

    del x509, hashes, ser, ec, rsa, NameOID


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
    """A certificate from a file (a Path) or from PEM (text or bytes). Text is never taken for a
    path: an answer that is no certificate is refused, not read as a file name."""
    from cryptography import x509

    data = (path_or_pem if isinstance(path_or_pem, bytes) else
            path_or_pem.encode("utf-8", "replace") if isinstance(path_or_pem, str)
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


def _leaf_key_usage(public_key: Any) -> Any:
    """A TLS endpoint's key usage: signing the handshake (EC and RSA), and for RSA also key
    encipherment (TLS 1.2's RSA key exchange)."""
    from cryptography import x509
    from cryptography.hazmat.primitives.asymmetric import rsa

    return x509.KeyUsage(digital_signature=True, content_commitment=False,
                         key_encipherment=isinstance(public_key, rsa.RSAPublicKey),
                         data_encipherment=False, key_agreement=False, key_cert_sign=False,
                         crl_sign=False, encipher_only=False, decipher_only=False)


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
            .add_extension(_leaf_key_usage(public_key), critical=True)
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


HOST_LABEL = re.compile(r"^(?!-)[a-z0-9-]{1,63}(?<!-)$")
REMOVED_FILE = "removed"        # in the TLS folder on the master: members taken out, a name a line


def host_name_problem(name: str) -> str | None:
    """Why *name* cannot be a component's name in a certificate (None: it can): a host name of
    ASCII letters, digits and '-' (dot-separated labels), never an address or only digits."""
    shown = name.encode("ascii", "backslashreplace").decode()[:60]
    if not name:
        return "the request names no component (an empty name)"
    try:
        ipaddress.ip_address(name.strip("[]"))
        return f"the request names the address {shown}; a certificate names a host, never an address"
    except ValueError:
        pass
    low = name.lower()
    if len(name) > 253 or not all(HOST_LABEL.match(x) for x in low.split(".")):
        return f"the request names '{shown}', not a host name (letters, digits and '-')"
    if low.replace(".", "").isdigit():
        return f"the request names '{shown}', only digits: not a host name"
    return None


def removed_members(paths: TlsPaths) -> list[str]:
    """The members `ros pair --remove` took out of the fleet (lower case)."""
    try:
        text = (paths.dir / REMOVED_FILE).read_text(encoding="utf-8", errors="replace")
    except FileNotFoundError:
        return []
    return [x.strip().lower() for x in text.splitlines()[:10000] if x.strip()]


def set_removed(paths: TlsPaths, name: str, removed: bool = True) -> None:
    """Say (or unsay) that *name* was taken out of the fleet; the CA never signs for it again."""
    names = [n for n in removed_members(paths) if n != name.lower()]
    if removed:
        names.append(name.lower())
    _write(paths.dir / REMOVED_FILE, "".join(n + "\n" for n in names).encode(), 0o644)


def key_fingerprint(public_key: Any) -> str:
    """SHA-256 of a public key (its DER SubjectPublicKeyInfo), hex pairs: what `ros pair
    --sign` shows, to compare with what the member's `--print-request` said."""
    from cryptography.hazmat.primitives import hashes
    from cryptography.hazmat.primitives import serialization as ser

    h = hashes.Hash(hashes.SHA256())
    h.update(public_key.public_bytes(ser.Encoding.DER, ser.PublicFormat.SubjectPublicKeyInfo))
    return ":".join(f"{b:02x}" for b in h.finalize())


def load_request_key(csr_pem: str) -> Any:
    """The public key of a request (PEM) this component made."""
    from cryptography import x509

    return x509.load_pem_x509_csr(csr_pem.encode()).public_key()


def key_problem(public_key: Any) -> str | None:
    """Why a member's key is too weak for the fleet (None: EC P-256, or RSA of 2048 bits up)."""
    from cryptography.hazmat.primitives.asymmetric import ec, rsa

    if isinstance(public_key, ec.EllipticCurvePublicKey):
        if isinstance(public_key.curve, ec.SECP256R1):
            return None
        return f"the request's key is on the curve {public_key.curve.name}; the fleet uses P-256"
    if isinstance(public_key, rsa.RSAPublicKey):
        if public_key.key_size >= 2048:
            return None
        return f"the request's key is RSA of {public_key.key_size} bits; at least 2048 are needed"
    return f"the request's key is a {type(public_key).__name__}; the fleet uses EC P-256 (or RSA)"


@dataclass(frozen=True)
class Request:
    """A member's certificate request that passed every check, and what to show before signing."""

    csr: Any
    name: str
    fingerprint: str
    role: str = "member"       # "member", or "relay" (the master's [relay] host)


def read_request(csr_pem: str, *, master: str, members: Any, removed: Any = (),
                 relay: str = "") -> Request:
    """A member's request, checked: it parses, its signature verifies, its key is strong enough,
    and it names a member of the fleet: a host name in *members* (the master's own settings,
    compared case-insensitively), or *relay* (the master's [relay] host: role "relay"), never
    *master*, never one of *removed*. Raises TlsError with the reason (never anything else,
    whatever the request holds)."""
    from cryptography import x509
    from cryptography.x509.oid import NameOID

    try:
        csr = x509.load_pem_x509_csr(csr_pem.strip().encode() + b"\n")
    except (ValueError, UnicodeError):
        raise TlsError("that is not a certificate request (a PEM block starting with "
                       f"{PEM_CSR})") from None
    try:
        valid = csr.is_signature_valid
        public_key = csr.public_key()
    except Exception:  # noqa: BLE001 - an unsupported algorithm is a refusal, not a crash
        valid, public_key = False, None
    if not valid:
        raise TlsError("the request's signature does not verify (changed after it was made?)")
    why = key_problem(public_key)
    if why:
        raise TlsError(why)
    try:
        cns = csr.subject.get_attributes_for_oid(NameOID.COMMON_NAME)
        cn = str(cns[0].value) if len(cns) == 1 else ""
    except Exception:  # noqa: BLE001 - a subject cryptography cannot read is no name
        cn = ""
    why = host_name_problem(cn)
    if why:
        raise TlsError(why)
    low = cn.lower()
    if not master:
        raise TlsError("the master's own name is not known here (its settings name none)")
    if low == master.lower():
        raise TlsError(f"the request names the master ({cn}); a member cannot take its name")
    if low in {r.lower() for r in removed}:
        raise TlsError(f"{cn} was taken out of the fleet (`ros pair --remove`); it is not signed "
                       "again")
    if relay and low == relay.lower():
        return Request(csr, low, key_fingerprint(public_key), "relay")
    if low not in {m.lower() for m in members}:
        raise TlsError(f"{cn} is not a member in this master's settings (no [[peer]] of that "
                       "name, and not its [relay] host): add it there first")
    return Request(csr, low, key_fingerprint(public_key))


def sign_request(paths: TlsPaths, csr_pem: str, *, master: str, members: Any,
                 removed: Any = (), days: int = CERT_DAYS, relay: str = "") -> tuple[str, str]:
    """On the master: sign a member's request checked by :func:`read_request` (the members
    removed before, from the TLS folder, are refused too). Returns (CA certificate PEM,
    certificate PEM)."""
    if not paths.ca_key.exists():
        raise TlsError(f"no fleet CA here ({paths.ca_key} is missing): run `rosnet-tui ros "
                       "apply` on the master first")
    req = read_request(csr_pem, master=master, members=members,
                       removed=[*removed, *removed_members(paths)], relay=relay)
    return sign_checked(paths, req, days=days)


def sign_checked(paths: TlsPaths, req: Request, *, days: int = CERT_DAYS) -> tuple[str, str]:
    """Sign a request :func:`read_request` passed (after asking, on the command line)."""
    ca = load_cert(paths.ca_crt)
    cert = issue(ca, _load_key(paths.ca_key), req.csr.public_key(), req.name, [req.name],
                 days=days)
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
    """Run over SSH on a member the master re-pairs, one ``ROSNET_TLS`` line out: ``request
    NAME`` and ``install CA_PEM CERT_PEM``. (Signing is never done by this program: a member
    has it done by the master's own `rosnet-tui ros pair --serve`, with the master's settings.)"""
    cmd, rest = (argv[0], argv[1:]) if argv else ("", [])
    arity = {"request": 1, "install": 2}
    if arity.get(cmd) != len(rest):
        print("usage: request NAME | install CA_PEM CERT_PEM", file=sys.stderr)
        return 2
    out: dict[str, Any]
    try:
        if cmd == "request":
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
