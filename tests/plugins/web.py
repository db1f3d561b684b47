"""Fixtures (a pytest plugin, loaded by tests/conftest.py): a small web server and the product's
probe server, both on 127.0.0.1 in their own threads.
"""

from __future__ import annotations

import asyncio
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import pytest

from rosnet_tui.core.net.probe_server import ProbeServer


class WebServer:
    """A tiny HTTP server on 127.0.0.1: ``routes[path] = (status, body)`` (changeable live)."""

    def __init__(self) -> None:
        self.routes: dict[str, tuple[int, str]] = {}
        self.fallback = None  # callable(path) -> (status, body) for paths not in routes
        self.on_request = None  # callable((host, port) of the client), before it is answered
        self.hits: list[str] = []
        routes, hits, server = self.routes, self.hits, self

        class Handler(BaseHTTPRequestHandler):
            def do_GET(self):  # noqa: N802
                hits.append(self.path)
                if server.on_request is not None:
                    server.on_request(self.client_address)
                if self.path in routes or server.fallback is None:
                    status, body = routes.get(self.path, (404, "not found"))
                else:
                    status, body = server.fallback(self.path)
                data = body.encode()
                try:
                    self.send_response(status)
                    self.send_header("Content-Type", "text/plain")
                    self.send_header("Content-Length", str(len(data)))
                    self.end_headers()
                    self.wfile.write(data)
                except (BrokenPipeError, ConnectionResetError):
                    # the client left (a test killed it): no traceback from this thread, which
                    # could land on the terminal between pytest's capture phases
                    self.close_connection = True

            def log_message(self, *a):
                pass

        self.httpd = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.httpd.daemon_threads = True
        self.port = self.httpd.server_address[1]
        self.thread = threading.Thread(target=self.httpd.serve_forever, args=(0.05,), daemon=True)
        self.thread.start()

    def url(self, path: str, host: str = "127.0.0.1") -> str:
        return f"http://{host}:{self.port}{path}"

    def close(self) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()


class ProbeThread:
    """The product's echoip-compatible probe server on 127.0.0.1, in its own thread and loop."""

    def __init__(self) -> None:
        self.loop = asyncio.new_event_loop()
        self.server = ProbeServer("127.0.0.1", 0)
        self.port = self.loop.run_until_complete(self.server.start())
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def close(self) -> None:
        asyncio.run_coroutine_threadsafe(self.server.close(), self.loop).result(5)
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(5)
        self.loop.close()


@pytest.fixture
def web():
    w = WebServer()
    yield w
    w.close()


@pytest.fixture
def probe_server():
    p = ProbeThread()
    yield p
    p.close()
