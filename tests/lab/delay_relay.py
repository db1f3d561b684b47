"""A TCP relay that holds every chunk it reads for DELAY ms before passing it on: the lab's delay
on a path (this kernel has no netem). Run in a namespace on the path to a port:

    python3 delay_relay.py LISTEN_HOST LISTEN_PORT TARGET_HOST TARGET_PORT DELAY_MS MAX_S [MAX_CONN]

TARGET_HOST ``ORIGINAL``: every connection goes on to where it was going before an iptables
REDIRECT brought it here (SO_ORIGINAL_DST), TARGET_PORT then being ``-`` or an address map
``FROM=TO[,FROM=TO]`` (a modem's own public address to the computer it forwards to): one hop
carries every TCP connection between two sites, whatever their ports.

It prints ``RELAY READY`` once listening. Bounded: at most HELD bytes held per direction (reading
waits while that much is held), at most MAX_CONN connections over its life, and it ends after
MAX_S s. Stdlib only."""

from __future__ import annotations

import collections
import socket
import struct
import sys
import threading
import time

MAX_CONN = 16
HELD = 4 << 20
CHUNK = 65536
SO_ORIGINAL_DST = 80     # linux/netfilter_ipv4.h


def _original(client: socket.socket, remap: dict[str, str]) -> tuple[str, int]:
    """Where a REDIRECTed *client* was going (its address mapped by *remap*)."""
    raw = client.getsockopt(socket.SOL_IP, SO_ORIGINAL_DST, 16)
    port, packed = struct.unpack("!H", raw[2:4])[0], raw[4:8]
    host = socket.inet_ntoa(packed)
    return remap.get(host, host), port


def _close(*socks: socket.socket) -> None:
    for s in socks:
        try:
            s.close()
        except OSError:
            pass


def _one_way(src: socket.socket, dst: socket.socket, delay: float) -> None:
    """Read *src*, hold each chunk *delay* s, write it to *dst*; an end or error closes both."""
    held: collections.deque[tuple[float, bytes]] = collections.deque()
    cv = threading.Condition()
    state = {"bytes": 0, "eof": False, "dead": False}

    def reader() -> None:
        try:
            while True:
                data = src.recv(CHUNK)
                with cv:
                    if not data:
                        state["eof"] = True
                        cv.notify_all()
                        return
                    while state["bytes"] > HELD and not state["dead"]:
                        cv.wait(0.1)
                    held.append((time.monotonic() + delay, data))
                    state["bytes"] += len(data)
                    cv.notify_all()
        except OSError:
            with cv:
                state["eof"] = True
                cv.notify_all()

    def writer() -> None:
        try:
            while True:
                with cv:
                    while not held and not state["eof"]:
                        cv.wait(0.5)
                    if not held:
                        dst.shutdown(socket.SHUT_WR)
                        return
                    due, data = held[0]
                    wait = due - time.monotonic()
                    if wait > 0:
                        cv.wait(wait)
                        continue
                    held.popleft()
                    state["bytes"] -= len(data)
                    cv.notify_all()
                dst.sendall(data)
        except OSError:
            with cv:
                state["dead"] = True
                cv.notify_all()
            _close(src, dst)

    threading.Thread(target=reader, daemon=True).start()
    threading.Thread(target=writer, daemon=True).start()


def main(argv: list[str]) -> int:
    host, port, to_host, to_port, delay_ms, max_s = argv[:6]
    max_conn = int(argv[6]) if len(argv) > 6 else MAX_CONN
    remap = dict(pair.split("=", 1) for pair in to_port.split(",") if "=" in pair) \
        if to_host == "ORIGINAL" else {}
    delay = float(delay_ms) / 1000.0
    srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    srv.bind((host, int(port)))
    srv.listen(min(max_conn, 128))
    srv.settimeout(0.5)
    print("RELAY READY", flush=True)
    end = time.monotonic() + float(max_s)
    conns = 0
    while time.monotonic() < end:
        try:
            client, _addr = srv.accept()
        except TimeoutError:
            continue
        if conns >= max_conn:
            _close(client)
            continue
        conns += 1
        try:
            target = _original(client, remap) if to_host == "ORIGINAL" else \
                (to_host, int(to_port))
            upstream = socket.create_connection(target, timeout=5)
        except OSError:
            _close(client)
            continue
        for s in (client, upstream):
            s.settimeout(None)
            s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        _one_way(client, upstream, delay)
        _one_way(upstream, client, delay)
    _close(srv)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
