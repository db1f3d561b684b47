"""A command on a pseudo-terminal that answers its `[y/N]` prompts: how the tests type at a
confirmation the way a technician does (every writer asks only where there is a terminal)."""

from __future__ import annotations

import os
import pty
import select
import subprocess
import time
from pathlib import Path


def run_answering(argv: list[str], answers: list[str], *, env: dict[str, str], cwd: Path,
                  timeout: float = 30) -> tuple[int, str]:
    """Run *argv* on a pseudo-terminal and answer each '[y/N]' prompt in turn with *answers*
    (prompts past the last answer stay unanswered); (exit code, everything it printed). Bounded
    by *timeout*; the process is killed if it outlives it."""
    master, slave = pty.openpty()
    proc = subprocess.Popen(argv, stdin=slave, stdout=slave, stderr=slave, cwd=cwd, env=env,
                            start_new_session=True)
    os.close(slave)
    out, pending = b"", list(answers)
    deadline = time.monotonic() + timeout
    try:
        while time.monotonic() < deadline:
            ended = proc.poll() is not None     # before the look: what it wrote last is read
            if select.select([master], [], [], 0 if ended else 0.1)[0]:
                try:
                    chunk = os.read(master, 4096)
                except OSError:
                    chunk = b""
                if not chunk:
                    break
                out += chunk
                if pending and out.count(b"[y/N]") > len(answers) - len(pending):
                    os.write(master, pending.pop(0).encode() + b"\n")
            elif ended:
                break
        rc = proc.wait(timeout=max(0.1, deadline - time.monotonic()))
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=5)
        os.close(master)
    return rc, out.decode(errors="replace")
