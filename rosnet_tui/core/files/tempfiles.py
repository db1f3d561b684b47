"""Temp files of our atomic writers, and removing the ones a killed writer left behind.

Every file we replace (managed files, state files, the settings file) goes through one writer,
:func:`rosnet_tui.core.files.managed_write.atomic_write`, which writes a temp file beside its target,
named with its process id, and holds an advisory lock on it until it is renamed into place. A temp file is left over when its writer is gone (or it is older than
STALE_S) and nobody holds its lock: the next writer of the same folder removes it. Standard
library only (the writers' crash tests run it with ``python -S``).
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import re
import stat
import time
from pathlib import Path

STALE_S = 60.0

# .NAME.rosnet-tui.PID.HEX.tmp    the one writer's temp file (managed_write.atomic_write)
MANAGED_TMP = re.compile(r"^\.(?P<name>.+)\.rosnet-tui\.(?P<pid>\d+)\.[0-9a-f]+\.tmp$")
# Left by earlier versions, which named temp files differently; still swept. PRIVATE_TMP also
# matches MANAGED_TMP names (NAME then ends in ".rosnet-tui").
# .NAME.PID.HEX.tmp               journal entries and backups in the state dir
PRIVATE_TMP = re.compile(r"^\.(?P<name>.+)\.(?P<pid>\d+)\.[0-9a-f]+\.tmp$")
# .NAME.tmp-PID-HEX               settings, status and other small files
ATOMIC_TMP = re.compile(r"^\.(?P<name>.+)\.tmp-(?P<pid>\d+)-[0-9a-f]+$")


def pid_alive(pid: int) -> bool:
    return process_start(pid) is not None


def process_start(pid: int) -> str | None:
    """When process *pid* started (clock ticks after boot), or None when there is none or it
    has died (a zombie): a pid that has come to name another process has another start."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii", errors="replace") as f:
            fields = f.read().rsplit(")", 1)[-1].split()
    except OSError:
        return None
    if len(fields) < 20 or fields[0] in ("Z", "X"):
        return None
    return fields[19]


def lock_free(path: str) -> bool:
    """Whether nobody holds a writer's lock on *path*."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_NOCTTY)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        return True
    except OSError:
        return False
    finally:
        os.close(fd)


def sweep(folder: Path, pattern: re.Pattern[str], name: str | None = None) -> list[str]:
    """Remove the left-over temp files in *folder* matching *pattern* (of target *name* only,
    when given); the names removed."""
    removed: list[str] = []
    try:
        with os.scandir(folder) as it:
            entries = list(it)
    except OSError:
        return removed
    now = time.time()
    for e in entries:
        m = pattern.match(e.name)
        if not m or (name is not None and m.group("name") != name):
            continue
        try:
            st = e.stat(follow_symlinks=False)
        except OSError:
            continue
        if not stat.S_ISREG(st.st_mode):
            continue
        gone = not pid_alive(int(m.group("pid"))) or now - st.st_mtime > STALE_S
        if gone and lock_free(e.path):
            with contextlib.suppress(OSError):
                os.unlink(e.path)
                removed.append(e.name)
    return removed
