"""probes.http_get on the standard library (issue 14: requests' import cost a tenth of a second of
every run): answers, redirects, errors in words, bounded time. Real sockets on 127.0.0.1 only."""

from __future__ import annotations

import asyncio
import socket
import threading
import time

import pytest

from rosnet_tui.core.checks.probes import MAX_BODY, http_get


class RawServer:
    """Answers every connection with *reply* (bytes, or None: accept and say nothing)."""

    def __init__(self, reply: bytes | None) -> None:
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(8)
        self.port = self.sock.getsockname()[1]
        self.reply = reply
        self.conns: list[socket.socket] = []
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self) -> None:
        while True:
            try:
                c, _ = self.sock.accept()
            except OSError:
                return
            self.conns.append(c)
            c.settimeout(2)
            try:
                c.recv(4096)
                if self.reply is not None:
                    c.sendall(self.reply)
                    c.close()
            except OSError:
                pass

    def url(self, path: str = "/", host: str = "127.0.0.1") -> str:
        return f"http://{host}:{self.port}{path}"

    def close(self) -> None:
        self.sock.close()
        for c in self.conns:
            c.close()


@pytest.fixture
def server():
    made: list[RawServer] = []

    def make(reply: bytes | None) -> RawServer:
        s = RawServer(reply)
        made.append(s)
        return s

    yield make
    for s in made:
        s.close()


def response(status: str, body: bytes = b"", **headers: str) -> bytes:
    head = "".join(f"{k.replace('_', '-')}: {v}\r\n" for k, v in headers.items())
    return (f"HTTP/1.1 {status}\r\nContent-Length: {len(body)}\r\n{head}\r\n").encode() + body


def test_plain_answer_and_charset(server):
    s = server(response("200 OK", "203.0.113.9 é\n".encode("latin-1"),
                        Content_Type="text/plain; charset=latin-1"))
    a = asyncio.run(http_get(s.url("/ip"), 2.0))
    assert a.ok and a.status == 200 and a.text == "203.0.113.9 é\n"


def test_redirect_on_the_same_host_is_followed_another_host_is_not(server):
    target = server(response("200 OK", b"198.51.100.7"))
    same = server(response("302 Found", Location=f"http://127.0.0.1:{target.port}/ip"))
    a = asyncio.run(http_get(same.url("/"), 2.0))
    assert a.ok and a.text == "198.51.100.7"
    other = server(response("301 Moved", Location=f"http://localhost:{target.port}/ip"))
    a = asyncio.run(http_get(other.url("/"), 2.0))
    assert not a.ok and a.status == 301 and "redirected to another host" in a.error


def test_http_errors_say_the_status(server):
    s = server(response("429 Too Many Requests", b"slow down"))
    a = asyncio.run(http_get(s.url("/port/1"), 2.0))
    assert not a.ok and a.status == 429 and a.error == "HTTP 429 Too Many Requests"
    assert a.text == "slow down"


def test_the_body_is_capped(server):
    s = server(response("200 OK", b"x" * (MAX_BODY + 5000)))
    a = asyncio.run(http_get(s.url(), 2.0))
    assert a.ok and len(a.text) == MAX_BODY


def test_refused_and_silent_are_told_apart_within_the_timeout(server):
    closed = socket.socket()
    closed.bind(("127.0.0.1", 0))
    port = closed.getsockname()[1]
    closed.close()
    a = asyncio.run(http_get(f"http://127.0.0.1:{port}/", 2.0))
    assert not a.ok and a.error == "connection refused"
    silent = server(None)
    t0 = time.monotonic()
    a = asyncio.run(http_get(silent.url(), 0.6))
    assert not a.ok and a.error == "connected, but no reply in time"
    assert time.monotonic() - t0 < 1.2


def test_not_http_is_refused_in_words():
    a = asyncio.run(http_get("ftp://127.0.0.1/x", 1.0))
    assert not a.ok and "not an http(s) URL" in a.error
