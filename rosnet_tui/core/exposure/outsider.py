"""What an outsider sees: the programs and verdicts behind ``security.ssh_auth`` and
``security.outsider`` (no Textual, no check registry; the checks live in core/checks/security.py).

- The SSH audit program runs on a peer with the interpreter of the rosnet-tui installed there:
  for each user at once, it opens an SSH connection to this component's public address, asks
  for the ``none`` method and reports the methods the server offers, the same answer any
  stranger on the internet gets. It asks with cryptography's primitives (core/peer/sshnone.py:
  curve25519 and chacha20-poly1305, OpenSSH's defaults), so it costs its round trips, not
  paramiko's import; paramiko (``auth_none``) only for a server that offers neither, or a reply
  that client misreads. It never logs in and sends no secret: it does not verify the host key
  because it authenticates nothing. When no TCP connection is made at all it says how it failed
  (``tcp``: refused, timeout, unreachable, error): nothing there to offer strangers anything, or
  no verdict.
- The TLS probe (standard library only) dials the master's Zenoh port with no client
  certificate, with a certificate from a throwaway CA made here (the "foreign" one, shipped in
  the program text on stdin; the probe writes it to a private temporary folder and removes it),
  and with the fleet's own certificate of the seat it runs on (the insider). An mTLS listener
  answers the first two with a TLS alert (certificate required; certificate unknown); a plain
  Zenoh listener does not speak TLS at all.
"""

from __future__ import annotations

import base64
import datetime as dt
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rosnet_tui.core.jsonsafe import loads_bounded
from rosnet_tui.core.peer import sshnone

SSH_MARK = "ROSNET_SSHAUDIT "
TLS_MARK = "ROSNET_OUTSIDER "
PASSWORD_METHODS = ("password", "keyboard-interactive")

_AUDIT_MAIN = r"""
import errno, json, socket, sys, threading
MARK = "ROSNET_SSHAUDIT "
host, port, t = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
users = sys.argv[4:]
out = {"users": {}, "python": sys.executable}
got = {}
lock = threading.Lock()

def tcp_kind(e):
    if isinstance(e, ConnectionRefusedError):
        return "refused"
    if isinstance(e, socket.timeout):
        return "timeout"
    if getattr(e, "errno", None) in (errno.EHOSTUNREACH, errno.ENETUNREACH, errno.EHOSTDOWN):
        return "unreachable"
    return "error"

def with_paramiko(user):
    # a server that offers neither curve25519 nor chacha20-poly1305: paramiko asks instead
    with lock:
        if "invoke" not in sys.modules:
            sys.modules["invoke"] = None   # paramiko's optional ssh_config helper, unused here
        import paramiko
    sock = socket.create_connection((host, port), timeout=t)
    tr = None
    try:
        sock.settimeout(t)
        tr = paramiko.Transport(sock)
        tr.banner_timeout = t; tr.handshake_timeout = t; tr.auth_timeout = t
        tr.start_client(timeout=t)
        out["banner"] = tr.remote_version
        try:
            tr.auth_none(user)
            return {"methods": ["none"], "via": "paramiko"}
        except paramiko.BadAuthenticationType as e:
            return {"methods": list(e.allowed_types), "via": "paramiko"}
    finally:
        for x in (tr, sock):
            try:
                x is not None and x.close()
            except Exception:
                pass

def audit(user):
    # sshd refuses another user name on the same connection: one connection per user, all at
    # once, so the audit costs the round trips of one
    try:
        sock = socket.create_connection((host, port), timeout=t)
    except OSError as e:
        got[user] = ("tcp", e)
        return
    try:
        sock.settimeout(t)
        try:
            methods, out["banner"] = none_methods(sock, user)
            got[user] = ("ok", {"methods": methods, "via": "sshnone"})
        except (Unsupported, ValueError, ConnectionError):   # or a server it misreads
            sock.close()
            got[user] = ("ok", with_paramiko(user))
    except ImportError as e:   # cryptography, or paramiko for a server sshnone cannot ask
        got[user] = ("ok", {"error": "no_module: %s" % e})
    except Exception as e:
        got[user] = ("ok", {"error": "%s: %s" % (type(e).__name__, e)})
    finally:
        sock.close()

threads = [threading.Thread(target=audit, args=(u,), daemon=True) for u in users]
for th in threads:
    th.start()
for th in threads:
    th.join(4 * t + 1)
reached = [u for u in users if got.get(u, ("",))[0] == "ok"]
if reached:
    out["tcp"] = "connected"
for u in users:
    kind, what = got.get(u, ("ok", {"error": "no answer within %.1f s" % (4 * t + 1)}))
    if kind == "ok":
        out["users"][u] = what
    elif reached:          # another user got through: this one's own error
        out["users"][u] = {"error": "%s: %s" % (type(what).__name__, what)}
    elif "tcp" not in out:  # no TCP at all: the other users fared the same
        out["tcp"] = tcp_kind(what)
        out["tcp_error"] = "%s: %s" % (type(what).__name__, what)
print(MARK + json.dumps(out))
"""
SSH_AUDIT_PROGRAM = Path(sshnone.__file__).read_text() + _AUDIT_MAIN
"""The SSH audit (fed on stdin): core/peer/sshnone.py asks sshd with cryptography's primitives;
paramiko only for a server that offers neither curve25519 nor chacha20-poly1305."""

