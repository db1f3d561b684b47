"""Process and namespace plumbing for the lab: liveness, descendants, killing, per-thread setns.

Liveness is read from /proc/PID/stat (a zombie counts as dead: finished processes whose parent
does not reap them linger as zombies here, and ``kill -0`` would call them alive).
"""

from __future__ import annotations

import ctypes
import os
import signal
import subprocess
import threading
import time
from collections.abc import Callable, Iterable
from typing import Any, TypeVar

T = TypeVar("T")
CLONE_NEWNET = 0x40000000
NETNS_DIR = "/run/netns"

_libc = ctypes.CDLL(None, use_errno=True)


def proc_state(pid: int) -> str | None:
    """The one-letter state of *pid* ('R', 'S', 'Z', ...), or None when there is no such process."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            data = f.read()
    except (FileNotFoundError, ProcessLookupError, PermissionError, OSError):
        return None
    # "pid (comm) S ppid ..." - comm may contain spaces and parentheses.
    rest = data[data.rfind(b")") + 2:]
    return rest[:1].decode() or None


def alive(pid: int) -> bool:
    state = proc_state(pid)
    return state is not None and state not in ("Z", "X")


def _ppid(pid: int) -> int | None:
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            data = f.read()
        return int(data[data.rfind(b")") + 2:].split()[1])
    except (OSError, ValueError, IndexError):
        return None


def all_pids() -> list[int]:
    return [int(n) for n in os.listdir("/proc") if n.isdigit()]


def descendants(pid: int) -> list[int]:
    """Every live descendant of *pid* (children first found by a scan of /proc)."""
    children: dict[int, list[int]] = {}
    for p in all_pids():
        pp = _ppid(p)
        if pp is not None:
            children.setdefault(pp, []).append(p)
    out, todo = [], [pid]
    while todo:
        for c in children.get(todo.pop(), []):
            if c not in out:
                out.append(c)
                todo.append(c)
    return out


def netns_inode(path: str) -> tuple[int, int] | None:
    try:
        st = os.stat(path)
    except OSError:
        return None
    return st.st_dev, st.st_ino


def pids_in_netns(inodes: Iterable[tuple[int, int]]) -> list[int]:
    """Live processes whose network namespace is one of *inodes* ((dev, ino) of a netns file)."""
    wanted = set(inodes)
    if not wanted:
        return []
    me = os.getpid()
    out = []
    for p in all_pids():
        if p == me:
            continue
        ino = netns_inode(f"/proc/{p}/ns/net")
        if ino in wanted and alive(p):
            out.append(p)
    return out


def signal_pids(pids: Iterable[int], sig: int) -> None:
    for p in pids:
        try:
            os.kill(p, sig)
        except (ProcessLookupError, PermissionError):
            pass


def signal_group(pgid: int, sig: int) -> None:
    try:
        os.killpg(pgid, sig)
    except (ProcessLookupError, PermissionError):
        pass


def wait_dead(pids: Iterable[int], timeout: float) -> list[int]:
    """Wait (bounded) until every pid is dead; return those still alive."""
    pids = list(pids)
    deadline = time.monotonic() + timeout
    while True:
        left = [p for p in pids if alive(p)]
        if not left or time.monotonic() >= deadline:
            return left
        time.sleep(0.02)


def stop(proc: subprocess.Popen, grace: float) -> None:
    """Stop a child: SIGTERM, up to *grace* s to exit, then SIGKILL; reaped either way."""
    if proc.poll() is not None:
        return
    proc.terminate()
    try:
        proc.wait(grace)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(5)


def kill_tree(pid: int, *, grace: float = 1.0) -> None:
    """Stop *pid*, its process group and all its descendants: TERM, bounded wait, then KILL."""
    family = [pid, *descendants(pid)]
    signal_group(pid, signal.SIGTERM)
    signal_pids(family, signal.SIGTERM)
    left = wait_dead(family, grace)
    if left:
        signal_group(pid, signal.SIGKILL)
        signal_pids(left + descendants(pid), signal.SIGKILL)
        wait_dead(left, 2.0)


def call_in_netns(netns_path: str, fn: Callable[..., T], *args: Any, timeout: float = 30.0,
                  **kwargs: Any) -> T:
    """Run ``fn(*args, **kwargs)`` in a fresh thread that has joined the network namespace at
    *netns_path*; return its result (or raise its exception).

    Only the network namespace changes: name resolution still reads this machine's files, so use
    addresses, not the lab's names. Sockets created inside stay in that namespace afterwards.
    """
    box: dict[str, Any] = {}

    def target() -> None:
        try:
            fd = os.open(netns_path, os.O_RDONLY | os.O_CLOEXEC)
            try:
                if _libc.setns(fd, CLONE_NEWNET) != 0:
                    err = ctypes.get_errno()
                    raise OSError(err, f"setns({netns_path}): {os.strerror(err)}")
            finally:
                os.close(fd)
            box["result"] = fn(*args, **kwargs)
        except BaseException as exc:  # handed back to the caller
            box["error"] = exc

    t = threading.Thread(target=target, name=f"netns:{os.path.basename(netns_path)}", daemon=True)
    t.start()
    t.join(timeout)
    if t.is_alive():
        raise TimeoutError(f"call in {netns_path} did not finish within {timeout} s")
    if "error" in box:
        raise box["error"]
    return box.get("result")  # type: ignore[return-value]


def listening_ports(proto: str = "tcp") -> set[int]:
    """Ports with a listening TCP socket (or bound UDP socket) in the calling thread's netns."""
    states = {"tcp": "0A", "udp": "07"}[proto]
    ports: set[int] = set()
    for suffix in ("", "6"):
        try:
            with open(f"/proc/thread-self/net/{proto}{suffix}") as f:
                next(f, None)
                for line in f:
                    fields = line.split()
                    if len(fields) > 3 and fields[3] == states:
                        ports.add(int(fields[1].rsplit(":", 1)[1], 16))
        except FileNotFoundError:
            continue
    return ports
