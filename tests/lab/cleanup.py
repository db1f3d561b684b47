"""Tear-down that always happens: live-lab registry, atexit and signal hooks, stale-lab sweep.

Every lab of a run is named ``rnl-<pid>-<n>-`` (namespaces, /etc/netns entries, its temporary
folder ``/tmp/rnl-<pid>-<n>-*``). A crashed run (kill -9, power loss) leaves such names behind with
a dead pid; :func:`sweep_stale` removes them at the next start.
"""

from __future__ import annotations

import atexit
import os
import re
import shutil
import signal
import subprocess
import tempfile
import threading
from pathlib import Path
from typing import TYPE_CHECKING

from . import procs

if TYPE_CHECKING:
    from .lab import Lab

PREFIX_RE = re.compile(r"^rnl-(\d+)-(\d+)-")
ETC_NETNS = Path("/etc/netns")
RUN_NETNS = Path(procs.NETNS_DIR)

_live: set[Lab] = set()  # strong refs: a lab dropped without destroy() is still torn down
_lock = threading.RLock()  # re-entrant: the signal handler may run while it is held
_hooks_installed = False
_previous_handlers: dict[int, object] = {}


def register(lab: Lab) -> None:
    global _hooks_installed
    with _lock:
        _live.add(lab)
        if not _hooks_installed:
            _install_hooks()
            _hooks_installed = True


def unregister(lab: Lab) -> None:
    with _lock:
        _live.discard(lab)


def destroy_all() -> None:
    """Destroy every lab of this process that is still up."""
    with _lock:
        labs = list(_live)
    for lab in labs:
        try:
            lab.destroy()
        except Exception:  # keep going: the others must go too
            pass


def _install_hooks() -> None:
    atexit.register(destroy_all)
    if threading.current_thread() is not threading.main_thread():
        return
    for sig in (signal.SIGTERM, signal.SIGHUP):
        try:
            previous = signal.getsignal(sig)
            _previous_handlers[sig] = previous
            signal.signal(sig, _on_signal)
        except (ValueError, OSError):
            pass


def _on_signal(signum: int, frame) -> None:
    destroy_all()
    previous = _previous_handlers.get(signum)
    if callable(previous):
        previous(signum, frame)
        return
    if previous == signal.SIG_IGN:
        return
    signal.signal(signum, signal.SIG_DFL)
    os.kill(os.getpid(), signum)


def _pid_of(name: str) -> int | None:
    m = PREFIX_RE.match(name)
    return int(m.group(1)) if m else None


def _run_is_dead(pid: int) -> bool:
    return pid != os.getpid() and not procs.alive(pid)


def remove_netns(names: list[str]) -> None:
    """Kill every process in these namespaces, then delete them (missing ones are fine)."""
    inodes = [i for i in (procs.netns_inode(str(RUN_NETNS / n)) for n in names) if i]
    pids = procs.pids_in_netns(inodes)
    if pids:
        procs.signal_pids(pids, signal.SIGKILL)
        procs.wait_dead(pids, 2.0)
    if names:
        subprocess.run(["ip", "-force", "-batch", "-"], input="".join(f"netns del {n}\n" for n in names),
                       text=True, capture_output=True, timeout=20)
    for n in names:  # belt and braces: a name ip could not delete
        p = RUN_NETNS / n
        if p.exists():
            subprocess.run(["umount", "-l", str(p)], capture_output=True, timeout=10)
            try:
                p.unlink()
            except OSError:
                pass


def sweep_stale() -> list[str]:
    """Remove what crashed runs left behind (their pid is dead); return the names removed."""
    stale_ns = []
    if RUN_NETNS.is_dir():
        stale_ns = [n for n in os.listdir(RUN_NETNS)
                    if (pid := _pid_of(n)) is not None and _run_is_dead(pid)]
    removed = list(stale_ns)
    remove_netns(stale_ns)
    if ETC_NETNS.is_dir():
        for n in os.listdir(ETC_NETNS):
            pid = _pid_of(n)
            if pid is not None and _run_is_dead(pid):
                shutil.rmtree(ETC_NETNS / n, ignore_errors=True)
                removed.append(f"/etc/netns/{n}")
        _remove_if_empty(ETC_NETNS)
    tmp = Path(tempfile.gettempdir())
    for d in tmp.glob("rnl-*"):
        pid = _pid_of(d.name)
        if pid is not None and _run_is_dead(pid) and d.is_dir():
            shutil.rmtree(d, ignore_errors=True)
            removed.append(str(d))
    return removed


def _remove_if_empty(path: Path) -> None:
    try:
        path.rmdir()
    except OSError:
        pass


def any_lab_netns() -> bool:
    return RUN_NETNS.is_dir() and any(PREFIX_RE.match(n) for n in os.listdir(RUN_NETNS))
