"""Host keys: which known_hosts files we trust, what they say about a host, and adding one.

known_hosts is read by our own parser (hashed names, wildcards, negations, markers):
``@cert-authority`` lines are not used (the result says so), a key marked ``@revoked`` is refused,
and any listed key of the server's type is accepted, as OpenSSH does. Reads are bounded and a
FIFO never hangs.
"""

from __future__ import annotations

import base64
import binascii
import errno
import hashlib
import hmac
import os
import re
import stat
from dataclasses import dataclass
from pathlib import Path

from rosnet_tui.core.files.regular_file import read_regular
from rosnet_tui.core.ssh.options import SshOptions, ssh_dir


def host_key_name(name: str, port: int) -> str:
    """The known_hosts spelling of a host: ``name`` on port 22, ``[name]:port`` otherwise."""
    return name if port == 22 else f"[{name}]:{port}"


MAX_KNOWN_HOSTS_BYTES = 16 << 20


@dataclass
class KnownHostKeys:
    """What known_hosts says of one host: its keys by type (every listed key counts, as with
    OpenSSH), the revoked keys, and notes on lines that were not used."""

    keys: dict[str, list[bytes]]          # key type -> key blobs, in file order
    revoked: set[bytes]                   # blobs marked @revoked (for any host: never accepted)
    notes: list[str]

    def fingerprints(self, ktype: str | None = None) -> list[str]:
        types = [ktype] if ktype else list(self.keys)
        return [key_fingerprint(b) for t in types for b in self.keys.get(t, [])]


def key_fingerprint(blob: bytes) -> str:
    """OpenSSH's SHA256 fingerprint of a public key blob."""
    return "SHA256:" + base64.b64encode(hashlib.sha256(blob).digest()).decode().rstrip("=")


def _read_known_hosts(path: Path) -> str | None:
    """The text of one known_hosts file; None when missing, unreadable, not a regular file (a
    FIFO there must not hang a check) or over MAX_KNOWN_HOSTS_BYTES."""
    try:
        return read_regular(path, MAX_KNOWN_HOSTS_BYTES).decode("utf-8", "replace")
    except OSError:
        return None


def _pattern_matches(pattern: str, name: str) -> bool:
    """OpenSSH host pattern: ``*`` and ``?`` wildcards, case-insensitive; brackets are literal
    (``[name]:port``)."""
    rx = "".join(".*" if c == "*" else "." if c == "?" else re.escape(c) for c in pattern.lower())
    return re.fullmatch(rx, name.lower()) is not None


def _hosts_match(field: str, name: str) -> bool:
    """Whether a known_hosts host field (patterns, negations, a hashed name) names *name*."""
    if field.startswith("|1|"):
        parts = field.split("|")
        if len(parts) != 4:
            return False
        try:
            salt = base64.b64decode(parts[2], validate=True)
            want = base64.b64decode(parts[3], validate=True)
        except (binascii.Error, ValueError):
            return False
        return hmac.compare_digest(hmac.new(salt, name.encode(), hashlib.sha1).digest(), want)
    matched = False
    for pat in field.split(","):
        if pat.startswith("!"):
            if _pattern_matches(pat[1:], name):
                return False          # a negated pattern that matches excludes the host
        elif pat and _pattern_matches(pat, name):
            matched = True
    return matched


def _key_blob(ktype: str, b64: str) -> bytes | None:
    """The key blob of a ``type base64`` pair, or None when it is not a well-formed key of
    that type (the blob starts with its own type name)."""
    try:
        blob = base64.b64decode(b64, validate=True)
    except (binascii.Error, ValueError):
        return None
    if len(blob) < 4:
        return None
    n = int.from_bytes(blob[:4], "big")
    if blob[4:4 + n] != ktype.encode("ascii", "replace") or len(blob) <= 4 + n:
        return None
    return blob


