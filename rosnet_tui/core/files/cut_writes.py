"""In-place writes cut short: where their journals are, found with a few stats.

A file that cannot be renamed over (a bind-mounted /etc/hosts in a container) is rewritten in
place, and an in-place rewrite cannot be atomic. So before it touches the file the writer
(:mod:`rosnet_tui.core.files.managed_write`) records its intent: a journal holding the old and the new
bytes and their digests, fsynced, renamed into place, its folder fsynced. The journal lies beside
the file (``.NAME.rosnet-tui.DEV-INODE.inplace``), or, when the writer may not write that folder,
in the ``inplace`` folder of its state dir. It is removed once the file holds the new bytes.

Every run of rosnet-tui looks for journals first (:func:`pending`, from the command line's
start-up), before anything reads a file, and completes what a killed run left half done. This
module is what that costs when nothing is pending: a few stats, no imports beyond ``os``.
"""

from __future__ import annotations

import os
from collections.abc import Iterable

# A journal: MAGIC, one line of JSON (path, dev, ino, lengths and sha256 of old and new), the
# old bytes, the new bytes.
MAGIC = b"rosnet-tui in-place journal 1\n"
SUFFIX = ".inplace"
# Where an in-place write journals when the target's folder may not be written (in a state dir).
INPLACE_DIR = "inplace"
_HEAD_MAX = 64 << 10


def journal_name(name: str, st: os.stat_result) -> str:
    """The journal's file name for the file *name* (its stat *st*: one journal per inode)."""
    return f".{name}.rosnet-tui.{st.st_dev:x}-{st.st_ino:x}{SUFFIX}"


def pending(files: Iterable[os.PathLike | str], state_dirs: Iterable[os.PathLike | str]
            ) -> list[tuple[str, str | None]]:
    """The in-place writes left unfinished: ``(file, state dir's journal folder or None)`` for
    each of *files* with a journal (beside it or in a state dir's folder), and for each journal
    in the folders of *state_dirs* (which names its file). Empty, at the cost of a few stats,
    when there is none. Files and folders that cannot be looked at are passed over."""
    folders = [os.path.join(os.fspath(d), INPLACE_DIR) for d in state_dirs]
    found: list[tuple[str, str | None]] = []
    for f in files:
        try:
            real = os.path.realpath(f)
            st = os.stat(real)
        except (OSError, ValueError):
            continue
        name = journal_name(os.path.basename(real), st)
        for folder in (os.path.dirname(real), *folders):
            if os.path.lexists(os.path.join(folder, name)):
                found.append((real, None if folder == os.path.dirname(real) else folder))
    for folder in folders:
        try:
            names = [n for n in os.listdir(folder) if n.endswith(SUFFIX)]
        except OSError:
            continue
        for n in names:
            target = journal_target(os.path.join(folder, n))
            if target is not None:
                found.append((target, folder))
    return list(dict.fromkeys(found))


def journal_target(journal: str) -> str | None:
    """The file a journal names in its head (None: not a journal, or not readable)."""
    from rosnet_tui.core.jsonsafe import loads_bounded

    try:
        fd = os.open(journal, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError:
        return None
    try:
        head = os.read(fd, _HEAD_MAX)
    except OSError:
        return None
    finally:
        os.close(fd)
    if not head.startswith(MAGIC):
        return None
    line = head[len(MAGIC):].split(b"\n", 1)[0]
    try:
        path = loads_bounded(line.decode("utf-8")).get("path")
    except (ValueError, AttributeError):   # JsonInputError and UnicodeDecodeError included
        return None
    return path if isinstance(path, str) and os.path.isabs(path) else None
