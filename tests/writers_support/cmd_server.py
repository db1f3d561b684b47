"""A command server for the writers' crash tests (issue 29 section 5).

Started by :class:`tests.writers_support.bench.HostsBench` inside a private mount namespace where
``/etc`` is an overlay (its changes land in the test's folder) and ``/etc/hosts`` is a bind mount
of a file in the test's folder: rename over it fails, so rosnet-tui takes the in-place path,
as in a container. The server imports rosnet-tui once; each request runs the real command line
(``rosnet_tui.cli.main``) in a fresh forked process, so a hundred commands cost seconds, not
minutes. A request can kill its process (SIGKILL, nothing after it runs):

- ``["timer", S]``: S seconds after the command starts (a random moment);
- ``["mark", N, S]``: S seconds after its N-th write of a file began (random, near the writes);
- ``["cut", F]``: in the middle of its rewrite of /etc/hosts, after the first fraction F of the
  new bytes went in (a kill inside the one write call);
- ``["truncate"]``: at the writer's own crash point between the rewrite and the truncation.

Requests and answers are JSON lines on stdin/stdout. Standard library and rosnet_tui only.
"""

from __future__ import annotations

import json
import os
import signal
import sys
import threading
import time

HOSTS = "/etc/hosts"


def _die() -> None:
    os.kill(os.getpid(), signal.SIGKILL)


def _arm(crash: list | None) -> None:
    from rosnet_tui.core.files import managed_write as mw

    if not crash:
        return
    kind = crash[0]
    if kind == "timer":
        t = threading.Timer(float(crash[1]), _die)
        t.daemon = True
        t.start()
    elif kind == "truncate":
        mw._before_truncate = _die
    elif kind in ("mark", "cut"):
        real = mw.write_all
        count = [0]

        def is_hosts(fd: int) -> bool:
            a, b = os.fstat(fd), os.stat(HOSTS)
            return (a.st_dev, a.st_ino) == (b.st_dev, b.st_ino)

        def hooked(fd: int, data: bytes) -> None:
            if kind == "mark":
                count[0] += 1
                if count[0] == int(crash[1]):
                    t = threading.Timer(float(crash[2]), _die)
                    t.daemon = True
                    t.start()
            elif is_hosts(fd):
                cut = int(len(data) * float(crash[1]))
                real(fd, data[:cut])
                _die()
            real(fd, data)

        mw.write_all = hooked
    else:
        raise ValueError(f"unknown crash {crash!r}")


def _child(req: dict) -> None:
    from rosnet_tui.cli import main

    rc = 70
    try:
        null = os.open(os.devnull, os.O_RDONLY)
        os.dup2(null, 0)
        for fd, name in ((1, "out"), (2, "err")):
            f = os.open(req[name], os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
            os.dup2(f, fd)
            os.close(f)
        os.environ.update(req.get("env") or {})
        uid = int(req.get("uid") or 0)
        if uid:
            os.setgroups([])
            os.setgid(uid)
            os.setuid(uid)
        _arm(req.get("crash"))
        try:
            rc = int(main(list(req["argv"])))
        except SystemExit as exc:
            rc = exc.code if isinstance(exc.code, int) else 1
    except BaseException as exc:  # noqa: BLE001 - said on stderr, exit 70
        print(f"cmd_server child: {type(exc).__name__}: {exc}", file=sys.stderr)
    finally:
        for f in (sys.stdout, sys.stderr):
            try:
                f.flush()
            except Exception:  # noqa: BLE001
                pass
        os._exit(rc)


def _wait(pid: int, limit_s: float) -> int:
    deadline = time.monotonic() + limit_s
    while True:
        got, status = os.waitpid(pid, os.WNOHANG)
        if got:
            return status
        if time.monotonic() > deadline:
            os.kill(pid, signal.SIGKILL)
            return os.waitpid(pid, 0)[1]
        time.sleep(0.002)


def serve() -> None:
    # What the commands import, loaded before any fork (and before a child drops to a user
    # who may not read the installed packages).
    import encodings.idna  # noqa: F401 - name resolution in a child that dropped to a user

    import rosnet_tui.cli.check
    import rosnet_tui.cli.hosts
    import rosnet_tui.cli.undo  # noqa: F401
    from rosnet_tui.core.checks import load_builtin_checks
    from rosnet_tui.core.checks.runner import select
    from rosnet_tui.core.files import undo_journal as uj

    load_builtin_checks()
    select(steps=["linux"])
    uj.JOURNAL_KEEP = 3        # the 2 MB backups of old applies are not kept
    print(json.dumps({"ready": os.getpid()}), flush=True)
    for line in sys.stdin:
        req = json.loads(line)
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:
            _child(req)
        status = _wait(pid, float(req.get("limit_s", 60)))
        killed = os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL
        rc = os.WEXITSTATUS(status) if os.WIFEXITED(status) else -os.WTERMSIG(status)
        print(json.dumps({"rc": rc, "killed": killed}), flush=True)


if __name__ == "__main__":
    serve()
