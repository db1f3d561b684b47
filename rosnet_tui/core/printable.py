"""Text from outside (a file name in the shared folder, a record, a peer's answer) made safe to
show on a terminal: its control characters (C0, DEL, C1) become ``?``, so no escape sequence
read from a file reaches the technician's terminal (or a log read in one)."""

from __future__ import annotations

import re

_CONTROLS = re.compile(r"[\x00-\x1f\x7f-\x9f]")


def printable(text: object) -> str:
    """*text* as a string with every control character (tabs and newlines too) replaced by
    ``?``; None stays ``''``."""
    if text is None:
        return ""
    return _CONTROLS.sub("?", str(text))
