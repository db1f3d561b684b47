"""A self-hostable what-is-my-IP and port-check service, compatible with echoip (ifconfig.co).

``GET /`` and ``GET /ip`` answer the caller's address as text; ``GET /json`` as JSON;
``GET /port/N`` tries a TCP connection back to the caller on port N and answers
``{"ip": caller, "port": N, "reachable": true|false}``.

The one address the server ever connects to is the peer address of the HTTP connection itself:
headers (``X-Forwarded-For``, ``Forwarded``, ``Host`` ...) and query strings are never read for an
address, so the service cannot be used to scan anyone but the caller. Connect-backs are short,
bounded in number, and rate-limited per caller; requests are small and read under a deadline.
"""

from __future__ import annotations

import asyncio
import ipaddress
import json
import logging
import re
import signal
import socket
import time
from collections import OrderedDict, deque
from collections.abc import Callable
from dataclasses import dataclass

log = logging.getLogger("rosnet_tui.probe_server")

DEFAULT_LISTEN = "0.0.0.0:8080"
CHECK_PORT_MIN, CHECK_PORT_MAX = 1024, 65535

_PORT_PATH = re.compile(r"^/port/([^/]*)$")
_REASONS = {200: "OK", 400: "Bad Request", 404: "Not Found", 405: "Method Not Allowed",
            408: "Request Timeout", 429: "Too Many Requests", 431: "Request Header Fields Too Large",
            500: "Internal Server Error", 503: "Service Unavailable"}


@dataclass
class ProbeLimits:
    """The knobs that keep the service cheap and safe to expose."""

    connect_timeout_s: float = 2.0      # one connect-back attempt
    max_connect_backs: int = 16         # connect-backs in flight at once (503 beyond)
    checks_per_minute: int = 30         # port checks per caller address (429 beyond)
    max_connections: int = 256          # HTTP connections open at once (503 beyond)
    request_timeout_s: float = 5.0      # to receive the request line and headers
    max_request_bytes: int = 8192       # request line + headers
    max_headers: int = 64
    max_tracked_callers: int = 10_000   # memory bound of the rate limiter


class RateLimiter:
    """A sliding-window counter per key, with a bounded number of keys."""

    def __init__(self, limit: int, window_s: float = 60.0, max_keys: int = 10_000) -> None:
        self.limit = limit
        self.window_s = window_s
        self.max_keys = max_keys
        self._hits: OrderedDict[str, deque[float]] = OrderedDict()

    def allow(self, key: str, now: float | None = None) -> tuple[bool, int]:
        """Count one hit for *key*; return (allowed, seconds until the next hit would be)."""
        now = time.monotonic() if now is None else now
        hits = self._hits.get(key)
        if hits is None:
            hits = self._hits[key] = deque()
            while len(self._hits) > self.max_keys:
                self._hits.popitem(last=False)
        else:
            self._hits.move_to_end(key)
        while hits and hits[0] <= now - self.window_s:
            hits.popleft()
        if len(hits) >= self.limit:
            return False, max(1, int(hits[0] + self.window_s - now + 0.999))
        hits.append(now)
        return True, 0


def parse_listen(text: str) -> tuple[str, int]:
    """Parse ``ADDR:PORT``, ``[V6ADDR]:PORT``, ``:PORT`` or ``PORT`` into (address, port)."""
    text = text.strip()
    m = re.fullmatch(r"\[([0-9A-Fa-f:.]+)\]:(\d+)", text)
    if m:
        host, port_s = m.group(1), m.group(2)
    elif text.isascii() and text.isdigit():
        host, port_s = "0.0.0.0", text
    else:
        host, sep, port_s = text.rpartition(":")
        if not sep or ":" in host:
            raise ValueError(f"'{text}' is not ADDR:PORT (like 0.0.0.0:8080 or [::]:8080)")
        host = host or "0.0.0.0"
    try:
        ipaddress.ip_address(host)
    except ValueError:
        raise ValueError(f"'{host}' is not an IP address to listen on") from None
    port = int(port_s)
    if not 0 <= port <= 65535:
        raise ValueError(f"port {port} is out of range 0-65535")
    return host, port


def caller_address(peer: object) -> str:
    """The caller's IP as text, from a socket peer name (IPv4-mapped IPv6 shown as IPv4)."""
    host = str(peer[0]) if isinstance(peer, tuple) and peer else str(peer)
    try:
        addr = ipaddress.ip_address(host.split("%", 1)[0])
    except ValueError:
        return host
    if isinstance(addr, ipaddress.IPv6Address) and addr.ipv4_mapped is not None:
        return str(addr.ipv4_mapped)
    return host


