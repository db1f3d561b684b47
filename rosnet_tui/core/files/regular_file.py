"""Reading a small file a user names or a state file, without hanging and without surprises.

Opening a FIFO for reading blocks until a writer comes; reading a device such as /dev/zero (a
link can point there) never ends. :func:`read_regular` opens without blocking, refuses anything
that is not a regular file before reading a byte, and refuses a file bigger than the caller's
bound. Its refusals are OSErrors (:class:`FileRefusedError`), so a caller that already says
"cannot read FILE: ..." for an OSError says it for these too.
"""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path


class FileRefusedError(OSError):
    """Not a regular file, or too big: nothing was read. ``str()`` says why in plain words;
    ``kind`` is ``"folder"``, ``"special"`` (FIFO, socket, device) or ``"big"``."""

    def __init__(self, path: Path | str, kind: str, why: str) -> None:
        super().__init__(errno.EINVAL, why, str(path))
        self.kind, self.why = kind, why

    def __str__(self) -> str:
        return f"{self.filename}: {self.why}"


def read_regular(path: Path | str, max_bytes: int, *, follow: bool = True) -> bytes:
    """The bytes of the regular file *path* (links followed unless not *follow*: then a link
    there is an OSError, ELOOP). FileNotFoundError when it is missing; FileRefusedError for a
    FIFO, a device, a socket or a folder, and for a file over *max_bytes* (also one that grows
    past it while being read); other OSErrors as they come."""
    flags = os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY | os.O_CLOEXEC
    fd = os.open(path, flags if follow else flags | os.O_NOFOLLOW)
    try:
        st = os.fstat(fd)
        if stat.S_ISDIR(st.st_mode):
            raise FileRefusedError(path, "folder", "is a folder, not a file")
        if not stat.S_ISREG(st.st_mode):
            raise FileRefusedError(path, "special", "is not a regular file (a FIFO, a socket or "
                                                    "a device?); nothing was read")
        if st.st_size > max_bytes:
            raise FileRefusedError(path, "big",
                                   f"is too big ({st.st_size} bytes; at most {max_bytes})")
        chunks, total = [], 0
        while True:
            chunk = os.read(fd, min(1 << 20, max_bytes + 1 - total))
            if not chunk:
                break
            chunks.append(chunk)
            total += len(chunk)
            if total > max_bytes:
                raise FileRefusedError(path, "big", f"is too big (over {max_bytes} bytes)")
        return b"".join(chunks)
    finally:
        os.close(fd)