def known_host_keys(files: list[Path], lookup: str) -> KnownHostKeys:
    """Read *files* (OpenSSH known_hosts format) for the host spelled *lookup*.

    Never raises for a file's content: a line we cannot use is skipped. ``@cert-authority``
    lines are not used (host certificates are not checked here; the server's plain key must be
    listed) and said in the notes when they name this host; ``@revoked`` keys are refused
    whatever host they name."""
    out = KnownHostKeys({}, set(), [])
    ca_lines, bad_lines = 0, 0
    for f in files:
        text = _read_known_hosts(f)
        if text is None:
            continue
        for raw in text.split("\n"):
            line = raw.strip()
            if not line or line.startswith("#"):
                continue
            fields = line.split()
            marker = fields.pop(0) if fields[0].startswith("@") else None
            if len(fields) < 3:
                if fields and _hosts_match(fields[0], lookup):
                    bad_lines += 1
                continue
            hosts, ktype, b64 = fields[0], fields[1], fields[2]
            if marker == "@revoked":
                blob = _key_blob(ktype, b64)
                if blob is not None:
                    out.revoked.add(blob)
                continue
            if not _hosts_match(hosts, lookup):
                continue
            if marker == "@cert-authority":
                ca_lines += 1
                continue
            blob = _key_blob(ktype, b64) if marker is None else None
            if blob is None:
                bad_lines += 1
                continue
            if blob not in out.keys.setdefault(ktype, []):
                out.keys[ktype].append(blob)
    if ca_lines:
        out.notes.append(f"{ca_lines} @cert-authority line(s) for this host not used (host "
                         "certificates are not checked; the server's own key must be listed)")
    if bad_lines:
        out.notes.append(f"{bad_lines} malformed line(s) for this host skipped")
    return out


def trust_host_key(opts: SshOptions | None, name: str, port: int, host_key: str) -> Path:
    """Append *host_key* ("<type> <base64>", as in SshResult.host_key) for *name* to known_hosts.

    Call this only after the user compared the fingerprint; it never replaces an existing entry
    (a changed key must be removed by the user, ``ssh-keygen -R NAME``). Returns the file written.
    """
    ktype, _, b64 = host_key.strip().partition(" ")
    base64.b64decode(b64.split()[0], validate=True)  # refuse garbage
    path = ssh_dir(opts) / "known_hosts"
    if known_host_keys([path], host_key_name(name, port)).keys.get(ktype):
        raise ValueError(f"{path} already has a {ktype} key for {name}; remove it first "
                         f"(ssh-keygen -R {host_key_name(name, port)})")
    path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
    line = f"{host_key_name(name, port)} {ktype} {b64.split()[0]}\n"
    try:   # without blocking: a FIFO there (no reader) must not hang the wizard
        fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_NONBLOCK, 0o600)
    except OSError as exc:
        if exc.errno == errno.ENXIO:
            raise ValueError(f"{path} is not a regular file (a FIFO?); nothing was written") \
                from None
        raise
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise ValueError(f"{path} is not a regular file; nothing was written")
    os.set_blocking(fd, True)
    with os.fdopen(fd, "a", encoding="utf-8") as f:
        if f.tell() > 0:
            with open(path, "rb") as r:
                r.seek(-1, os.SEEK_END)
                if r.read(1) != b"\n":
                    f.write("\n")
        f.write(line)
    return path


_KEYSCAN_TYPE = {"ssh-ed25519": "ed25519", "ssh-rsa": "rsa", "ssh-dss": "dsa"}


def fingerprint_command(port: int = 22, key_type: str = "") -> str:
    """The command that prints, run on a machine itself, its sshd's host key fingerprint (of
    *key_type* when known): it asks the running sshd, so it holds wherever sshd keeps its keys
    (a HostKey outside /etc/ssh) and whatever their type. Run from anywhere else it would show
    whatever answers on the way, a man in the middle too: it proves nothing there."""
    kind = _KEYSCAN_TYPE.get(key_type, "ecdsa" if key_type.startswith("ecdsa") else "")
    opts = (f" -t {kind}" if kind else "") + (f" -p {port}" if port != 22 else "")
    return f"ssh-keyscan{opts} 127.0.0.1 2>/dev/null | ssh-keygen -lf -"


def verify_commands(name: str, port: int, key_type: str = "ssh-ed25519", user: str = "") -> str:
    """How a user can check a fingerprint themselves, and accept it with plain ssh."""
    p = f" -p {port}" if port != 22 else ""
    login = f"{user}@{name}" if user else name
    return (f"compare with what `{fingerprint_command(port, key_type)}` prints on {name} itself "
            f"(its console, or someone you trust there); if it matches, accept it by running "
            f"`ssh{p} {login}` once, or in rosnet-tui")
