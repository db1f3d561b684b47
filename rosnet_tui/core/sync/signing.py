"""Who may speak for a component in the sync store: its own Ed25519 key.

Every component has a sync key of its own (``config.sync.key`` beside its settings file, 0600,
made on first use; the same for ROS 1 and ROS 2, so a ROS 1 fleet without fleet TLS has one
too). Its public half is pinned on every other component as that peer's ``sync_key`` in the settings
(``rosnet-tui sync key`` prints the line to copy). A record counts only with a valid ``sig``
by the key pinned for its name: anyone who can write the shared folder or the zone (another
member, a Syncthing participant) can delete or replay records, but cannot make one, and so
cannot raise a component's sequence past what its owner publishes.

What is signed: the record's canonical JSON (every field but ``sig``, keys sorted, no spaces),
after a fixed prefix (a signature for something else never fits a record).
"""

from __future__ import annotations

import base64
import binascii
import json
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives import serialization as ser
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey, Ed25519PublicKey

from rosnet_tui.core.config.settings_model import SYNC_KEY_RE, Settings
from rosnet_tui.core.files.managed_write import atomic_write
from rosnet_tui.core.files.regular_file import read_regular
from rosnet_tui.core.saved.sync_records import Record
from rosnet_tui.core.ssh.known_hosts import key_fingerprint

PREFIX = b"rosnet-tui sync record v1\n"
KEY_SUFFIX = ".sync.key"


def key_path(config_path: Path) -> Path:
    """This component's sync key: beside its settings file, named after it (``config.toml``'s
    is ``config.sync.key``), so two settings files in one folder have a key each."""
    p = Path(config_path)
    return p.with_name(p.stem + KEY_SUFFIX)


def load_or_make_key(path: Path) -> Ed25519PrivateKey:
    """This component's signing key, made (0600) when there is none yet. Raises OSError or
    ValueError (a file that is not one)."""
    try:    # a regular file only (a FIFO is refused, never waited on), never through a link
        data = read_regular(path, 4096, follow=False)
    except FileNotFoundError:
        key = Ed25519PrivateKey.generate()
        path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
        atomic_write(path, key.private_bytes(ser.Encoding.PEM, ser.PrivateFormat.PKCS8,
                                             ser.NoEncryption()), create_mode=0o600, mode=0o600)
        return key
    key = ser.load_pem_private_key(data, password=None)
    if not isinstance(key, Ed25519PrivateKey):
        raise ValueError(f"{path} is not an Ed25519 key")
    return key


def public_text(key: Ed25519PrivateKey | Ed25519PublicKey) -> str:
    """``ed25519:BASE64``: the form a peer's ``sync_key`` takes."""
    pub = key.public_key() if isinstance(key, Ed25519PrivateKey) else key
    raw = pub.public_bytes(ser.Encoding.Raw, ser.PublicFormat.Raw)
    return "ed25519:" + base64.b64encode(raw).decode()


def parse_public(text: str) -> Ed25519PublicKey:
    """A pinned ``sync_key``. Raises ValueError."""
    if not SYNC_KEY_RE.match(text or ""):
        raise ValueError("not a sync key (ed25519:...)")
    return Ed25519PublicKey.from_public_bytes(base64.b64decode(text.split(":", 1)[1]))


def fingerprint(text: str) -> str:
    """A pinned key's short form to compare by eye: ``SHA256:`` and the base64 of its digest (as
    ssh-keygen shows host keys). Raises ValueError."""
    if not SYNC_KEY_RE.match(text or ""):
        raise ValueError("not a sync key (ed25519:...)")
    return key_fingerprint(base64.b64decode(text.split(":", 1)[1]))


def canonical(rec: Record) -> bytes:
    body = rec.to_json()
    body.pop("sig", None)
    return PREFIX + json.dumps(body, sort_keys=True, separators=(",", ":")).encode()


def sign_record(rec: Record, key: Ed25519PrivateKey) -> Record:
    """*rec* with its signature by *key*."""
    return replace(rec, sig=base64.b64encode(key.sign(canonical(replace(rec, sig="")))).decode())


def signature_problem(rec: Record, key: Ed25519PublicKey | None) -> str | None:
    """Why *rec* does not count as its owner's (None: it does)."""
    if key is None:
        return (f"no sync key of {rec.name} is pinned here (its [[peer]] sync_key): "
                f"`rosnet-tui sync pin {rec.name}` fetches it over SSH")
    if not rec.sig:
        return f"unsigned: only a record signed by {rec.name}'s own key counts"
    try:
        sig = base64.b64decode(rec.sig, validate=True)
        key.verify(sig, canonical(rec))
    except (InvalidSignature, binascii.Error, ValueError):
        return (f"its signature is not by {rec.name}'s key (changed or forged by someone else)")
    return None


def pinned_keys(s: Settings, own: Ed25519PrivateKey | None) -> dict[str, Any]:
    """Name (lower case) to public key: each peer's pinned sync_key (None when not pinned or
    unreadable), and this component's own."""
    out: dict[str, Any] = {}
    for p in s.peers:
        try:
            out[p.name.lower()] = parse_public(p.sync_key) if p.sync_key else None
        except ValueError:
            out[p.name.lower()] = None
    out[s.this.name.lower()] = own.public_key() if own is not None else None
    return out


def verify_each(copies: list[Any], keys: Mapping[str, Any]) -> tuple[list[Any], list[Any]]:
    """Split candidates (``.record``) into (signed by their owner, [(candidate, why)])."""
    good, bad = [], []
    for c in copies:
        why = signature_problem(c.record, keys.get(c.record.name.lower()))
        if why is None:
            good.append(c)
        else:
            bad.append((c, why))
    return good, bad
