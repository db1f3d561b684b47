"""The probe server on real loopback sockets: caller IP, connect-back, limits, and safety."""

from __future__ import annotations

import asyncio
import json
import os
import re
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from rosnet_tui.core.net.probe_server import (
    ProbeLimits,
    ProbeServer,
    RateLimiter,
    caller_address,
    parse_listen,
)
from tests.builders import free_port

REPO = Path(__file__).resolve().parents[1]


async def http(port: int, path: str = "/ip", *, src: str = "127.0.0.1", headers: dict | None = None,
               raw: bytes | None = None, method: str = "GET") -> tuple[int, dict, bytes]:
    """A tiny HTTP/1.1 client that can choose its source address (any of 127.0.0.0/8)."""
    reader, writer = await asyncio.wait_for(
        asyncio.open_connection("127.0.0.1", port, local_addr=(src, 0)), 5)
    if raw is None:
        lines = [f"{method} {path} HTTP/1.1", f"Host: 127.0.0.1:{port}"]
        lines += [f"{k}: {v}" for k, v in (headers or {}).items()]
        raw = ("\r\n".join(lines) + "\r\n\r\n").encode()
    writer.write(raw)
    await writer.drain()
    data = await asyncio.wait_for(reader.read(), 10)
    writer.close()
    head, _, body = data.partition(b"\r\n\r\n")
    status_line, *header_lines = head.decode("latin-1").split("\r\n")
    hdrs = {k.lower(): v.strip() for k, _, v in (h.partition(":") for h in header_lines)}
    return int(status_line.split()[1]), hdrs, body


class Listener:
    """A real TCP listener on (host, port 0) that records who connected."""

    def __init__(self, host: str = "127.0.0.1", backlog: int = 16) -> None:
        self.sock = socket.socket()
        self.sock.bind((host, 0))
        self.sock.listen(backlog)
        self.sock.setblocking(False)
        self.port = self.sock.getsockname()[1]

    def accepted(self) -> list[tuple[str, int]]:
        out = []
        while True:
            try:
                conn, peer = self.sock.accept()
            except BlockingIOError:
                return out
            out.append(peer)
            conn.close()

    def close(self) -> None:
        self.sock.close()


@pytest.fixture
async def server():
    srv = ProbeServer("127.0.0.1", 0, ProbeLimits(connect_timeout_s=1.0))
    await srv.start()
    yield srv
    await srv.close()


# ---------------------------------------------------------------------------- what-is-my-IP
async def test_answers_the_callers_address_as_text(server):
    for path in ("/", "/ip"):
        status, hdrs, body = await http(server.port, path)
        assert status == 200
        assert hdrs["content-type"].startswith("text/plain")
        assert body == b"127.0.0.1\n"
    status, _, body = await http(server.port, "/ip", src="127.0.0.7",
                                 headers={"X-Forwarded-For": "198.51.100.7"})
    assert (status, body) == (200, b"127.0.0.7\n")
    status, _, body = await http(server.port, "/json")
    assert json.loads(body) == {"ip": "127.0.0.1"}


# ---------------------------------------------------------------------------- port checks
async def test_open_port_is_reachable(server):
    listener = Listener()
    try:
        status, hdrs, body = await http(server.port, f"/port/{listener.port}")
        assert status == 200 and hdrs["content-type"] == "application/json"
        assert json.loads(body) == {"ip": "127.0.0.1", "port": listener.port, "reachable": True}
        assert [p[0] for p in listener.accepted()] == ["127.0.0.1"]
    finally:
        listener.close()


async def test_closed_port_is_not_reachable(server):
    port = free_port()
    status, _, body = await http(server.port, f"/port/{port}")
    assert status == 200
    assert json.loads(body) == {"ip": "127.0.0.1", "port": port, "reachable": False}


@pytest.mark.parametrize("bad", ["80", "1023", "65536", "99999", "abc", "", "12345x", "-1"])
async def test_bad_port_is_a_400_with_a_json_error(server, bad):
    status, hdrs, body = await http(server.port, f"/port/{bad}")
    assert status == 400
    assert "1024" in json.loads(body)["error"]
    assert not server.recent_connect_backs