_TLS_PROGRAM = r"""
import base64, json, os, select, shutil, socket, ssl, sys, tempfile, time
MARK = "ROSNET_OUTSIDER "
host, port, t = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
wait = min(1.0, t)

connected = {}   # name -> seconds its TCP connection took (a round trip, near enough)

def attempt(cert=None, key=None, ca=None, patient=True, name=None):
    t0 = time.monotonic()
    try:
        raw = socket.create_connection((host, port), timeout=t)
        connected[name] = time.monotonic() - t0
    except socket.timeout:
        return {"result": "closed", "tcp": "timeout"}
    except OSError as e:
        return {"result": "closed", "tcp": "refused" if isinstance(e, ConnectionRefusedError)
                else "error", "detail": str(e)[:160]}
    ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
    if ca:
        ctx.load_verify_locations(ca)
    else:
        ctx.check_hostname = False
        ctx.verify_mode = ssl.CERT_NONE
    if cert:
        ctx.load_cert_chain(cert, key)
    raw.settimeout(t)
    out = {"tcp": "connected"}
    started = time.monotonic()
    try:
        s = ctx.wrap_socket(raw, server_hostname=host)
    except ssl.SSLCertVerificationError as e:
        raw.close()
        out.update(result="server_cert", detail=str(e.verify_message)[:160],
                   code=e.verify_code)
        return out
    except ssl.SSLError as e:
        raw.close()
        why = e.reason or str(e)
        out.update(result="alert" if "ALERT" in why else "not_tls", detail=str(why)[:160])
        return out
    except socket.timeout:      # no answer: a plain router waits for more, a slow link is late
        raw.close()
        out.update(result="timeout", detail="no TLS answer to our hello within %.1f s" % t)
        return out
    except (OSError, ValueError) as e:
        raw.close()
        out.update(result="not_tls", detail=("%s: %s" % (type(e).__name__, e))[:160])
        return out
    out["tls"] = s.version()
    out["server_cert"] = base64.b64encode(s.getpeercert(True) or b"").decode()
    # TLS 1.3: the server's verdict on our certificate follows the handshake, half a round trip
    # after our last message: an alert refuses it; a session ticket, which a server sends only
    # once it has taken the certificate (Zenoh's rustls sends two), accepts it. Either ends the
    # wait at once, so a healthy verdict costs a round trip. A server that sends no ticket
    # answers a taken certificate with silence: it reads as accepted when the wait ends. A
    # stranger (patient) waits the whole per-step timeout (its healthy answer, a refusal, ends it
    # at once, and a busy router's late refusal must not read as a session); the insider five
    # handshake times (0.4 s to `wait`).
    limit = t if patient else min(wait, max(0.4, 5 * (time.monotonic() - started)))
    out.update(zip(("result", "detail"), verdict(s, limit, patient)))
    return out


def verdict(s, limit, patient):
    end = time.monotonic() + limit
    try:
        s.setblocking(False)
        while True:
            left = end - time.monotonic()
            if not s.pending() and (left <= 0 or not select.select([s], [], [], left)[0]):
                if patient:     # a stranger: Zenoh takes a certificate with tickets, refuses
                    return "timeout", "no verdict within %.1f s" % limit   # with an alert
                return "accepted", "no verdict within %.1f s: taken" % limit
            try:
                return ("accepted", "data") if s.recv(1) else ("closed", "the server hung up")
            except ssl.SSLWantReadError:     # a handshake message, no data: a ticket?
                if s.session is not None and s.session.has_ticket:
                    return "accepted", "a session ticket came: the certificate was taken"
            except ssl.SSLError as e:
                return "alert", str(e.reason or e)[:160]
            except OSError as e:
                return "closed", str(e)[:160]
    finally:
        s.close()

# A Zenoh client's first message in plain TCP (InitSyn of protocol 1.x, no extensions, a client
# with a random id): a plain router answers with its InitAck at once, a TLS-only port with an
# alert. Asked only while our TLS hello has no answer (see watch): the proof of a plain port is
# then an answer, not a silence (which a slow link gives too).
def plain_hello():
    body = bytes([0x41, 0x09, 0xf2]) + os.urandom(16) + bytes([0x0a, 0xc8, 0xff])
    try:
        raw = socket.create_connection((host, port), timeout=t)
    except OSError as e:
        return {"result": "closed", "detail": str(e)[:160]}
    try:
        raw.settimeout(t)
        raw.sendall(len(body).to_bytes(2, "little") + body)
        data = raw.recv(64)
    except socket.timeout:
        return {"result": "timeout", "detail": "no answer to a plain Zenoh hello within %.1f s" % t}
    except OSError as e:
        return {"result": "hung_up", "detail": str(e)[:160]}
    finally:
        raw.close()
    if not data:
        return {"result": "hung_up", "detail": "the port hung up on a plain Zenoh hello"}
    if len(data) >= 3 and data[2] & 0x3f == 0x21:      # INIT with its ack flag
        return {"result": "accepted", "detail": "a plain Zenoh hello got the router's InitAck"}
    if data[0] in (0x15, 0x16):                         # a TLS record: an alert, as a rule
        return {"result": "refused", "detail": "the port answered a plain Zenoh hello in TLS"}
    return {"result": "other", "detail": "an answer that is no Zenoh InitAck: " + data[:8].hex()}

import threading
rep = {}
settled = threading.Event()     # a plain Zenoh session was had: nothing else can change that
hello_done = threading.Event()  # the stranger's TLS hello (no_cert) has its result
asked = threading.Lock()

def ask_plain():
    if not asked.acquire(blocking=False):     # once per run
        return
    got = plain_hello()
    rep["plain"] = got
    if got.get("result") == "accepted":
        settled.set()

def run(name, *a):
    try:
        rep[name] = attempt(*a, name=name)
    except (OSError, ssl.SSLError, ValueError) as e:
        rep[name] = {"result": "no_fleet_cert" if name == "insider" else "error",
                     "detail": str(e)[:160]}
    if name == "no_cert":
        hello_done.set()
        if rep[name].get("result") == "timeout":
            ask_plain()

def watch():
    # A TLS port answers our hello within a round trip or two; a plain router says nothing,
    # waiting for more. A hello still unanswered after five connect times (0.3 s at least) has
    # the plain hello asked beside it, so a plain port is proven by its answer at once instead
    # of after the whole wait (on a slow link a TLS port answers it with an alert: no harm).
    end = time.monotonic() + t
    while "no_cert" not in connected and time.monotonic() < end:
        if hello_done.wait(0.01):
            return
    if "no_cert" in connected and not hello_done.wait(max(0.3, 5 * connected["no_cert"])):
        ask_plain()

tmp = tempfile.mkdtemp(prefix="rosnet-outsider-")
try:
    os.chmod(tmp, 0o700)
    for name, text in FOREIGN.items():
        fd = os.open(os.path.join(tmp, name), os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "w") as f:
            f.write(text)
    try:   # where the rosnet-tui installed on this seat keeps its fleet certificate
        from rosnet_tui.core.ros.fleet_tls import tls_paths
        p = tls_paths()
        files = [str(p.node_crt), str(p.node_key), str(p.ca_crt)]
        missing = [f for f in files if not os.path.isfile(f)]
        why = "missing: " + ", ".join(missing)
    except ImportError:   # the peer's python3 (no rosnet-tui there, so no fleet certificate)
        files, missing, why = [], ["rosnet-tui"], "rosnet-tui is not installed on this seat"
    if missing:
        rep["insider"] = {"result": "no_fleet_cert", "detail": why}
    # The insider goes first, the strangers when it is done (or after half of `wait`): Zenoh's
    # router sleeps 100 ms after every handshake it refuses, handshakes in flight included, so
    # an insider behind a refusal would wait for its ticket, and behind both, 200 ms.
    jobs = [("no_cert",), ("foreign", os.path.join(tmp, "crt"), os.path.join(tmp, "key"))]
    threads = []
    if not missing:
        threads.append(threading.Thread(target=run, args=("insider", *files, False),
                                        daemon=True))
        threads[0].start()
        threads[0].join(wait / 2)
    threads += [threading.Thread(target=run, args=j, daemon=True) for j in jobs]
    threads.append(threading.Thread(target=watch, daemon=True))
    for th in threads[-3:]:
        th.start()
    end = time.monotonic() + 4 * t + wait + 1
    while any(th.is_alive() for th in threads) and time.monotonic() < end:
        if settled.wait(0.01):
            break
    if settled.is_set():     # the hellos a plain router leaves unanswered: not waited for
        for name in ("no_cert", "foreign", "insider"):
            if name not in rep:
                rep[name] = {"result": "timeout", "tcp": "connected", "detail": "no TLS "
                             "answer; not waited for: the port took a plain Zenoh session"}
finally:
    shutil.rmtree(tmp, ignore_errors=True)
print(MARK + json.dumps(dict(rep)))
"""

