"""Our marked block in a text file: finding, extracting and composing it, byte for byte.

Every other byte of the file (line endings, tabs, comments, a missing final newline, bytes that
are not UTF-8) is kept. Also the errors every writer of ours raises.
"""

from __future__ import annotations

import hashlib
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

BEGIN_MARKER = "# BEGIN rosnet-tui"
END_MARKER = "# END rosnet-tui"
ABSENT = "absent"  # the digest of a file that does not exist

_MARKER_RE = re.compile(r"^[ \t]*#[ \t]*(BEGIN|END)[ \t]+rosnet-tui(?:[ \t]|$)")


# --------------------------------------------------------------------------- errors
class ManagedFileError(Exception):
    """A file we will not or could not write; the message says why, in plain words."""


class DamagedBlockError(ManagedFileError):
    """The file has a BEGIN without END (or the reverse, or two blocks): we do not guess."""


class StalePreviewError(ManagedFileError):
    """The file changed between the preview and the apply."""


class PermissionNeededError(ManagedFileError):
    """This user may not write the file (use the sudo command from rosnet_tui.core.files.privilege)."""

    def __init__(self, message: str, paths: Sequence[Path] = ()) -> None:
        super().__init__(message)
        self.paths = list(paths)


class NothingToUndoError(ManagedFileError):
    """The journal holds no apply that has not been undone yet."""


class UndoConflictError(ManagedFileError):
    """A file was changed by someone else after our apply; undoing would lose that change."""


# --------------------------------------------------------------------------- text helpers
def decode(data: bytes) -> str:
    """Bytes to text that encodes back to the very same bytes (undecodable bytes survive)."""
    return data.decode("utf-8", "surrogateescape")


def encode(text: str) -> bytes:
    return text.encode("utf-8", "surrogateescape")


def file_digest(data: bytes | None) -> str:
    """The digest a preview carries: sha256 of the bytes, or ``absent`` for a missing file."""
    return ABSENT if data is None else hashlib.sha256(data).hexdigest()


def split_lines(text: str) -> list[str]:
    """Lines with their terminators; only ``\\n`` ends a line (a ``\\r`` before it stays with it)."""
    if not text:
        return []
    lines = text.split("\n")
    out = [line + "\n" for line in lines[:-1]]
    if lines[-1]:
        out.append(lines[-1])
    return out


def line_content(line: str) -> str:
    """A line without its terminator (``\\n`` or ``\\r\\n``)."""
    if line.endswith("\n"):
        line = line[:-1]
        if line.endswith("\r"):
            line = line[:-1]
    return line


def detect_newline(text: str | None) -> str:
    """``\\r\\n`` when most lines of *text* end that way, else ``\\n``."""
    if not text:
        return "\n"
    crlf = text.count("\r\n")
    return "\r\n" if crlf and crlf * 2 >= text.count("\n") else "\n"


def find_block(lines: Sequence[str]) -> tuple[int, int] | None:
    """Indexes of our BEGIN and END lines, or None when the file has no block.

    Raises DamagedBlockError for a BEGIN without END, an END without BEGIN, or a second block.
    """
    begin = end = None
    for i, line in enumerate(lines):
        m = _MARKER_RE.match(line_content(line))
        if not m:
            continue
        if m.group(1) == "BEGIN":
            if begin is not None:
                raise DamagedBlockError(
                    f"line {i + 1} starts a second rosnet-tui block (the first starts at line "
                    f"{begin + 1}); remove one of them by hand, then try again")
            begin = i
        else:
            if begin is None:
                raise DamagedBlockError(
                    f"line {i + 1} ends a rosnet-tui block that never began; remove the stray "
                    f"'{END_MARKER}' line by hand, then try again")
            if end is not None:
                raise DamagedBlockError(
                    f"line {i + 1} ends the rosnet-tui block a second time; remove the stray "
                    f"'{END_MARKER}' line by hand, then try again")
            end = i
    if begin is None:
        return None
    if end is None:
        raise DamagedBlockError(
            f"the rosnet-tui block that starts at line {begin + 1} has no '{END_MARKER}' line; "
            "fix the file by hand (add the END line or remove the block), then try again")
    return begin, end


def extract_block(text: str | None) -> list[str] | None:
    """The lines between our markers (no terminators), or None when there is no block."""
    lines = split_lines(text or "")
    span = find_block(lines)
    if span is None:
        return None
    return [line_content(x) for x in lines[span[0] + 1:span[1]]]


def compose_block(text: str | None, body: Sequence[str], *, position: str = "end",
                  replace_lines: Mapping[int, str] | None = None) -> str:
    """*text* with our block set to *body* (lines without terminators); nothing else changes.

    An existing block is replaced where it stands, in its own line endings. A new block goes at
    the top (``position="top"``: first match wins, as in /etc/hosts) or at the end (``"end"``: last
    assignment wins, as in ~/.bashrc), in the file's dominant line ending. *replace_lines* maps
    0-based indexes of lines outside the block to new content (terminator kept): the only way a
    line outside our block changes, used to comment lines out when the user agreed.
    """
    for line in body:
        if "\n" in line or "\r" in line or _MARKER_RE.match(line):
            raise ValueError(f"a block line may not hold a newline or a marker: {line!r}")
    text = text or ""
    lines = split_lines(text)
    span = find_block(lines)
    replace_lines = dict(replace_lines or {})
    for i, new in replace_lines.items():
        if not 0 <= i < len(lines) or (span and span[0] <= i <= span[1]):
            raise ValueError(f"line index {i} is not a line outside the block")
        if "\n" in new or "\r" in new:
            raise ValueError("a replacement line may not hold a newline")
        old = lines[i]
        lines[i] = new + old[len(line_content(old)):]
    if span is not None:
        begin_line, end_line = lines[span[0]], lines[span[1]]
        nl = begin_line[len(line_content(begin_line)):] or detect_newline(text)
        block = [x + nl for x in (BEGIN_MARKER, *body, END_MARKER)]
        if not end_line.endswith("\n"):
            block[-1] = END_MARKER  # the block was the end of a file without a final newline
        return "".join(lines[:span[0]] + block + lines[span[1] + 1:])
    nl = detect_newline(text)
    block = [x + nl for x in (BEGIN_MARKER, *body, END_MARKER)]
    if position == "top":
        return "".join(block + lines)
    if position != "end":
        raise ValueError(f"position must be 'top' or 'end', not {position!r}")
    if lines and not lines[-1].endswith("\n"):
        block[0] = nl + block[0]
    return "".join(lines + block)


def remove_block(text: str | None) -> str:
    """*text* without our block (its marker lines and what is between them); every other line
    as it was, byte for byte. Unchanged when there is no block."""
    text = text or ""
    lines = split_lines(text)
    span = find_block(lines)
    if span is None:
        return text
    return "".join(lines[:span[0]] + lines[span[1] + 1:])


@dataclass(frozen=True)
class LineChange:
    """A line outside our block that we offer to change (comment out), and why."""

    index: int      # 0-based line index in the file
    old: str        # the line as it is (no terminator)
    new: str        # what it would become (no terminator)
    why: str        # the reason, shown to the user before asking

    @property
    def lineno(self) -> int:
        return self.index + 1
