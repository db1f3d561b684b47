"""HTTP GET to the services the settings name (what-is-my-IP, the port checker): bounded, never
raising for network trouble, answers and failures in a few words. HTTP ignores proxy variables: a
proxy would answer with its own address. requests is imported when a GET is made (start-up cost),
without a character detector (a third of its import: a body is decoded by the charset it
declares, never by a guess).
"""

from __future__ import annotations

import asyncio
import errno
import socket
import time
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from urllib.parse import urljoin, urlsplit

from rosnet_tui import __version__
from rosnet_tui.core.net.blocking import run_blocking
from rosnet_tui.core.net.lazy_import import import_without

MAX_BODY = 64 * 1024


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


def _ca_bundle() -> str | bool:
    """The system's trusted CAs (requests' own bundle, certifi's, when the system has none)."""
    import ssl

    paths = ssl.get_default_verify_paths()
    for path in (paths.cafile, paths.capath):
        if path and Path(path).exists():
            return path
    return True


def _root_cause(exc: BaseException) -> BaseException:
    """The socket or TLS error inside a requests exception (requests and urllib3 wrap it)."""
    import ssl

    seen: list[BaseException] = []
    todo = [exc]
    while todo:
        e = todo.pop(0)
        if e in seen:
            continue
        seen.append(e)
        todo += [x for x in (getattr(e, "reason", None), e.__cause__, e.__context__, *e.args)
                 if isinstance(x, BaseException)]
    for kinds in ((ssl.SSLError, ssl.CertificateError), socket.gaierror, ConnectionRefusedError,
                  OSError):
        found = [e for e in seen if isinstance(e, kinds) and (kinds is not OSError or e.errno)]
        if found:
            return found[-1]
    return exc


def _read_capped(r, deadline: float) -> bytes:
    """At most MAX_BODY bytes of the body of *r* (streamed), read before *deadline*."""
    body = b""
    for chunk in r.iter_content(8192):
        body += chunk
        if len(body) >= MAX_BODY or time.monotonic() > deadline:
            break
    return body[:MAX_BODY]


def _charset(content_type: str | None) -> str:
    from email.message import Message

    m = Message()
    m["content-type"] = content_type or "text/plain"
    return m.get_content_charset() or "utf-8"


def load_requests() -> ModuleType:
    """requests, imported on first use without a character detector (nothing here guesses a
    body's encoding; the detector's import cost about 30 ms)."""
    return import_without("requests", "chardet", "charset_normalizer",
                          quiet="Unable to find acceptable character detection")


def _http_get_blocking(url: str, timeout: float) -> HttpAnswer:
    """GET *url* with requests (imported here: never on the start-up path). No proxies from the
    environment (a proxy would answer with its own address); redirects are followed on the same
    host only; the body is streamed and capped at MAX_BODY."""
    requests = load_requests()
    deadline = time.monotonic() + timeout
    current = url
    with requests.Session() as http:
        http.trust_env = False
        for _ in range(4):
            parts = urlsplit(current)
            if parts.scheme not in ("http", "https") or not parts.hostname:
                return HttpAnswer(url, False, None, "", f"not an http(s) URL: {current}")
            try:
                parts.port  # noqa: B018 (a bad port raises here)
            except ValueError:
                return HttpAnswer(url, False, None, "", f"bad port in {current}")
            left = max(deadline - time.monotonic(), 0.05)
            try:
                with http.get(current, timeout=left, stream=True, allow_redirects=False,
                              verify=_ca_bundle() if parts.scheme == "https" else True,
                              headers={"User-Agent": f"rosnet-tui/{__version__}",
                                       "Accept": "text/plain, application/json;q=0.9, */*;q=0.5"}
                              ) as r:
                    location = r.headers.get("location")
                    if r.status_code in (301, 302, 303, 307, 308) and location:
                        nxt = urljoin(current, location)
                        if urlsplit(nxt).hostname != urlsplit(url).hostname:
                            return HttpAnswer(url, False, r.status_code, "",
                                              f"HTTP {r.status_code}: redirected to another host "
                                              f"({nxt}); not followed")
                        current = nxt
                        continue
                    body = _read_capped(r, deadline)
                    status, reason = r.status_code, r.reason
                    charset = _charset(r.headers.get("content-type"))
            except requests.RequestException as exc:
                if isinstance(exc, requests.Timeout):  # connected when the read timed out
                    words = _short_error(TimeoutError(), isinstance(exc, requests.ReadTimeout))
                else:
                    words = _short_error(_root_cause(exc))
                return HttpAnswer(url, False, None, "", words)
            try:
                text = body.decode(charset, "replace")
            except LookupError:
                text = body.decode("utf-8", "replace")
            if 200 <= status < 300:
                return HttpAnswer(url, True, status, text, None)
            return HttpAnswer(url, False, status, text, f"HTTP {status} {reason or ''}".strip())
    return HttpAnswer(url, False, None, "", "too many redirects")


async def http_get(url: str, timeout: float) -> HttpAnswer:
    """GET *url* within *timeout* seconds overall; never raises for network trouble. requests'
    own timeout holds for each step (connect, each read), so a server that trickles its answer
    could hold it longer: the wait here ends at *timeout* all the same (it ended 0.3 s after,
    and at 64 kbit/s isp.internet overran its budget by that much: the runner's bare timeout)."""
    inner = max(timeout - 0.1, timeout * 0.5)   # its own words first, when it has any
    try:
        return await run_blocking(_http_get_blocking, url, inner, timeout=timeout)
    except asyncio.TimeoutError:
        return HttpAnswer(url, False, None, "", f"no answer within {timeout:.1f} s")