_FOREIGN: dict[str, str] = {}


def foreign_pems() -> dict[str, str]:
    """A throwaway CA's client certificate and key (PEM), made once per process: what a
    stranger with a certificate of their own (or a member of another fleet) presents."""
    if not _FOREIGN:
        from cryptography import x509
        from cryptography.hazmat.primitives import hashes, serialization
        from cryptography.hazmat.primitives.asymmetric import ec
        from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

        now = dt.datetime.now(dt.timezone.utc)
        ca_key, key = ec.generate_private_key(ec.SECP256R1()), ec.generate_private_key(ec.SECP256R1())
        ca_name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "rosnet-tui outsider CA")])
        name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "rosnet-tui-outsider")])
        cert = (x509.CertificateBuilder().subject_name(name).issuer_name(ca_name)
                .public_key(key.public_key()).serial_number(x509.random_serial_number())
                .not_valid_before(now - dt.timedelta(minutes=5))
                .not_valid_after(now + dt.timedelta(days=1))
                .add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.CLIENT_AUTH,
                                                      ExtendedKeyUsageOID.SERVER_AUTH]), False)
                .add_extension(x509.SubjectAlternativeName([x509.DNSName("rosnet-tui-outsider")]),
                               False)
                .sign(ca_key, hashes.SHA256()))
        _FOREIGN["crt"] = cert.public_bytes(serialization.Encoding.PEM).decode()
        _FOREIGN["key"] = key.private_bytes(serialization.Encoding.PEM,
                                            serialization.PrivateFormat.PKCS8,
                                            serialization.NoEncryption()).decode()
    return dict(_FOREIGN)


