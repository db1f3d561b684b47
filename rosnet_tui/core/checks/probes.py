"""What the checks of several steps share: time budgets, HTTP to the configured services, the
public IP, and small stdlib-only programs run on a peer over SSH.

The check modules (``isp``, ``router``, ``linux``, ``ros``) import from here and from the core,
never from each other, so each step's checks can change without opening another step's file.
HTTP ignores proxy variables: a proxy would answer with its own address.
"""

from __future__ import annotations

import asyncio
import base64
import contextlib
import errno
import ipaddress
import shlex
import socket
import time
from dataclasses import dataclass
from urllib.parse import urljoin, urlsplit

from rosnet_tui import __version__
from rosnet_tui.core.checks import REGISTRY, CheckContext
from rosnet_tui.core.checks.data import view
from rosnet_tui.core.settings import Peer, Settings
from rosnet_tui.core.ssh import SshResult, run_blocking

MAX_BODY = 64 * 1024


def budget(ctx: CheckContext, check_id: str) -> float:
    """Seconds *check_id* may take under *ctx* (its timeout times its factor)."""
    spec = REGISTRY.get(check_id)
    return ctx.timeout_s * (spec.timeout_factor if spec else 1.0)


# --------------------------------------------------------------------------- HTTP
@dataclass
class HttpAnswer:
    url: str
    ok: bool                 # a 2xx answer arrived
    status: int | None
    text: str
    error: str | None        # why not, in a few words

    def describe(self) -> str:
        if self.ok:
            return f"GET {self.url} -> HTTP {self.status}: {self.text.strip()[:80]!r}"
        return f"GET {self.url} -> {self.error}"


def _short_error(exc: BaseException, connected: bool = False) -> str:
    """A failed GET in a few words (*connected*: the TCP connection was made)."""
    import ssl

    text = str(exc)
    if isinstance(exc, ssl.SSLError) or isinstance(exc, ssl.CertificateError):
        return "TLS error (" + text[:120] + ")"
    if isinstance(exc, (TimeoutError, socket.timeout)):
        return "connected, but no reply in time" if connected else \
            "no answer (timed out connecting)"
    if isinstance(exc, socket.gaierror):
        return ("the name does not resolve (DNS)" if exc.errno == socket.EAI_AGAIN
                else "the name does not resolve")
    if isinstance(exc, ConnectionRefusedError):
        return "connection refused"
    if isinstance(exc, OSError) and exc.errno == errno.EHOSTUNREACH:
        return "no route to the host"
    if isinstance(exc, OSError) and exc.errno == errno.ENETUNREACH:
        return "the network is unreachable"
    return text[:160] or type(exc).__name__


_TLS: list = []


def _tls_context():  # -> ssl.SSLContext
    """The system's trusted CAs (certifi's bundle when the system has none), made once."""
    import ssl

    if not _TLS:
        ctx = ssl.create_default_context()
        if not ctx.cert_store_stats().get("x509_ca"):
            with contextlib.suppress(Exception):
                import certifi

                ctx = ssl.create_default_context(cafile=certifi.where())
        _TLS.append(ctx)
    return _TLS[0]


def _http_get_blocking(url: str, timeout: float) -> HttpAnswer:
    """GET *url* with the standard library (no proxies from the environment: a proxy would
    answer with its own address); redirects are followed on the same host only."""
    import http.client

    deadline = time.monotonic() + timeout
    current = url
    for _ in range(4):
        parts = urlsplit(current)
        if parts.scheme not in ("http", "https") or not parts.hostname:
            return HttpAnswer(url, False, None, "", f"not an http(s) URL: {current}")
        left = max(deadline - time.monotonic(), 0.05)
        try:
            port = parts.port
        except ValueError:
            return HttpAnswer(url, False, None, "", f"bad port in {current}")
        conn = (http.client.HTTPSConnection(parts.hostname, port, timeout=left,
                                            context=_tls_context())
                if parts.scheme == "https" else
                http.client.HTTPConnection(parts.hostname, port, timeout=left))
        path = (parts.path or "/") + (f"?{parts.query}" if parts.query else "")
        try:
            try:
                conn.request("GET", path, headers={
                    "User-Agent": f"rosnet-tui/{__version__}",
                    "Accept": "text/plain, application/json;q=0.9, */*;q=0.5"})
                if conn.sock is not None:
                    conn.sock.settimeout(max(deadline - time.monotonic(), 0.05))
                r = conn.getresponse()
                location = r.getheader("location")
                if r.status in (301, 302, 303, 307, 308) and location:
                    nxt = urljoin(current, location)
                    if urlsplit(nxt).hostname != urlsplit(url).hostname:
                        return HttpAnswer(url, False, r.status, "",
                                          f"HTTP {r.status}: redirected to another host ({nxt}); "
                                          "not followed")
                    current = nxt
                    continue
                body = r.read(MAX_BODY) or b""
            except (OSError, http.client.HTTPException) as exc:
                return HttpAnswer(url, False, None, "",
                                  _short_error(exc, connected=conn.sock is not None))
            charset = r.headers.get_content_charset() or "utf-8"
            try:
                text = body.decode(charset, "replace")
            except LookupError:
                text = body.decode("utf-8", "replace")
            if 200 <= r.status < 300:
                return HttpAnswer(url, True, r.status, text, None)
            return HttpAnswer(url, False, r.status, text, f"HTTP {r.status} {r.reason or ''}".strip())
        finally:
            conn.close()
    return HttpAnswer(url, False, None, "", "too many redirects")