async def test_unknown_path_and_method(server):
    assert (await http(server.port, "/admin"))[0] == 404
    status, hdrs, _ = await http(server.port, "/ip", method="POST")
    assert status == 405 and hdrs["allow"] == "GET"


async def test_rate_limit_per_caller_gives_429():
    srv = ProbeServer("127.0.0.1", 0, ProbeLimits(checks_per_minute=3))
    await srv.start()
    try:
        port = free_port()
        codes = [(await http(srv.port, f"/port/{port}"))[0] for _ in range(4)]
        assert codes == [200, 200, 200, 429]
        status, hdrs, body = await http(srv.port, f"/port/{port}")
        assert status == 429 and int(hdrs["retry-after"]) >= 1
        assert "error" in json.loads(body)
        # Another caller has its own allowance; the plain IP lookup is not rate-limited.
        assert (await http(srv.port, f"/port/{port}", src="127.0.0.2"))[0] == 200
        assert (await http(srv.port, "/ip"))[0] == 200
        assert len(srv.recent_connect_backs) == 4
    finally:
        await srv.close()


async def test_only_ever_connects_back_to_the_caller(server):
    """Addresses named in headers, the Host, the query or an absolute URL are never used."""
    elsewhere = Listener("127.0.0.2")  # the address a malicious request names
    try:
        p = elsewhere.port
        spoof = {"X-Forwarded-For": "127.0.0.2", "X-Real-IP": "127.0.0.2",
                 "Forwarded": "for=127.0.0.2", "X-Client-IP": "127.0.0.2",
                 "Host": f"127.0.0.2:{p}"}
        status, _, body = await http(server.port, f"/port/{p}?ip=127.0.0.2&host=127.0.0.2",
                                     headers=spoof)
        assert status == 200
        assert json.loads(body) == {"ip": "127.0.0.1", "port": p, "reachable": False}
        raw = (f"GET http://127.0.0.2:{p}/port/{p} HTTP/1.1\r\nHost: 127.0.0.2:{p}\r\n"
               f"X-Forwarded-For: 127.0.0.2\r\n\r\n").encode()
        status, _, body = await http(server.port, raw=raw)
        assert json.loads(body)["reachable"] is False
        assert elsewhere.accepted() == []
        assert set(server.recent_connect_backs) == {("127.0.0.1", p)}

        # The same request sent from 127.0.0.2 itself is checked against 127.0.0.2.
        status, _, body = await http(server.port, f"/port/{p}", src="127.0.0.2",
                                     headers={"X-Forwarded-For": "127.0.0.1"})
        assert json.loads(body) == {"ip": "127.0.0.2", "port": p, "reachable": True}
        assert [peer[0] for peer in elsewhere.accepted()] == ["127.0.0.1"]  # the server's side
        assert server.recent_connect_backs[-1] == ("127.0.0.2", p)
    finally:
        elsewhere.close()


async def test_concurrent_connect_backs_are_bounded():
    # the first connect-back hangs for its 4 s timeout: the second request, 0.2 s later, meets
    # it in flight even on a loaded machine (with 1 s, a late start could miss it)
    srv = ProbeServer("127.0.0.1", 0, ProbeLimits(connect_timeout_s=4.0, max_connect_backs=1))
    await srv.start()
    # A listener whose accept queue is full: connects to it hang until the timeout.
    stuck = Listener(backlog=0)
    filler = socket.create_connection(("127.0.0.1", stuck.port), timeout=2)
    try:
        results = await asyncio.gather(http(srv.port, f"/port/{stuck.port}"),
                                       _later(http(srv.port, f"/port/{stuck.port}"), 0.2))
        codes = sorted(r[0] for r in results)
        assert codes == [200, 503]
        ok = next(r for r in results if r[0] == 200)
        assert json.loads(ok[2])["reachable"] is False
    finally:
        filler.close()
        stuck.close()
        await srv.close()


async def _later(coro, delay: float):
    await asyncio.sleep(delay)
    return await coro