def tls_probe_program() -> bytes:
    """The TLS probe's source, the foreign certificate inside (fed on stdin)."""
    return (f"FOREIGN = {json.dumps(foreign_pems())}\n" + _TLS_PROGRAM).encode()


def parse_marked(stdout: str, mark: str) -> dict[str, Any] | None:
    """The JSON report after *mark* on a line of a peer program's output (None: none)."""
    for line in stdout.splitlines():
        if line.startswith(mark):
            try:
                rep = loads_bounded(line[len(mark):], unique_keys=False)
            except ValueError:
                return None
            return rep if isinstance(rep, dict) else None
    return None


def as_dict(x: Any) -> dict[str, Any]:
    """*x* when a peer's report holds a dict there, else an empty one (any shape is refused
    cleanly, never a traceback)."""
    return x if isinstance(x, dict) else {}


# --------------------------------------------------------------------------- SSH audit verdict
# How the audit's TCP connection to sshd failed when nothing was reached: refused (a reset: a
# modem that forwards nothing there, or no sshd), timeout (dropped) or unreachable (an ICMP
# error). Any of these means the internet, seen from that peer, reaches no sshd at all.
NOT_REACHED = ("refused", "timeout", "unreachable")


@dataclass
class SshAudit:
    methods: list[str]          # offered to an ordinary user
    root_methods: list[str]     # offered to root
    error: str | None
    tcp: str | None = None      # core/net/connect.py's kinds ("connected", "refused", ...); None: untold
    tcp_error: str | None = None  # the failed connection's error, in words

    @property
    def not_reached(self) -> bool:
        """Whether the audit found nothing at the address to talk to (no TCP connection)."""
        return self.tcp in NOT_REACHED and not self.methods and not self.root_methods

    @property
    def password(self) -> bool:
        return "password" in self.methods

    @property
    def keyboard_interactive(self) -> bool:
        return "keyboard-interactive" in self.methods

    @property
    def root_password(self) -> bool:
        return any(m in self.root_methods for m in PASSWORD_METHODS)


