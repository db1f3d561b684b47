"""Run a terminal program under a pseudo-terminal and watch what it writes, with timestamps.

Pure Python: ``os.openpty`` + ``subprocess``, the window size set with ``TIOCSWINSZ``, the child
made a session leader with the pty as its controlling terminal (so it gets SIGWINCH like in a real
terminal), ``select`` with timeouts for every read. Nothing here waits without a bound, and
:meth:`PtyProcess.close` always kills the child's whole process group.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import re
import select
import signal
import struct
import subprocess
import termios
import time
from collections.abc import Callable
from dataclasses import dataclass

# Escape sequences: CSI (cursor moves, colours, modes), OSC (titles, clipboard), DCS/APC strings,
# charset selection and the other two-byte escapes. What is left is the text a person would see.
_ANSI = re.compile(
    r"\x1b\[[0-?]*[ -/]*[@-~]"          # CSI ... final byte
    r"|\x1b\][^\x07\x1b]*(?:\x07|\x1b\\)"  # OSC ... BEL or ST
    r"|\x1b[P_^X][^\x1b]*\x1b\\"        # DCS / APC / PM / SOS ... ST
    r"|\x1b[()*+][0-9A-Za-z]"           # charset designation
    r"|\x1b[@-Z\\-_=>78]"               # other two-byte escapes
)


def strip_ansi(data: bytes | str) -> str:
    """The visible characters of terminal output, escape sequences removed."""
    text = data.decode("utf-8", "replace") if isinstance(data, bytes) else data
    return _ANSI.sub("", text)


def _child_setup() -> None:  # runs in the child between fork and exec
    os.setsid()
    fcntl.ioctl(0, termios.TIOCSCTTY, 0)


@dataclass
class Chunk:
    t: float       # time.monotonic() when it was read
    data: bytes


class PtyProcess:
    """A program under a pty of *cols* x *rows*; everything it writes is kept with read times."""

    def __init__(self, argv: list[str], env: dict[str, str], *, cols: int = 80, rows: int = 24,
                 cwd: str | None = None, term: str = "xterm-256color",
                 no_color: bool = False) -> None:
        env = dict(env)
        env.update(TERM=term, COLUMNS=str(cols), LINES=str(rows))
        env.pop("NO_COLOR", None)
        env.pop("COLORTERM", None)
        if no_color:
            env["NO_COLOR"] = "1"
        master, slave = os.openpty()
        fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", rows, cols, 0, 0))
        self.chunks: list[Chunk] = []
        self.master = master
        self.t_start = time.monotonic()
        try:
            self.proc = subprocess.Popen(argv, stdin=slave, stdout=slave, stderr=slave, env=env,
                                         cwd=cwd, preexec_fn=_child_setup, close_fds=True)
        except BaseException:
            os.close(master)
            os.close(slave)
            raise
        os.close(slave)
        self.eof = False

    # ------------------------------------------------------------------ reading
    def pump(self, timeout: float) -> bool:
        """Read what is available within *timeout* seconds; True if anything came."""
        if self.eof:
            time.sleep(max(0.0, timeout))
            return False
        r, _, _ = select.select([self.master], [], [], max(0.0, timeout))
        if not r:
            return False
        try:
            data = os.read(self.master, 65536)
        except OSError:  # EIO: the child closed the terminal (it exited)
            data = b""
        if not data:
            self.eof = True
            return False
        self.chunks.append(Chunk(time.monotonic(), data))
        return True

    def drain(self, seconds: float) -> None:
        """Keep reading for *seconds* (the child never blocks on a full pty buffer)."""
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0:
            self.pump(left)

    @property
    def mark(self) -> int:
        """A position in the output, for :meth:`bytes_since` and :meth:`text_since`."""
        return len(self.chunks)

    def bytes_since(self, mark: int = 0, until: float | None = None) -> int:
        return sum(len(c.data) for c in self.chunks[mark:] if until is None or c.t <= until)

    def raw_since(self, mark: int = 0) -> bytes:
        return b"".join(c.data for c in self.chunks[mark:])

    def text_since(self, mark: int = 0) -> str:
        return strip_ansi(self.raw_since(mark))

    def wait_for(self, predicate: Callable[[str], bool], timeout: float, mark: int = 0
                 ) -> float | None:
        """Read until predicate(visible text since *mark*) holds: the read time of the chunk that
        made it true, or None on timeout / exit."""
        end = time.monotonic() + timeout
        text = ""
        scanned = mark
        while True:
            # Decode incrementally: escape sequences never span our chunks often, but the text is
            # rebuilt from the raw bytes when a new chunk lands, so a split is handled.
            if len(self.chunks) > scanned:
                text = self.text_since(mark)
                scanned = len(self.chunks)
                if predicate(text):
                    return self.chunks[-1].t
            left = end - time.monotonic()
            if left <= 0 or self.eof:
                return None
            self.pump(min(left, 0.05))

    def wait_text(self, needle: str, timeout: float, mark: int = 0) -> float | None:
        return self.wait_for(lambda t: needle in t, timeout, mark)

    def wait_quiet(self, quiet: float, timeout: float) -> tuple[float, bool]:
        """Read until nothing came for *quiet* seconds (or *timeout* passed): (time of the last
        byte read, or now if none; whether it did go quiet)."""
        end = time.monotonic() + timeout
        last = self.chunks[-1].t if self.chunks else time.monotonic()
        while True:
            now = time.monotonic()
            if now - last >= quiet:
                return last, True
            if now >= end or self.eof:
                return last, self.eof
            if self.pump(min(quiet - (now - last), end - now)):
                last = self.chunks[-1].t

    # ------------------------------------------------------------------ writing
    def send(self, data: bytes | str) -> float:
        """Type *data*; returns the time it was written."""
        if isinstance(data, str):
            data = data.encode()
        t = time.monotonic()
        os.write(self.master, data)
        return t

    def resize(self, cols: int, rows: int) -> None:
        fcntl.ioctl(self.master, termios.TIOCSWINSZ, struct.pack("HHHH", rows, cols, 0, 0))

    # ------------------------------------------------------------------ the process
    @property
    def pid(self) -> int:
        return self.proc.pid

    def alive(self) -> bool:
        return self.proc.poll() is None

    def status_kb(self, field: str) -> int | None:
        """A kB field of /proc/PID/status (VmHWM: peak resident set size; VmRSS: now)."""
        try:
            with open(f"/proc/{self.pid}/status", encoding="ascii") as f:
                for line in f:
                    if line.startswith(field + ":"):
                        return int(line.split()[1])
        except (OSError, ValueError, IndexError):
            return None
        return None

    def close(self, quit_keys: bytes | None = None, grace: float = 1.0) -> int | None:
        """Stop the program: *quit_keys* first if given, then SIGTERM, then SIGKILL, each to its
        process group; the pty is drained meanwhile and closed at the end. Returns the exit code."""
        try:
            if quit_keys and self.alive():
                with contextlib.suppress(OSError):
                    self.send(quit_keys)
                end = time.monotonic() + grace
                while self.alive() and time.monotonic() < end:
                    self.pump(0.02)
            for sig in (signal.SIGTERM, signal.SIGKILL):
                if not self.alive():
                    break
                with contextlib.suppress(ProcessLookupError, PermissionError):
                    os.killpg(self.pid, sig)
                end = time.monotonic() + grace
                while self.alive() and time.monotonic() < end:
                    self.pump(0.02)
            # Whatever the group left behind (a grandchild that ignored the signal).
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(self.pid, signal.SIGKILL)
            with contextlib.suppress(subprocess.TimeoutExpired):
                self.proc.wait(timeout=2)
            return self.proc.returncode
        finally:
            with contextlib.suppress(OSError):
                os.close(self.master)

    def __enter__(self) -> PtyProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