# ---------------------------------------------------------------------------- request limits
async def test_oversized_request_is_refused():
    srv = ProbeServer("127.0.0.1", 0, ProbeLimits(max_request_bytes=1024))
    await srv.start()
    try:
        status, _, _ = await http(srv.port, "/ip", headers={"X-Big": "a" * 4000})
        assert status == 431
        many = {f"X-H{i}": "1" for i in range(200)}
        assert (await http(srv.port, "/ip", headers=many))[0] == 431
    finally:
        await srv.close()


async def test_slow_request_times_out():
    srv = ProbeServer("127.0.0.1", 0, ProbeLimits(request_timeout_s=0.3))
    await srv.start()
    try:
        reader, writer = await asyncio.open_connection("127.0.0.1", srv.port)
        writer.write(b"GET /ip HTTP/1.1\r\n")  # ... and never finishes the headers
        data = await asyncio.wait_for(reader.read(), 5)
        writer.close()
        assert data.startswith(b"HTTP/1.1 408")
    finally:
        await srv.close()


async def test_logs_one_line_per_request(server, caplog):
    caplog.set_level("INFO", logger="rosnet_tui.probe_server")
    await http(server.port, "/ip")
    await http(server.port, f"/port/{free_port()}")

    def lines() -> list[str]:
        return [r.getMessage() for r in caplog.records if r.name == "rosnet_tui.probe_server"]

    for _ in range(500):                 # bounded (5 s): the line may follow the reply
        if len(lines()) >= 2:
            break
        await asyncio.sleep(0.01)
    lines = lines()
    assert len(lines) == 2
    assert lines[0].startswith("127.0.0.1 GET /ip 200")
    assert "reachable=false" in lines[1]


# ---------------------------------------------------------------------------- helpers
def test_parse_listen():
    assert parse_listen("0.0.0.0:8080") == ("0.0.0.0", 8080)
    assert parse_listen("192.0.2.10:80") == ("192.0.2.10", 80)
    assert parse_listen(":9000") == ("0.0.0.0", 9000)
    assert parse_listen("9000") == ("0.0.0.0", 9000)
    assert parse_listen("[::]:8080") == ("::", 8080)
    for bad in ("example.com:80", "1.2.3.4", "1.2.3.4:99999", "::1:80", "nope"):
        with pytest.raises(ValueError):
            parse_listen(bad)


def test_rate_limiter_window_and_bound():
    rl = RateLimiter(2, window_s=60, max_keys=2)
    assert rl.allow("a", 0)[0] and rl.allow("a", 1)[0]
    allowed, retry = rl.allow("a", 2)
    assert not allowed and retry == 58
    assert rl.allow("a", 61)[0]
    rl.allow("b", 62)
    rl.allow("c", 63)
    assert len(rl._hits) == 2


def test_caller_address_unmaps_ipv4_in_ipv6():
    assert caller_address(("::ffff:203.0.113.2", 5, 0, 0)) == "203.0.113.2"
    assert caller_address(("2001:db8::1", 5, 0, 0)) == "2001:db8::1"
    assert caller_address(("198.51.100.2", 5)) == "198.51.100.2"


def test_cli_serves_and_stops_cleanly_on_ctrl_c():
    port = free_port()
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.Popen([sys.executable, "-m", "rosnet_tui", "probe-server", "--listen",
                             f"127.0.0.1:{port}"], stderr=subprocess.PIPE, text=True, env=env)
    try:
        first = proc.stderr.readline()
        assert re.search(rf"listening on http://127\.0\.0\.1:{port}", first), first
        body = asyncio.run(http(port, "/ip"))[2]
        assert body == b"127.0.0.1\n"
        proc.send_signal(signal.SIGINT)
        rc = proc.wait(timeout=5)
        rest = proc.stderr.read()
        assert rc == 0
        assert "127.0.0.1 GET /ip 200" in rest and "stopped" in rest
        assert "Traceback" not in rest
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_cli_refuses_a_bad_listen_address():
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    r = subprocess.run([sys.executable, "-m", "rosnet_tui", "probe-server", "--listen", "host"],
                       capture_output=True, text=True, env=env, timeout=30)
    assert r.returncode == 2
    assert "ADDR:PORT" in r.stderr
