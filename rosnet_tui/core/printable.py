"""Text from outside (a file name in the shared folder, a record, a peer's answer) made safe to
show on a terminal: its control characters (C0, DEL, C1) and every other character Python does
not call printable (format characters such as bidi overrides, line separators) become ``?``, so
no escape sequence read from a file, a record or a modem reaches the technician's terminal (or a
log read in one). The one rule for every text shown from outside."""

from __future__ import annotations


def printable(text: object, limit: int | None = None) -> str:
    """*text* as a string (at most *limit* characters of it) with every control character (tabs
    and newlines too) replaced by ``?``; None stays ``''``."""
    if text is None:
        return ""
    s = str(text) if limit is None else str(text)[:limit]
    return s if s.isprintable() else "".join(c if c.isprintable() else "?" for c in s)