def _printable(text: str, limit: int = 120) -> str:
    """A request path made safe for one log line."""
    out = "".join(c if c.isprintable() and not c.isspace() else "?" for c in text)
    return out if len(out) <= limit else out[:limit] + "..."


class _BadRequest(Exception):
    def __init__(self, status: int, message: str) -> None:
        super().__init__(message)
        self.status = status
        self.message = message


class ProbeServer:
    """The service. ``await start()`` binds it; ``await serve(stop)`` runs until *stop* is set."""

    def __init__(self, host: str = "0.0.0.0", port: int = 8080,
                 limits: ProbeLimits | None = None) -> None:
        self.host = host
        self.port = port
        self.limits = limits or ProbeLimits()
        self._limiter = RateLimiter(self.limits.checks_per_minute, 60.0,
                                    self.limits.max_tracked_callers)
        self._server: asyncio.base_events.Server | None = None
        self._connections = 0
        self._connect_backs = 0
        # The last connect-back targets (ip, port): evidence for tests and for the log reader.
        self.recent_connect_backs: deque[tuple[str, int]] = deque(maxlen=256)

    # ------------------------------------------------------------------ lifecycle
    async def start(self) -> int:
        """Bind and start accepting; returns the bound port (useful with port 0)."""
        self._server = await asyncio.start_server(
            self._handle, self.host, self.port, limit=self.limits.max_request_bytes,
            reuse_address=True)
        sock = self._server.sockets[0]
        self.port = sock.getsockname()[1]
        return self.port

    async def close(self) -> None:
        if self._server is not None:
            self._server.close()
            try:
                await asyncio.wait_for(self._server.wait_closed(), 1.0)
            except (asyncio.TimeoutError, asyncio.CancelledError):
                pass
            self._server = None

    async def serve(self, stop: asyncio.Event) -> None:
        """Serve until *stop* is set (or the task is cancelled), then close."""
        if self._server is None:
            await self.start()
        try:
            await stop.wait()
        finally:
            await self.close()

    # ------------------------------------------------------------------ connect-back
    async def check_port(self, ip: str, port: int) -> bool:
        """Whether a TCP connection to (ip, port) is accepted within the connect timeout.

        *ip* must be the caller's own address; only ``_handle`` calls this with the peer name.
        """
        self.recent_connect_backs.append((ip, port))
        writer = None
        try:
            _, writer = await asyncio.wait_for(
                asyncio.open_connection(ip, port, flags=socket.AI_NUMERICHOST),
                self.limits.connect_timeout_s)
            return True
        except (OSError, asyncio.TimeoutError):
            return False
        finally:
            if writer is not None:
                writer.close()
                try:
                    await asyncio.wait_for(writer.wait_closed(), 0.5)
                except (OSError, asyncio.TimeoutError):
                    pass

    # ------------------------------------------------------------------ HTTP
    async def _read_request(self, reader: asyncio.StreamReader) -> tuple[str, str]:
        """Read the request line and headers (ignored); return (method, path)."""
        total, lines = 0, []
        while True:
            try:
                line = await reader.readline()
            except (ValueError, asyncio.LimitOverrunError):
                raise _BadRequest(431, "request too large") from None
            if not line:
                raise _BadRequest(0 if total == 0 else 400, "incomplete request")
            total += len(line)
            if total > self.limits.max_request_bytes:
                raise _BadRequest(431, "request too large")
            if line in (b"\r\n", b"\n"):
                if lines:
                    break
                continue  # tolerate blank lines before the request line
            lines.append(line)
            if len(lines) > self.limits.max_headers + 1:
                raise _BadRequest(431, "too many headers")
            if not line.endswith(b"\n"):
                raise _BadRequest(400, "incomplete request")
        # Split on spaces only: str.split() would also split on Latin-1 NBSP (0xA0) and others.
        parts = [x for x in lines[0].decode("latin-1").rstrip("\r\n").split(" ") if x]
        if len(parts) != 3 or not parts[2].startswith("HTTP/"):
            raise _BadRequest(400, "malformed request line")
        method, target, _ = parts
        if target.startswith(("http://", "https://")):  # absolute-form: keep the path only
            target = "/" + target.split("://", 1)[1].partition("/")[2]
        return method, target.split("?", 1)[0].split("#", 1)[0]

    async def _handle(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        started = time.monotonic()
        caller = caller_address(writer.get_extra_info("peername"))
        self._connections += 1
        method, path, note = "-", "-", ""
        try:
            if self._connections > self.limits.max_connections:
                status, ctype, body, extra = self._error(503, "busy, try again shortly")
            else:
                try:
                    method, path = await asyncio.wait_for(self._read_request(reader),
                                                          self.limits.request_timeout_s)
                    status, ctype, body, extra, note = await self._route(caller, method, path)
                except _BadRequest as exc:
                    if not exc.status:  # connected and closed without a byte: nothing to answer
                        return
                    status, ctype, body, extra = self._error(exc.status, exc.message)
                except asyncio.TimeoutError:
                    status, ctype, body, extra = self._error(408, "request not received in time")
                except Exception as exc:  # noqa: BLE001 - a bug answers 500, never an empty reply
                    note = f"internal error: {type(exc).__name__}"
                    status, ctype, body, extra = self._error(500, "internal error")
            await self._respond(writer, status, ctype, body, extra)
        except (ConnectionError, OSError, asyncio.TimeoutError):
            status = 0
        finally:
            self._connections -= 1
            writer.close()
            try:
                await asyncio.wait_for(writer.wait_closed(), 0.5)
            except (OSError, asyncio.TimeoutError):
                pass
        ms = (time.monotonic() - started) * 1000
        log.info("%s %s %s %s%s %.0fms", caller, method, _printable(path), status or "-",
                 f" {note}" if note else "", ms)

    async def _route(self, caller: str, method: str, path: str):
        if method != "GET":
            return (*self._error(405, "only GET is supported", {"Allow": "GET"}), "")
        if path in ("/", "/ip"):
            return 200, "text/plain; charset=utf-8", (caller + "\n").encode(), {}, ""
        if path == "/json":
            return (*self._json(200, {"ip": caller}), "")
        m = _PORT_PATH.match(path)
        if not m:
            return (*self._error(404, "unknown path (try /ip or /port/N)"), "")
        raw = m.group(1)
        # ASCII digits only: str.isdigit() is also true for '²', '³' ..., which int() refuses.
        if not (raw.isascii() and raw.isdigit() and len(raw) <= 5) \
                or not CHECK_PORT_MIN <= int(raw) <= CHECK_PORT_MAX:
            return (*self._error(400, f"port must be a number between {CHECK_PORT_MIN} and "
                                      f"{CHECK_PORT_MAX}"), "")
        port = int(raw)
        allowed, retry = self._limiter.allow(caller)
        if not allowed:
            return (*self._error(429, "too many port checks from your address, slow down",
                                 {"Retry-After": str(retry)}), "rate-limited")
        if self._connect_backs >= self.limits.max_connect_backs:
            return (*self._error(503, "too many port checks in progress, try again shortly",
                                 {"Retry-After": "1"}), "busy")
        self._connect_backs += 1
        try:
            reachable = await self.check_port(caller, port)
        finally:
            self._connect_backs -= 1
        return (*self._json(200, {"ip": caller, "port": port, "reachable": reachable}),
                f"port={port} reachable={'true' if reachable else 'false'}")

    @staticmethod
    def _json(status: int, data: dict, extra: dict | None = None):
        return status, "application/json", (json.dumps(data) + "\n").encode(), extra or {}

    @classmethod
    def _error(cls, status: int, message: str, extra: dict | None = None):
        return cls._json(status, {"error": message}, extra)

    @staticmethod
    async def _respond(writer: asyncio.StreamWriter, status: int, ctype: str, body: bytes,
                       extra: dict) -> None:
        headers = {"Content-Type": ctype, "Content-Length": str(len(body)),
                   "Cache-Control": "no-store", "Connection": "close", **extra}
        head = f"HTTP/1.1 {status} {_REASONS.get(status, 'Error')}\r\n" + "".join(
            f"{k}: {v}\r\n" for k, v in headers.items()) + "\r\n"
        writer.write(head.encode("latin-1") + body)
        await asyncio.wait_for(writer.drain(), 5.0)


async def run_probe_server(host: str, port: int, limits: ProbeLimits | None = None,
                           ready: Callable[[int], None] | None = None) -> None:
    """Run the service until SIGINT/SIGTERM; *ready(port)* is called once it listens."""
    server = ProbeServer(host, port, limits)
    await server.start()
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        try:
            loop.add_signal_handler(sig, stop.set)
        except (NotImplementedError, RuntimeError, ValueError):  # not the main thread / Windows
            pass
    if ready is not None:
        ready(server.port)
    await server.serve(stop)