async def http_get(url: str, timeout: float) -> HttpAnswer:
    """GET *url* within *timeout* seconds overall; never raises for network trouble."""
    try:
        return await run_blocking(_http_get_blocking, url, timeout, timeout=timeout + 0.3)
    except asyncio.TimeoutError:
        return HttpAnswer(url, False, None, "", f"no answer within {timeout:.1f} s")


def parse_ip(text: str) -> str | None:
    """The IPv4 address a what-is-my-IP service answered (plain text, or JSON with "ip")."""
    t = text.strip()
    if t.startswith("{"):
        import json

        with contextlib.suppress(ValueError, AttributeError):
            t = str(json.loads(t).get("ip", ""))
    t = t.split()[0] if t.split() else ""
    try:
        a = ipaddress.ip_address(t)
    except ValueError:
        return None
    return str(a) if a.version == 4 else None


def round_public_ip(ctx: CheckContext) -> str | None:
    """The public IP isp.public_ip found in this round (None: it did not run, or found none)."""
    res = ctx.results.get("isp.public_ip")
    if res is None:
        return None
    return view("isp.public_ip", res.data).get("public_ip")


async def fetch_public_ip(ctx: CheckContext, timeout: float) -> str | None:
    """This component's public IP: from this round's isp.public_ip if it ran, else one quick ask."""
    found = round_public_ip(ctx)
    if found:
        return str(found)
    for url in ctx.settings.probe.public_ip_urls[:1]:
        ans = await http_get(url, timeout)
        if ans.ok:
            return parse_ip(ans.text)
    return None


# --------------------------------------------------------------------------- programs on a peer
def ssh_peers(s: Settings) -> list[Peer]:
    """The peers we can run commands on (those with an SSH user), in the settings' order."""
    return [p for p in s.peers if p.ssh_user]


def shq(s: str) -> str:
    """*s* quoted for a POSIX shell (single quotes)."""
    return "'" + s.replace("'", "'\\''") + "'"


def python_command(script: str, *args: str, python: str = "python3") -> str:
    """A shell command running stdlib-only *script* with python3 on a peer (no install needed).

    ``-S``: the probes need the standard library only, so the peer skips site (its
    site-packages, .pth files): a faster start, and nothing of the peer's can shadow a module.
    """
    b64 = base64.b64encode(script.encode()).decode()
    quoted = " ".join(shq(a) for a in args)
    return (f"{python} -S -c 'import base64;exec(base64.b64decode(\"{b64}\"))' "
            f"{quoted}").strip()


def python_stdin_command(*args: str) -> str:
    """A shell command running the program fed on stdin with python3 on a peer (``python3 -``,
    without site, as :func:`python_command`)."""
    return "python3 -S - " + " ".join(shlex.quote(a) for a in args)


def peer_program_problem(res: SshResult, peer: Peer) -> str | None:
    """Why a program could not run on *peer* over SSH (None when it ran)."""
    if res.failure:
        return f"SSH to {peer.name} failed ({res.failure}): {res.detail}"
    if res.exit_status == 127:
        return f"{peer.name} has no python3 to run the probe (exit status 127)"
    return None


def stderr_tail(res: SshResult) -> str:
    """The last lines the peer's program wrote on stderr, on one line."""
    tail = (res.stderr or "").strip().splitlines()[-3:]
    return " | ".join(tail)
