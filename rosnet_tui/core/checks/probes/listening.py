"""Who listens on a TCP port of this machine: a service of the user's (a Zenoh router, sshd,
roscore), or a listener of rosnet-tui's own, which stands in for the service during a round and
must never be taken for it.

The look (psutil, blocking: call these in a thread) and the round's listeners run at once: a
check's stand-in may open or close while another check looks. So :func:`services_listening`
asks the pool whether rosnet-tui has the port both before and after the look: a stand-in alive at
any moment of the look is seen by one of the two questions (a listener's lock is held from before
it binds until after it closes, see :mod:`rosnet_tui.core.net.listener`).
"""

from __future__ import annotations

from rosnet_tui.core.addresses import is_loopback
from rosnet_tui.core.net.listener import ListenerPool


def _listening(port: int) -> list[tuple[str, int | None]]:
    """(address, pid) of each TCP listener on *port* (pid None: another user's); none seen when
    the kernel's table cannot be read."""
    import psutil  # noqa: PLC0415

    try:
        conns = psutil.net_connections(kind="tcp")
    except (psutil.AccessDenied, OSError):
        return []
    return [(c.laddr.ip, c.pid) for c in conns
            if c.status == psutil.CONN_LISTEN and c.laddr and c.laddr.port == port]


def who_listens(port: int) -> tuple[int | None, str | None, bool]:
    """(pid, process name, found) of a TCP listener on *port* (pid None: another user's)."""
    import psutil  # noqa: PLC0415

    found = _listening(port)
    if not found:
        return None, None, False
    pid = found[0][1]
    if pid is None:
        return None, None, True
    try:
        p = psutil.Process(pid)
        name = " ".join(p.cmdline()[:3]) or p.name()
    except (psutil.Error, OSError):
        name = None
    return pid, name, True


def services_listening(port: int, pool: ListenerPool | None = None, *,
                       reachable: bool = False) -> list[str]:
    """The addresses on which something other than rosnet-tui listens on TCP *port* here, sorted
    (*reachable*: loopback left out). With *pool* (the round's listeners), a listener of
    rosnet-tui's, this round's or another run's, is nobody's service: the answer is then []."""
    if pool is not None and pool.rosnet_listens(port):
        return []
    addrs = sorted({a for a, _pid in _listening(port)
                    if not (reachable and is_loopback(a))})
    if addrs and pool is not None and pool.rosnet_listens(port):   # a stand-in came meanwhile
        return []
    return addrs
