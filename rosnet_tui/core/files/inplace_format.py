"""The in-place journal's format (:mod:`.cut_writes` says where it lies, :mod:`.managed_write`
writes and completes it): MAGIC, one line of JSON (path, dev, ino, lengths and sha256 of the old
and the new bytes), the old bytes, the new bytes; and what a rewrite cut short can leave."""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

from rosnet_tui.core.files.cut_writes import MAGIC
from rosnet_tui.core.jsonsafe import loads_bounded


def journal_bytes(real: Path, st: os.stat_result, old: bytes, new: bytes) -> bytes:
    head = {"path": str(real), "dev": st.st_dev, "ino": st.st_ino,
            "old_len": len(old), "old_sha256": hashlib.sha256(old).hexdigest(),
            "new_len": len(new), "new_sha256": hashlib.sha256(new).hexdigest()}
    return MAGIC + json.dumps(head, sort_keys=True).encode() + b"\n" + old + new


def parse_journal(data: bytes) -> tuple[dict, bytes, bytes] | None:
    """(header, old, new) of an in-place journal, or None when it is not a whole, valid one."""
    if not data.startswith(MAGIC):
        return None
    nl = data.find(b"\n", len(MAGIC))
    if nl < 0:
        return None
    try:
        head = loads_bounded(data[len(MAGIC):nl].decode("utf-8"))
        old_len, new_len = int(head["old_len"]), int(head["new_len"])
    except (ValueError, TypeError, KeyError):   # JsonInputError, UnicodeDecodeError included
        return None
    body = data[nl + 1:]
    if old_len < 0 or new_len < 0 or len(body) != old_len + new_len:
        return None
    old, new = body[:old_len], body[old_len:]
    if hashlib.sha256(old).hexdigest() != head.get("old_sha256") \
            or hashlib.sha256(new).hexdigest() != head.get("new_sha256"):
        return None
    return head, old, new


def common_prefix(a: bytes, b: bytes) -> int:
    n = min(len(a), len(b))
    lo, step = 0, 1 << 16
    while lo < n:                                 # whole blocks first, then bytes
        hi = min(n, lo + step)
        if a[lo:hi] != b[lo:hi]:
            break
        lo = hi
    while lo < n and a[lo] == b[lo]:
        lo += 1
    return lo


SECTOR = 512


def is_torn(cur: bytes, old: bytes, new: bytes) -> bool:
    """Whether *cur* is what rewriting *old* with *new* in place leaves when cut short: the new
    bytes up to some point and the old ones after it (a killed writer: not yet truncated, or
    extended); or, after the machine itself went down, each 512-byte sector the old one or the
    new one (zeros where the file grew)."""
    k = common_prefix(cur, new)
    if cur[k:] == old[k:]:
        return True
    if not min(len(old), len(new)) <= len(cur) <= max(len(old), len(new)):
        return False
    for i in range(0, len(cur), SECTOR):
        c = cur[i:i + SECTOR]
        if c != new[i:i + len(c)] and c != old[i:i + len(c)] \
                and not (i >= len(old) and c == bytes(len(c))):
            return False
    return True