def read_ssh_audit(rep: dict[str, Any], user: str) -> SshAudit:
    users = as_dict(rep.get("users"))
    mine, root = as_dict(users.get(user)), as_dict(users.get("root"))
    err = mine.get("error") or (root.get("error") if user != "root" else None)

    def methods(x: Any) -> list[str]:
        got = x.get("methods")
        return [str(m) for m in got] if isinstance(got, list) else []
    tcp, tcp_error = rep.get("tcp"), rep.get("tcp_error")
    err = err or tcp_error      # no TCP connection: that is why nothing was read
    return SshAudit(methods(mine), methods(root), str(err) if err else None,
                    str(tcp) if isinstance(tcp, str) else None,
                    str(tcp_error) if tcp_error else None)


def ssh_fix(host_name: str, user: str) -> list[str]:
    """The exact steps that take passwords off an sshd, keys first."""
    return [f"From each machine that logs in to {host_name}: `ssh-copy-id {user}@{host_name}`, "
            f"then check that `ssh {user}@{host_name} true` works without a password.",
            f"On {host_name}, in /etc/ssh/sshd_config.d/10-rosnet-tui.conf (sshd takes the first "
            "value it reads, and Debian reads this folder first): `PasswordAuthentication no` and "
            "`KbdInteractiveAuthentication no` (and `PermitRootLogin prohibit-password`).",
            "Check and reload: `sudo sshd -t && sudo systemctl reload ssh` "
            "(`sudo sshd -T | grep -i -E 'passwordauth|kbdinteractive|permitrootlogin'` shows "
            "what it now uses)."]


