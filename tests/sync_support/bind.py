"""An authoritative BIND 9 server (Debian package bind9) in the lab's internet namespace, taking
TSIG-signed RFC 2136 updates for one zone: the DNS store's server in the tests and the bench.

It listens on its own address (192.0.2.54 by default; the lab's tiny resolver already has
192.0.2.53), added to the internet namespace's loopback for the server's lifetime and removed
after. Nothing listens outside the lab.
"""

from __future__ import annotations

import base64
import contextlib
import os
import shutil
import subprocess
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

NAMED = "/usr/sbin/named"
DEFAULT_IP = "192.0.2.54"
DEFAULT_ZONE = "robots.lab.test"
KEY_NAME = "rosnet-sync"


def bind_available() -> tuple[bool, str]:
    if not os.access(NAMED, os.X_OK) and shutil.which("named") is None:
        return False, "BIND is not installed (Debian package bind9): the DNS store test skips"
    return True, ""


@dataclass
class BindServer:
    lab: object
    proc: subprocess.Popen
    dir: Path
    ip: str
    zone: str
    key_file: Path
    key_name: str
    secret: str

    def log(self) -> str:
        return self.lab.output(self.proc)  # type: ignore[attr-defined]


def _named_conf(d: Path, ip: str, zone: str, key_name: str, secret: str) -> str:
    return f"""
options {{
    directory "{d}";
    pid-file "{d}/named.pid";
    session-keyfile "{d}/session.key";
    managed-keys-directory "{d}";
    listen-on port 53 {{ {ip}; }};
    listen-on-v6 {{ none; }};
    recursion no;
    allow-query {{ any; }};
    dnssec-validation no;
    notify no;
}};
controls {{ }};
key "{key_name}" {{
    algorithm hmac-sha256;
    secret "{secret}";
}};
zone "{zone}" {{
    type primary;
    file "{d}/db.zone";
    update-policy {{ grant {key_name} zonesub A TXT; }};
}};
"""


def _zone_file(zone: str, ip: str) -> str:
    return (f"$TTL 60\n@ IN SOA ns.{zone}. hostmaster.{zone}. 1 60 60 3600 60\n"
            f"@ IN NS ns.{zone}.\nns IN A {ip}\n")


def write_key_file(path: Path, key_name: str, secret: str) -> Path:
    """A BIND-style key file, as `tsig-keygen` writes it (mode 0600)."""
    path.write_text(f'key "{key_name}" {{\n\talgorithm hmac-sha256;\n\tsecret "{secret}";\n}};\n')
    os.chmod(path, 0o600)
    return path


def new_secret() -> str:
    return base64.b64encode(os.urandom(32)).decode()


def start_bind(lab, workdir: Path, *, ip: str = DEFAULT_IP, zone: str = DEFAULT_ZONE,
               key_name: str = KEY_NAME, secret: str | None = None,
               timeout: float = 20.0) -> BindServer:
    """Start named in the lab's internet namespace; returns when it answers (bounded).
    The key file (BIND style) is ``workdir/tsig.key``; pass *secret* to keep an earlier one."""
    ok, why = bind_available()
    if not ok:
        raise RuntimeError(why)
    d = Path(workdir)
    d.mkdir(parents=True, exist_ok=True)
    secret = secret or new_secret()
    (d / "named.conf").write_text(_named_conf(d, ip, zone, key_name, secret))
    (d / "db.zone").write_text(_zone_file(zone, ip))
    for stale in d.glob("db.zone.jnl"):
        stale.unlink()
    key_file = write_key_file(d / "tsig.key", key_name, secret)
    lab.run("internet", ["ip", "addr", "replace", f"{ip}/32", "dev", "lo"])
    named = NAMED if os.access(NAMED, os.X_OK) else shutil.which("named")
    proc = lab.spawn("internet", [named, "-g", "-n", "1", "-c", str(d / "named.conf")])
    server = BindServer(lab, proc, d, ip, zone, key_file, key_name, secret)
    # "running" alone on its line (named also says "running as: named -g ..." at the start)
    if lab.wait_output(proc, r"(?m) running\s*$", timeout=timeout) is None \
            or not wait_answers(lab, server, timeout=5.0):
        out = lab.output(proc)
        stop_bind(server)
        raise RuntimeError(f"named did not start within {timeout} s:\n{out[-3000:]}")
    return server


def stop_bind(server: BindServer) -> None:
    """Stop named (bounded) and take its address away again."""
    server.lab.kill(server.proc, grace=2.0)  # type: ignore[attr-defined]
    with contextlib.suppress(Exception):
        server.lab.run("internet", ["ip", "addr", "del", f"{server.ip}/32", "dev", "lo"])  # type: ignore[attr-defined]


@contextlib.contextmanager
def bind_server(lab, workdir: Path, **kw) -> Iterator[BindServer]:
    server = start_bind(lab, workdir, **kw)
    try:
        yield server
    finally:
        stop_bind(server)


def query_a(lab, server: BindServer, name: str, timeout: float = 3.0) -> list[str]:
    """The A records of NAME.ZONE, asked of the server from inside the internet namespace."""
    import dns.message
    import dns.query
    import dns.rdatatype

    def ask() -> list[str]:
        q = dns.message.make_query(f"{name}.{server.zone}.", "A")
        r = dns.query.udp(q, server.ip, timeout=timeout)
        return [rd.address for rrset in r.answer if rrset.rdtype == dns.rdatatype.A
                for rd in rrset]
    return lab.call_in("internet", ask, timeout=timeout + 5)


def wait_answers(lab, server: BindServer, timeout: float = 10.0) -> bool:
    """Whether the server answers an SOA query within *timeout* (asked from the internet ns)."""
    import dns.message
    import dns.query

    def ask() -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                q = dns.message.make_query(f"{server.zone}.", "SOA")
                dns.query.udp(q, server.ip, timeout=0.5)
                return True
            except Exception:
                time.sleep(0.05)
        return False
    return lab.call_in("internet", ask, timeout=timeout + 5)
