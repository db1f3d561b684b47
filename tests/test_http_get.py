"""core.http.http_get on requests (the user's stack; issue 23): answers, redirects, errors in words,
bounded size and time. requests is imported where a GET is made, never on the start-up path
(issue 14: its import costs a tenth of a second). Real sockets on 127.0.0.1 only."""

from __future__ import annotations

import asyncio
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from rosnet_tui.core.net.http import MAX_BODY, http_get


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
    a = asyncio.run(http_get(silent.url(), 1.0))
    assert not a.ok and a.error == "connected, but no reply in time"
    assert time.monotonic() - t0 < 2 * 1.0  # one wait, never two (bench row 3 times it)


def test_a_server_trickling_its_answer_is_cut_at_the_timeout():
    """requests' timeout holds for each read: a server sending a byte every 0.15 s never trips
    it. The GET ends at its own timeout all the same (it ended 0.3 s later, and a check whose
    budget it filled ended with the runner's bare "no verdict")."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)
    stop = threading.Event()

    def trickle() -> None:
        c, _ = srv.accept()
        with c:
            c.recv(4096)
            for b in b"HTTP/1.1 200 OK\r\nX-Slow: " + b"y" * 100:
                if stop.wait(0.15):
                    return
                try:
                    c.sendall(bytes([b]))
                except OSError:
                    return

    th = threading.Thread(target=trickle, daemon=True)
    th.start()
    try:
        t0 = time.monotonic()
        a = asyncio.run(http_get(f"http://127.0.0.1:{srv.getsockname()[1]}/", 1.0))
        took = time.monotonic() - t0
    finally:
        stop.set()
        srv.close()
        th.join(5)
    assert not a.ok, a
    assert took < 1.15, took


def test_not_http_is_refused_in_words():
    a = asyncio.run(http_get("ftp://127.0.0.1/x", 1.0))
    assert not a.ok and "not an http(s) URL" in a.error


def loads_requests(argv: list[str]) -> bool:
    """Whether running rosnet-tui with *argv* (no network: help texts) imports requests."""
    code = ("import sys\nfrom rosnet_tui.cli import main\n"
            f"try:\n    main({argv!r})\nexcept SystemExit:\n    pass\n"
            "print('requests' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip().splitlines()[-1] == "True"


@pytest.mark.parametrize("argv", [["--help"], ["check", "--help"]], ids=" ".join)
def test_help_does_not_import_requests(argv):
    assert not loads_requests(argv)


def test_a_get_imports_requests_without_a_character_detector(server):
    """The same helper sees the import once a GET is made (so the test above can fail); the
    character detector requests would load (a third of its import, on the path of every round
    of checks) is not, and nothing is said about it."""
    s = server(response("200 OK", b"203.0.113.9"))
    code = ("import asyncio, sys\nfrom rosnet_tui.core.net.http import http_get\n"
            f"print(asyncio.run(http_get({s.url()!r}, 2.0)).ok, 'requests' in sys.modules,\n"
            "      any(m in sys.modules for m in ('chardet', 'charset_normalizer')))\n")
    out = subprocess.run([sys.executable, "-W", "default", "-c", code], capture_output=True,
                         text=True, timeout=60)
    assert out.stdout.split() == ["True", "True", "False"], out.stderr
    assert out.stderr == ""


def test_the_wizards_first_frame_does_not_import_requests(tmp_path: Path):
    """The real wizard under a pty: first frame, quit; the modules it loaded are written at exit."""
    from bench.local_env import base_env
    from bench.pty_harness import PtyProcess

    mods = tmp_path / "modules.txt"
    code = ("import atexit, sys\n"
            f"atexit.register(lambda: open({str(mods)!r}, 'w').write('\\n'.join(sys.modules)))\n"
            "from rosnet_tui.cli import main\n"
            f"sys.exit(main(['--config', {str(tmp_path / 'config.toml')!r}]))\n")
    env = base_env()
    env.update(HOME=str(tmp_path), XDG_CONFIG_HOME=str(tmp_path / "config"),
               XDG_STATE_HOME=str(tmp_path / "state"))
    p = PtyProcess([sys.executable, "-c", code], env, cols=100, rows=30,
                   cwd=str(Path(__file__).resolve().parents[1]))
    try:
        assert p.wait_text("Describe this machine", 30) is not None, p.text_since(0)[-800:]
        p.wait_quiet(0.4, 10)
    finally:
        p.close(quit_keys=b"\x11")
    loaded = mods.read_text().split()
    assert "rosnet_tui.ui.app" in loaded  # the wizard did run
    assert "requests" not in loaded


def test_the_round_s_first_gets_at_once_all_get_their_answer(server):
    """A round starts several GETs at once (isp.*, security.*) in a new process: each waits for
    the one import of requests another thread has begun, none uses it half made."""
    s = server(response("200 OK", b"203.0.113.9"))
    code = ("import asyncio\nfrom rosnet_tui.core.net.http import http_get\n"
            "async def main():\n"
            f"    got = await asyncio.gather(*(http_get({s.url()!r}, 5.0) for _ in range(6)))\n"
            "    print([a.error for a in got if not a.ok])\n"
            "asyncio.run(main())\n")
    for _ in range(3):
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                             timeout=60)
        assert out.stdout.strip() == "[]", out.stdout + out.stderr