# --------------------------------------------------------------------------- TLS verdict
def refused(att: dict[str, Any]) -> bool:
    """Whether an outsider attempt got no session (anything but an accepted handshake, a port
    that speaks plain TCP, or no verdict in time)."""
    return att.get("result") not in ("accepted", "not_tls", "timeout", None)  # None: no report


def no_verdict(att: dict[str, Any]) -> bool:
    """Whether an attempt's answer did not come in time (a slow or busy link): not judged."""
    return att.get("result") == "timeout"


def plain_attempt(no_cert: dict[str, Any], plain: dict[str, Any] | None = None
                  ) -> dict[str, Any]:
    """The plain-TCP verdict: a port that answers our ClientHello with a TLS handshake speaks
    only TLS, so a plain Zenoh session cannot open there; one whose reply is no TLS record takes
    plain sessions. Silence to the ClientHello proves nothing (a plain router waits for more, a
    slow link is late): then *plain*, the answer to a plain Zenoh hello, decides: an InitAck
    (open), TLS (refused), a hang-up or another answer (no TLS and no Zenoh of this version:
    taken as open), or silence again (no verdict)."""
    r = no_cert.get("result")
    if r == "closed":
        return {"result": "closed", "detail": "the port did not accept TCP"}
    if r == "not_tls":
        return {"result": "accepted", "detail": "the port does not speak TLS: a plain Zenoh "
                                                "session opens there"}
    if r == "timeout":
        p = plain or {}
        pr, detail = p.get("result"), str(p.get("detail") or "")
        if pr == "accepted":
            return {"result": "accepted", "detail": detail}
        if pr in ("hung_up", "other"):
            return {"result": "accepted", "detail": f"no TLS answer, and {detail}: taken as open"}
        if pr == "refused":
            return {"result": "refused", "detail": detail}
        return {"result": "timeout", "detail": detail or "no answer to our hellos in time"}
    return {"result": "refused", "detail": "the port speaks only TLS (it answered our "
                                           "ClientHello with a TLS handshake)"}


@dataclass
class CertFacts:
    names: list[str]
    not_after: str
    expired: bool
    issuer: str


def cert_facts(der_b64: str) -> CertFacts | None:
    """Names, expiry and issuer of a DER certificate (base64), or None."""
    try:
        from cryptography import x509

        cert = x509.load_der_x509_certificate(base64.b64decode(der_b64))
    except Exception:  # noqa: BLE001 - a peer's bytes: anything unreadable is "no facts"
        return None
    names = [a.value for a in cert.subject.get_attributes_for_oid(x509.NameOID.COMMON_NAME)]
    try:
        san = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
        names += [str(n) for n in san.get_values_for_type(x509.DNSName)]
        names += [str(n) for n in san.get_values_for_type(x509.IPAddress)]
    except x509.ExtensionNotFound:
        pass
    end = cert.not_valid_after_utc
    return CertFacts(list(dict.fromkeys(str(n) for n in names)), end.isoformat(),
                     end < dt.datetime.now(dt.timezone.utc), cert.issuer.rfc4514_string())


def insider_cause(ins: dict[str, Any]) -> str | None:
    """Why the fleet's own certificate did not get in (None: it did)."""
    r, detail = ins.get("result"), str(ins.get("detail") or "").lower()
    if r == "accepted":
        return None
    if r == "no_fleet_cert":
        return "no_fleet_cert"
    if r == "closed":
        return "unreachable"
    if r == "server_cert":
        if "hostname" in detail or "ip address mismatch" in detail:
            return "wrong_name"
        if "expired" in detail:
            return "expired"
        return "foreign_ca"          # the master's certificate is not from this seat's CA
    if r == "alert":
        if "expired" in detail:
            return "expired"
        if "unknown" in detail or "bad_certificate" in detail or "unknown_ca" in detail:
            return "foreign_ca"       # the master does not know this seat's certificate
        return "refused"
    if r == "not_tls":
        return "plain_open"
    return "refused"
