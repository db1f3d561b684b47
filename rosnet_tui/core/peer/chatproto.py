"""The peer's side of the Linux chats (linux.chat_out, linux.chat_in), stdlib only: run on a peer
by the round's peer agent (core/peer/agentproto.py), or alone as ``python3 -S`` (fed base64 on the
command line) where no agent runs. Python 3.8+ syntax, no imports from rosnet_tui.

    listen PORT TOKEN WAIT        listen on PORT (or a random port when taken, or when a run of
                                  rosnet-tui here holds its lock), say LISTENING, greet the one
                                  who connects with our chat line, print what it sends (FROM,
                                  GOT)
    connect NAME PORT T [TOKEN]   resolve NAME as this machine does (RESOLVED), connect to it
                                  (CONNECTED); with TOKEN, chat: read its greeting (HELLO), send
                                  our chat line, read its answer (ECHO)

Failures are lines too (RESOLVE-ERROR, CONNECT-ERROR, ERROR, TIMEOUT) with an exit status.
"""
# The peer's python3 may be 3.8: socket.timeout is not yet TimeoutError there.
# ruff: noqa: UP041

from __future__ import annotations

import os
import random
import select
import socket
import sys
import time

CHAT = "ROSNET-TUI CHAT"


def _line(c: socket.socket) -> str:
    b = b""
    while b"\n" not in b and len(b) < 512:
        x = c.recv(512)
        if not x:
            break
        b += x
    return b.decode("utf-8", "replace").strip()


def _port_lock(port: int):
    """This machine's lock of the test *port*, shared with every run of rosnet-tui here (see
    core/net/portshare.py): the socket, None when another run holds it, False where there are
    no abstract unix sockets."""
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        s.bind(f"\0rosnet-tui/test-port/{port}")
        s.listen(8)
    except OSError as e:
        s.close()
        return None if e.errno == 98 else False
    s.setblocking(False)
    return s


def _accept(srv: socket.socket, lock, wait: float, asking: list):
    """The one connection to *srv* within *wait* s (None: nobody came); meanwhile each run of
    rosnet-tui here that asks *lock* for the port is told how long we keep it at most (BUSY),
    and kept in *asking* (closed when we let the port go: its sign to try again)."""
    deadline = time.monotonic() + wait
    while True:
        left = deadline - time.monotonic()
        if left <= 0:
            return None
        ready = select.select([srv] + ([lock] if lock else []), [], [], left)[0]
        if srv in ready:
            return srv.accept()
        if lock not in ready:
            continue
        try:
            g = lock.accept()[0]
            g.sendall(f"BUSY {os.getpid()} {left + 7:.1f}\n".encode())
            asking.append(g)
        except OSError:     # it gave up already
            pass


def listen(port: int, token: str, wait: float) -> int:
    srv = None
    last = ""
    lock, test_port, asking = _port_lock(port), port, []
    for p in [port] * (lock is not None) + [random.randint(20000, 60000) for _ in range(5)]:
        s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("0.0.0.0", p))
            s.listen(4)
            srv, port = s, p
            break
        except Exception as e:  # noqa: BLE001 - said, then the next port
            last = str(e)
            s.close()
    if lock and (srv is None or port != test_port):
        lock.close()                    # the test port was not ours: the lock is not needed
        lock = None
    if srv is None:
        print("ERROR cannot listen: " + last)
        return 3
    print(f"LISTENING {port}", flush=True)
    try:
        return _chat(_accept(srv, lock, wait, asking), token)
    finally:
        srv.close()
        for x in [*asking, lock]:
            if x:
                x.close()


def _chat(got, token: str) -> int:
    if got is None:
        print("TIMEOUT nobody connected")
        return 4
    c, a = got
    c.settimeout(3)
    try:
        c.sendall(f"{CHAT} {token}\n".encode())
        print(f"FROM {a[0]}")
        print("GOT " + _line(c))
    except Exception as e:  # noqa: BLE001
        print(f"ERROR {e}")
        return 5
    finally:
        c.close()
    return 0


def connect(name: str, port: int, t: float, token: str = "") -> int:
    try:
        ip = socket.gethostbyname(name)
    except Exception as e:  # noqa: BLE001
        print(f"RESOLVE-ERROR {e}")
        return 2
    print(f"RESOLVED {ip}", flush=True)
    try:
        c = socket.create_connection((ip, port), timeout=t)
    except Exception as e:  # noqa: BLE001
        print(f"CONNECT-ERROR {e}")
        return 3
    if not token:
        c.close()
        print("CONNECTED")
        return 0
    c.settimeout(t)
    try:
        print("HELLO " + _line(c), flush=True)
        c.sendall(f"{CHAT} {token}\n".encode())
        print("ECHO " + _line(c))
    except Exception as e:  # noqa: BLE001
        print(f"ERROR {e}")
        return 4
    finally:
        c.close()
    return 0


def main(argv: list[str]) -> int:
    if argv[:1] == ["listen"] and len(argv) == 4:
        return listen(int(argv[1]), argv[2], float(argv[3]))
    if argv[:1] == ["connect"] and len(argv) in (4, 5):
        return connect(argv[1], int(argv[2]), float(argv[3]), *argv[4:])
    print("ERROR usage: listen PORT TOKEN WAIT | connect NAME PORT T [TOKEN]")
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
