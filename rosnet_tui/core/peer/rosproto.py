"""A small client of the documented ROS 1 protocols: Master API, Slave API and TCPROS.

Stdlib only and a single file on purpose: the checks pipe this very source over SSH into
``python3 -`` on a peer that may have neither ROS nor rosnet-tui installed, e.g.::

    python3 - sub --master http://turtlebot:11311 --topic /rosnet_probe/ab12 --timeout 6

prints one JSON line (``{"rosnet_probe": 1, ...}``) saying which hop worked and which failed.

The probe node behaves like any ROS 1 node started in the same environment: it advertises
``http://<ROS_HOSTNAME or ROS_IP or hostname>:<port>/`` (rospy's rules), so a wrong ROS_IP shows up
here exactly as it does for real nodes. Every network operation has a timeout; failures come back
as data (:class:`ProbeReport`, :class:`Hop`), never as a hang. Our servers live only as long as
the probe and never connect to an address a caller hands them: publisher addresses are always taken
from the master we were pointed at.

Python 3.8+ syntax, no imports from rosnet_tui.
"""
# The peer's python3 may be 3.8: keep typing's generics and socket.timeout (not yet TimeoutError).
# ruff: noqa: UP006, UP035, UP041, UP045

from __future__ import annotations

import errno
import json
import os
import re
import select
import shlex
import socket
import socketserver
import stat
import struct
import sys
import threading
import time

# A peer runs this program once per check, so its start-up counts (issue 25): no typing,
# dataclasses, http.client, xmlrpc.*, argparse, urllib, secrets or concurrent.futures at run
# time (~75 ms of CPU per start together); the XML-RPC and HTTP it needs are below, on a socket.
TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import Any, Dict, Iterable, List, Optional, Tuple

STRING_TYPE = "std_msgs/String"
STRING_MD5 = "992ce8a1687cec8c8bd883ec73ca41d1"
STRING_DEFINITION = "string data\n"
PROBE_PREFIX = "/rosnet_probe"
REPORT_KEY = "rosnet_probe"
MAX_HEADER = 1 << 20     # a connection header longer than this is not a ROS peer
MAX_MESSAGE = 1 << 20

# The hops of one publish/subscribe exchange, in order.
HOPS = ("registration", "xmlrpc_callback", "tcpros", "no_message")



# --------------------------------------------------------------------------- records
_NEW_LIST = object()   # a field default: a fresh empty list per record


class Record:
    """A plain record in the manner of a dataclass (whose import costs ~6 ms per start): the
    fields are the class's annotations in order, a class attribute is a field's default.
    Positional and keyword construction, ==, repr and :meth:`to_dict` (dataclasses.asdict)."""

    FIELDS: Tuple[Tuple[str, Any], ...] = ()
    _REQUIRED = object()

    def __init_subclass__(cls, **kw: Any) -> None:
        super().__init_subclass__(**kw)
        names = [n for n in cls.__dict__.get("__annotations__", {}) if n != "FIELDS"]
        cls.FIELDS = tuple((n, cls.__dict__.get(n, Record._REQUIRED)) for n in names)

    def __init__(self, *args: Any, **kw: Any) -> None:
        if len(args) > len(self.FIELDS):
            raise TypeError(f"{type(self).__name__} takes at most {len(self.FIELDS)} values")
        given = {self.FIELDS[i][0]: a for i, a in enumerate(args)}
        for k, v in kw.items():
            if k in given or all(k != n for n, _ in self.FIELDS):
                raise TypeError(f"{type(self).__name__}: unexpected or repeated field {k!r}")
            given[k] = v
        for name, default in self.FIELDS:
            if name in given:
                value = given[name]
            elif default is Record._REQUIRED:
                raise TypeError(f"{type(self).__name__}: missing field {name!r}")
            else:
                value = [] if default is _NEW_LIST else default
            setattr(self, name, value)

    def to_dict(self) -> Dict[str, Any]:
        return {n: _plain(getattr(self, n)) for n, _ in self.FIELDS}

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        return all(getattr(self, n) == getattr(other, n) for n, _ in self.FIELDS)

    __hash__ = None  # type: ignore[assignment]  (mutable, like a dataclass with eq)

    def __repr__(self) -> str:
        inner = ", ".join(f"{n}={getattr(self, n)!r}" for n, _ in self.FIELDS)
        return f"{type(self).__name__}({inner})"


def _plain(value: Any) -> Any:
    if isinstance(value, Record):
        return value.to_dict()
    if isinstance(value, (list, tuple)):
        return type(value)(_plain(v) for v in value)
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    return value


# --------------------------------------------------------------------------- errors
class MasterCallError(Exception):
    """The master answered, but with a failure code (code, status message)."""

    def __init__(self, method: str, code: int, message: str) -> None:
        self.method, self.code, self.message = method, code, message
        super().__init__(f"{method} returned code {code}: {message}")


class HttpError(Exception):
    """An HTTP answer other than 200 to an XML-RPC call."""

    def __init__(self, errcode: int, errmsg: str) -> None:
        self.errcode, self.errmsg = errcode, errmsg
        super().__init__(f"HTTP {errcode} {errmsg}")


class XmlRpcFault(Exception):
    """An XML-RPC fault answer."""

    def __init__(self, fault_code: Any, fault_string: Any) -> None:
        self.faultCode, self.faultString = fault_code, fault_string  # noqa: N815 (XML-RPC names)
        super().__init__(f"fault {fault_code}: {fault_string}")


class XmlRpcError(ValueError):
    """An answer or request that is not XML-RPC over HTTP."""


def describe_error(exc: BaseException, timeout: Optional[float] = None) -> Tuple[str, str]:
    """(kind, plain words) for a network failure; kind is one of resolve, refused, timeout,
    unreachable, reset, http, fault, protocol, master, error."""
    if isinstance(exc, MasterCallError):
        return "master", f"the master refused {exc.method}: {exc.message} (code {exc.code})"
    if isinstance(exc, socket.gaierror):
        return "resolve", f"the name does not resolve ({exc.strerror or exc})"
    if isinstance(exc, ConnectionRefusedError):
        return "refused", "connection refused (nothing listens on that port, or it is blocked)"
    if isinstance(exc, (socket.timeout, TimeoutError)):
        within = f" within {timeout:g} s" if timeout else ""
        return "timeout", f"no answer{within} (timed out)"
    if isinstance(exc, ConnectionResetError):
        return "reset", "the connection was reset by the other side"
    if isinstance(exc, HttpError):
        return "http", f"HTTP error {exc.errcode} {exc.errmsg}"
    if isinstance(exc, XmlRpcFault):
        return "fault", f"XML-RPC fault {exc.faultCode}: {exc.faultString}"
    if isinstance(exc, ValueError):
        return "protocol", f"the answer is not ROS XML-RPC ({type(exc).__name__}: {exc})"
    if isinstance(exc, OSError):
        if exc.errno in (errno.EHOSTUNREACH, errno.ENETUNREACH):
            return "unreachable", f"no route to the address ({exc.strerror})"
        return "error", f"{exc.strerror or exc}"
    return "error", f"{type(exc).__name__}: {exc}"


# --------------------------------------------------------------------------- environment
_ASSIGN_RE = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*)=(.*)$", re.S)



def read_small_text(path: str, limit: int) -> str:
    """The first *limit* bytes of a regular file, as text. This program also runs alone on peers
    (stdlib only), so it carries its own guard: opened without blocking, anything but a regular
    file (a FIFO would block until a writer comes, a device never end) raises OSError."""
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY)
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise OSError(errno.EINVAL, "not a regular file", path)
        chunks, total = [], 0
        while total < limit:
            chunk = os.read(fd, min(65536, limit - total))
            if not chunk:
                break
            chunks.append(chunk)
            total += len(chunk)
    finally:
        os.close(fd)
    return b"".join(chunks).decode("utf-8", "replace")


def read_shell_exports(path: Optional[str], names: Iterable[str]
                       ) -> Dict[str, Tuple[Optional[str], int]]:
    """The last effective assignment of each of *names* in a shell rc file such as ~/.bashrc.

    Returns {name: (value, line)}; value None means a later ``unset``. Commented lines are ignored;
    ``export A=1``, ``A=1``, ``declare -x A=1`` and quotes are understood; conditionals are not
    evaluated (every assignment counts). A missing or unreadable file gives {}.
    """
    wanted = set(names)
    found: Dict[str, Tuple[Optional[str], int]] = {}
    if not path:
        return found
    try:
        lines = read_small_text(os.path.expanduser(str(path)), 4 << 20).splitlines()
    except OSError:
        return found
    for n, raw in enumerate(lines, 1):
        line = raw.strip()
        if not line or line.startswith("#") or not any(w in line for w in wanted):
            continue
        for part in re.split(r"\s*(?:;|&&|\|\|)\s*", line):
            try:
                tokens = shlex.split(part, comments=True, posix=True)
            except ValueError:
                continue
            if not tokens:
                continue
            if tokens[0] in ("if", "then", "else", "elif", "do") and len(tokens) > 1:
                tokens = tokens[1:]
            if tokens[0] == "unset":
                for t in tokens[1:]:
                    if t in wanted:
                        found[t] = (None, n)
                continue
            if tokens[0] == "export" or (tokens[0] in ("declare", "typeset") and "-x" in tokens):
                tokens = [t for t in tokens[1:] if not t.startswith("-")]
            elif not _ASSIGN_RE.match(tokens[0]):
                continue
            for t in tokens:
                m = _ASSIGN_RE.match(t)
                if m and m.group(1) in wanted:
                    found[m.group(1)] = (m.group(2), n)
                elif not m:
                    break
    return found


def effective_ros_env(env: Optional[Dict[str, str]] = None, bashrc: Optional[str] = None
                      ) -> Dict[str, Tuple[str, str]]:
    """ROS_HOSTNAME, ROS_IP and ROS_MASTER_URI as a node started here would see them.

    The environment wins; a variable absent from it is taken from *bashrc* (what a new terminal
    gets). Returns {name: (value, where)} for the variables that are set.
    """
    env = dict(os.environ) if env is None else env
    names = ("ROS_HOSTNAME", "ROS_IP", "ROS_MASTER_URI")
    rc = read_shell_exports(bashrc, names)
    out: Dict[str, Tuple[str, str]] = {}
    for name in names:
        if name in env:
            out[name] = (env[name], "environment")
        elif name in rc and rc[name][0] is not None:
            out[name] = (str(rc[name][0]), f"{bashrc} line {rc[name][1]}")
    return out


def _first_local_address() -> str:
    """This machine's main IPv4 address without sending anything (a UDP connect only routes)."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        s.connect(("192.0.2.1", 9))  # TEST-NET-1: a route lookup, no packet leaves
        return s.getsockname()[0]
    except OSError:
        return "127.0.0.1"
    finally:
        s.close()


def advertised_host(env: Optional[Dict[str, str]] = None, bashrc: Optional[str] = None
                    ) -> Tuple[str, str]:
    """(host, why) a ROS node started here puts in its URIs, by rospy's rules:
    ROS_HOSTNAME, else ROS_IP, else the hostname unless it is localhost, else a local address."""
    eff = effective_ros_env(env, bashrc)
    for name in ("ROS_HOSTNAME", "ROS_IP"):
        if name in eff and eff[name][0]:
            return eff[name][0], f"{name} ({eff[name][1]})"
    try:
        hostname = socket.gethostname()
    except OSError:
        hostname = ""
    if hostname and hostname != "localhost" and not hostname.startswith("127."):
        return hostname, "the hostname"
    return _first_local_address(), "a local address (the hostname is localhost)"


def bind_address(host: str) -> str:
    """Where a node that advertises *host* listens (rospy: loopback for loopback, else all)."""
    if host == "localhost" or host.startswith("127."):
        return host if host.startswith("127.") else "127.0.0.1"
    return "0.0.0.0"


def split_uri(uri: str) -> Tuple[str, int]:
    """(host, port) of an http:// URI; port 80 when absent. ValueError when unusable."""
    scheme, host, port, _ = parse_uri(uri)
    if scheme not in ("http", "rosrpc") or not host:
        raise ValueError(f"not an http:// URI: {uri!r}")
    return host, port or 80


def parse_uri(uri: str) -> Tuple[str, str, Optional[int], str]:
    """(scheme, host, port or None, path) of ``scheme://[user@]host[:port][/path]``, host in
    lower case, IPv6 literals without brackets (urllib.parse's answers, without its import).
    ValueError when the port is not a number in 0..65535."""
    scheme, sep, rest = str(uri).partition("://")
    if not sep:
        return "", "", None, str(uri)
    netloc, _, path = rest.partition("/")
    netloc = netloc.split("?", 1)[0].split("#", 1)[0].rpartition("@")[2]
    if netloc.startswith("["):
        host, _, tail = netloc[1:].partition("]")
        port_s = tail[1:] if tail.startswith(":") else ""
    else:
        host, _, port_s = netloc.partition(":")
    port = None
    if port_s:
        if not (port_s.isascii() and port_s.isdigit()) or int(port_s) > 65535:
            raise ValueError(f"bad port in {uri!r}")
        port = int(port_s)
    return scheme.lower(), host.lower(), port, "/" + path.split("#", 1)[0]


def new_probe_id() -> str:
    return os.urandom(4).hex()


def probe_caller_id(role: str, probe_id: str) -> str:
    """A valid ROS graph name with this host in it, e.g. /rosnet_probe_sami_pub_1a2b."""
    try:
        host = re.sub(r"[^A-Za-z0-9_]", "_", socket.gethostname().split(".")[0]) or "host"
    except OSError:
        host = "host"
    return f"{PROBE_PREFIX}_{host}_{role}_{probe_id}"


# --------------------------------------------------------------------------- XML-RPC clients
MAX_XMLRPC = 64 << 20    # an XML-RPC message longer than this is not from a ROS node
_HTTP_LINE = 65536


def _escape(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


def _dump(value: Any, out: List[str]) -> None:
    """XML-RPC <value> of *value* (xmlrpc.client's encoding, None as <nil/>)."""
    if value is None:
        out.append("<value><nil/></value>")
    elif value is True or value is False:
        out.append(f"<value><boolean>{int(value)}</boolean></value>")
    elif isinstance(value, int):
        if not -(1 << 31) <= value < (1 << 31):
            raise OverflowError(f"int {value} exceeds XML-RPC limits")
        out.append(f"<value><int>{int(value)}</int></value>")
    elif isinstance(value, float):
        out.append(f"<value><double>{value!r}</double></value>")
    elif isinstance(value, str):
        out.append(f"<value><string>{_escape(value)}</string></value>")
    elif isinstance(value, (bytes, bytearray)):
        import base64
        out.append(f"<value><base64>{base64.b64encode(value).decode('ascii')}</base64></value>")
    elif isinstance(value, (list, tuple)):
        out.append("<value><array><data>")
        for v in value:
            _dump(v, out)
        out.append("</data></array></value>")
    elif isinstance(value, dict):
        out.append("<value><struct>")
        for k, v in value.items():
            if not isinstance(k, str):
                raise TypeError("XML-RPC struct keys must be strings")
            out.append(f"<member><name>{_escape(k)}</name>")
            _dump(v, out)
            out.append("</member>")
        out.append("</struct></value>")
    else:
        raise TypeError(f"cannot marshal {type(value).__name__} objects")


def dump_call(method: str, params: Any) -> bytes:
    out = ["<?xml version='1.0'?>\n<methodCall>\n<methodName>", _escape(method),
           "</methodName>\n<params>\n"]
    for p in params:
        out.append("<param>\n")
        _dump(p, out)
        out.append("\n</param>\n")
    out.append("</params>\n</methodCall>\n")
    return "".join(out).encode("utf-8")


def dump_response(value: Any) -> bytes:
    out = ["<?xml version='1.0'?>\n<methodResponse>\n<params>\n<param>\n"]
    _dump(value, out)
    out.append("\n</param>\n</params>\n</methodResponse>\n")
    return "".join(out).encode("utf-8")


def dump_fault(code: int, message: str) -> bytes:
    out = ["<?xml version='1.0'?>\n<methodResponse>\n<fault>\n"]
    _dump({"faultCode": code, "faultString": message}, out)
    out.append("\n</fault>\n</methodResponse>\n")
    return "".join(out).encode("utf-8")


_SCALARS = ("int", "i4", "i8", "boolean", "double", "string", "nil", "base64",
            "dateTime.iso8601")


class _Struct:
    __slots__ = ("members", "name")

    def __init__(self) -> None:
        self.members: Dict[str, Any] = {}
        self.name = ""


def load_xmlrpc(data: bytes) -> Tuple[Optional[str], List[Any], bool]:
    """(methodName or None, params, is_fault) of an XML-RPC methodCall or methodResponse.
    XmlRpcError when it is not well-formed XML-RPC."""
    from xml.parsers import expat
    stack: List[Any] = []          # open arrays (list) and structs (_Struct)
    params: List[Any] = []
    text: List[str] = []
    done: List[bool] = []          # per open <value>: has a typed child given its value
    state = {"method": None, "fault": False, "root": None}

    def put(v: Any) -> None:
        if done:
            done[-1] = True
        if not stack:
            params.append(v)
        elif isinstance(stack[-1], list):
            stack[-1].append(v)
        else:
            stack[-1].members[stack[-1].name] = v

    def start(tag: str, attrs: Any) -> None:
        if state["root"] is None:
            state["root"] = tag
        if tag == "value":
            done.append(False)
        elif tag == "array":
            stack.append([])
        elif tag == "struct":
            stack.append(_Struct())
        elif tag == "fault":
            state["fault"] = True
        text.clear()

    def end(tag: str) -> None:
        t = "".join(text)
        text.clear()
        if tag in ("int", "i4", "i8"):
            put(int(t.strip()))
        elif tag == "boolean":
            if t.strip() not in ("0", "1"):
                raise XmlRpcError(f"bad boolean {t!r}")
            put(t.strip() == "1")
        elif tag == "double":
            put(float(t.strip()))
        elif tag in ("string", "dateTime.iso8601"):
            put(t)
        elif tag == "nil":
            put(None)
        elif tag == "base64":
            import base64
            put(base64.b64decode(t.encode("ascii")))
        elif tag in ("array", "struct"):
            if not stack:
                raise XmlRpcError(f"unbalanced <{tag}>")
            top = stack.pop()
            if isinstance(top, list) != (tag == "array"):
                raise XmlRpcError(f"unbalanced <{tag}>")
            put(top if tag == "array" else top.members)
        elif tag == "name":
            if not stack or isinstance(stack[-1], list):
                raise XmlRpcError("<name> outside a struct")
            stack[-1].name = t
        elif tag == "value":
            if not done.pop():
                put(t)         # a <value> without a type is a string
        elif tag == "methodName":
            state["method"] = t

    parser = expat.ParserCreate("utf-8")
    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.CharacterDataHandler = text.append
    try:
        parser.Parse(data, True)
    except (expat.ExpatError, ValueError, TypeError, KeyError, IndexError) as exc:
        raise XmlRpcError(f"not XML-RPC: {exc}") from None
    if state["root"] not in ("methodCall", "methodResponse"):
        raise XmlRpcError(f"not XML-RPC: root element {state['root']!r}")
    return state["method"], params, bool(state["fault"])


def read_http(rfile: Any, response: bool) -> Tuple[List[str], Dict[str, str], bytes]:
    """One HTTP/1.x message from a binary file: (start line's words, headers with lower-case
    names, body). A response without Content-Length is read to EOF; a request needs it."""
    line = rfile.readline(_HTTP_LINE + 1)
    if not line:
        raise ConnectionResetError(errno.ECONNRESET, "the connection closed without an answer")
    first = line.decode("latin-1").strip().split(None, 2)
    if len(first) < 2 or not (first[0] if response else first[-1]).startswith("HTTP/"):
        raise XmlRpcError(f"not HTTP: {line[:80]!r}")
    headers: Dict[str, str] = {}
    for _ in range(200):
        line = rfile.readline(_HTTP_LINE + 1)
        if line in (b"\r\n", b"\n", b""):
            break
        name, sep, value = line.decode("latin-1").partition(":")
        if sep:
            headers[name.strip().lower()] = value.strip()
    else:
        raise XmlRpcError("too many HTTP header lines")
    length = headers.get("content-length")
    if length is not None:
        if not (length.isascii() and length.isdigit()) or int(length) > MAX_XMLRPC:
            raise XmlRpcError(f"bad Content-Length {length!r}")
        body = rfile.read(int(length))
        if len(body) < int(length):
            raise ConnectionResetError(errno.ECONNRESET, "the connection closed mid-answer")
    elif response:
        body = rfile.read(MAX_XMLRPC + 1)
        if len(body) > MAX_XMLRPC:
            raise XmlRpcError("answer too long")
    else:
        body = b""
    return first, headers, body


def xmlrpc_call(uri: str, method: str, *args: Any, timeout: float = 3.0) -> Any:
    """Call *method* on the XML-RPC server at *uri*, bounded by *timeout* per socket operation
    (connect, and every send and read). Raises OSError, HttpError, XmlRpcFault, XmlRpcError."""
    scheme, host, port, path = parse_uri(uri)
    if scheme != "http" or not host:
        raise XmlRpcError(f"not an http:// URI: {uri!r}")
    port = port or 80
    body = dump_call(method, args)
    hostport = f"[{host}]:{port}" if ":" in host else f"{host}:{port}"
    head = (f"POST {path} HTTP/1.1\r\nHost: {hostport}\r\nUser-Agent: rosnet-tui\r\n"
            f"Content-Type: text/xml\r\nContent-Length: {len(body)}\r\n"
            "Connection: close\r\n\r\n").encode("latin-1")
    sock = socket.create_connection((host, port), timeout=timeout)
    try:
        sock.sendall(head + body)
        with sock.makefile("rb") as rfile:
            first, _, answer = read_http(rfile, response=True)
    finally:
        sock.close()
    if first[1] != "200":
        raise HttpError(int(first[1]) if first[1].isascii() and first[1].isdigit() else 0,
                        first[2] if len(first) > 2 else "")
    _, params, fault = load_xmlrpc(answer)
    if fault:
        f = params[0] if params and isinstance(params[0], dict) else {}
        raise XmlRpcFault(f.get("faultCode"), f.get("faultString"))
    if len(params) != 1:
        raise XmlRpcError(f"an answer with {len(params)} values, not 1")
    return params[0]


def ros_call(uri: str, method: str, *args: Any, timeout: float = 3.0) -> Any:
    """A ROS API call: returns the value of a [code, statusMessage, value] answer with code 1,
    raises MasterCallError otherwise (and socket/XML-RPC errors as they come)."""
    answer = xmlrpc_call(uri, method, *args, timeout=timeout)
    if not isinstance(answer, (list, tuple)) or len(answer) != 3:
        raise ValueError(f"{method} answered {answer!r}, not [code, message, value]")
    code, message, value = answer
    if code != 1:
        raise MasterCallError(method, int(code), str(message))
    return value


class SystemState(Record):
    publishers: List[Tuple[str, List[str]]]
    subscribers: List[Tuple[str, List[str]]]
    services: List[Tuple[str, List[str]]]

    @property
    def nodes(self) -> List[str]:
        names = set()
        for group in (self.publishers, self.subscribers, self.services):
            for _, nodes in group:
                names.update(nodes)
        return sorted(names)

    @property
    def topics(self) -> List[str]:
        return sorted({t for t, _ in self.publishers} | {t for t, _ in self.subscribers})

    def publishers_of(self, topic: str) -> List[str]:
        return next((list(n) for t, n in self.publishers if t == topic), [])


class MasterClient:
    """The ROS Master API (wiki ROS/Master_API) over XML-RPC, every call under *timeout*."""

    def __init__(self, uri: str, caller_id: str = "/rosnet_tui", timeout: float = 3.0) -> None:
        self.uri = uri
        self.caller_id = caller_id
        self.timeout = timeout

    def _call(self, method: str, *args: Any, timeout: Optional[float] = None) -> Any:
        return ros_call(self.uri, method, self.caller_id, *args,
                        timeout=self.timeout if timeout is None else timeout)

    def get_system_state(self, timeout: Optional[float] = None) -> SystemState:
        pubs, subs, srvs = self._call("getSystemState", timeout=timeout)
        conv = lambda g: [(str(t), [str(n) for n in nodes]) for t, nodes in g]  # noqa: E731
        return SystemState(conv(pubs), conv(subs), conv(srvs))

    def get_topic_types(self, timeout: Optional[float] = None) -> List[Tuple[str, str]]:
        return [(str(t), str(ty)) for t, ty in self._call("getTopicTypes", timeout=timeout)]

    def get_uri(self, timeout: Optional[float] = None) -> str:
        return str(self._call("getUri", timeout=timeout))

    def lookup_node(self, node: str, timeout: Optional[float] = None) -> str:
        return str(self._call("lookupNode", node, timeout=timeout))

    def register_publisher(self, topic: str, topic_type: str, caller_api: str,
                           timeout: Optional[float] = None) -> List[str]:
        """Returns the XML-RPC URIs of the topic's current subscribers."""
        return [str(u) for u in self._call("registerPublisher", topic, topic_type, caller_api,
                                           timeout=timeout)]

    def unregister_publisher(self, topic: str, caller_api: str,
                             timeout: Optional[float] = None) -> int:
        return int(self._call("unregisterPublisher", topic, caller_api, timeout=timeout))

    def register_subscriber(self, topic: str, topic_type: str, caller_api: str,
                            timeout: Optional[float] = None) -> List[str]:
        """Returns the XML-RPC URIs of the topic's current publishers."""
        return [str(u) for u in self._call("registerSubscriber", topic, topic_type, caller_api,
                                           timeout=timeout)]

    def unregister_subscriber(self, topic: str, caller_api: str,
                              timeout: Optional[float] = None) -> int:
        return int(self._call("unregisterSubscriber", topic, caller_api, timeout=timeout))


def request_topic(slave_uri: str, caller_id: str, topic: str, timeout: float = 3.0
                  ) -> Tuple[str, int]:
    """Slave API requestTopic asking for TCPROS; returns the (host, port) to connect to."""
    params = ros_call(slave_uri, "requestTopic", caller_id, topic, [["TCPROS"]], timeout=timeout)
    if not params or params[0] != "TCPROS" or len(params) < 3:
        raise ValueError(f"requestTopic offered {params!r}, not TCPROS host port")
    return str(params[1]), int(params[2])


# --------------------------------------------------------------------------- TCPROS
def encode_header(fields: Dict[str, str]) -> bytes:
    """A connection header: 4-byte length, then per field a 4-byte length and b"name=value"
    (all lengths little-endian; wiki ROS/Connection Header)."""
    body = b""
    for k, v in fields.items():
        item = f"{k}={v}".encode()
        body += struct.pack("<I", len(item)) + item
    return struct.pack("<I", len(body)) + body


def decode_header(body: bytes) -> Dict[str, str]:
    fields: Dict[str, str] = {}
    i = 0
    while i < len(body):
        if i + 4 > len(body):
            raise ValueError("truncated connection header")
        (n,) = struct.unpack_from("<I", body, i)
        i += 4
        if i + n > len(body):
            raise ValueError("truncated connection header field")
        item = body[i:i + n].decode("utf-8", "replace")
        i += n
        k, sep, v = item.partition("=")
        if not sep:
            raise ValueError(f"header field without '=': {item[:40]!r}")
        fields[k] = v
    return fields


def recv_exact(sock: socket.socket, n: int) -> bytes:
    buf = bytearray()
    while len(buf) < n:
        chunk = sock.recv(n - len(buf))
        if not chunk:
            raise ConnectionResetError("the connection closed early")
        buf += chunk
    return bytes(buf)


def read_frame(sock: socket.socket, limit: int = MAX_MESSAGE) -> bytes:
    (n,) = struct.unpack("<I", recv_exact(sock, 4))
    if n > limit:
        raise ValueError(f"a frame of {n} bytes is too large for a probe")
    return recv_exact(sock, n)


def read_header(sock: socket.socket) -> Dict[str, str]:
    return decode_header(read_frame(sock, MAX_HEADER))


def encode_string(text: str) -> bytes:
    """A std_msgs/String message as sent on the wire: frame length, then string length + bytes."""
    data = text.encode("utf-8")
    body = struct.pack("<I", len(data)) + data
    return struct.pack("<I", len(body)) + body


def decode_string(body: bytes) -> str:
    (n,) = struct.unpack_from("<I", body, 0)
    if 4 + n > len(body):
        raise ValueError("truncated std_msgs/String")
    return body[4:4 + n].decode("utf-8", "replace")


def subscriber_header(caller_id: str, topic: str) -> Dict[str, str]:
    return {"message_definition": STRING_DEFINITION, "callerid": caller_id, "topic": topic,
            "md5sum": STRING_MD5, "type": STRING_TYPE, "tcp_nodelay": "1"}


def publisher_header(caller_id: str, topic: str) -> Dict[str, str]:
    return {"callerid": caller_id, "topic": topic, "md5sum": STRING_MD5, "type": STRING_TYPE,
            "message_definition": STRING_DEFINITION, "latching": "0"}


# --------------------------------------------------------------------------- reports
class Hop(Record):
    hop: str            # registration | xmlrpc_callback | tcpros | no_message | info
    ok: bool
    detail: str


class ProbeReport(Record):
    """What one probe node saw. failed_hop/node/uri name the first hop that failed and whose
    advertised address it was (for registration: our node and the master's URI)."""

    role: str
    topic: str
    master_uri: str
    caller_id: str = ""
    advertised_uri: str = ""
    advertised_from: str = ""
    ok: bool = False
    failed_hop: Optional[str] = None
    node: Optional[str] = None
    uri: Optional[str] = None
    hops: List[Hop] = _NEW_LIST  # type: ignore[assignment]
    received: Optional[str] = None
    sent: int = 0
    served: int = 0

    def add(self, hop: str, ok: bool, detail: str) -> None:
        self.hops.append(Hop(hop, ok, detail))

    def fail(self, hop: str, detail: str, node: Optional[str] = None,
             uri: Optional[str] = None) -> None:
        self.add(hop, False, detail)
        if self.failed_hop is None:
            self.failed_hop, self.node, self.uri = hop, node, uri
        self.ok = False

    def to_json(self) -> Dict[str, Any]:
        out = self.to_dict()
        out[REPORT_KEY] = 1
        return out

    @classmethod
    def from_json(cls, data: Dict[str, Any]) -> ProbeReport:
        known = {k: data.get(k) for k, _ in cls.FIELDS if k in data and k != "hops"}
        rep = cls(**known)
        rep.hops = [Hop(str(h.get("hop")), bool(h.get("ok")), str(h.get("detail")))
                    for h in data.get("hops") or []]
        return rep

    def evidence(self, where: str = "") -> List[str]:
        """One line per hop, e.g. "turtlebot xmlrpc_callback: FAILED - ..."."""
        prefix = f"{where} " if where else ""
        return [f"{prefix}{h.hop}: {'ok' if h.ok else 'FAILED'} - {h.detail}" for h in self.hops]


def parse_report_line(stdout: str) -> Optional[Dict[str, Any]]:
    """The last JSON report line in *stdout* of a remote run, or None."""
    for line in reversed((stdout or "").splitlines()):
        line = line.strip()
        if line.startswith("{"):
            try:
                data = json.loads(line)
            except (ValueError, RecursionError):   # stdlib only: too deep is a decode error
                continue
            if isinstance(data, dict) and data.get(REPORT_KEY):
                return data
    return None


# --------------------------------------------------------------------------- slave server
class _Handler(socketserver.StreamRequestHandler):
    """One XML-RPC request per connection, answered with HTTP/1.0 and closed (what Python's
    SimpleXMLRPCServer does, which rospy and roscore speak to)."""

    timeout = 5              # a slow caller cannot hold a thread for long

    def handle(self) -> None:
        try:
            first, _, body = read_http(self.rfile, response=False)
        except (OSError, ValueError):
            return
        if first[0] != "POST":
            self._send(501, "Unsupported method", b"")
            return
        _caller.addr = self.client_address
        try:
            method, params, _ = load_xmlrpc(body)
            fn = self.server.functions.get(method or "")  # type: ignore[attr-defined]
            if fn is None:
                raise LookupError(f'method "{method}" is not supported')
            answer = dump_response(fn(*params))
        except Exception as exc:
            answer = dump_fault(1, f"{type(exc)}:{exc}")
        self._send(200, "OK", answer)

    def _send(self, code: int, reason: str, body: bytes) -> None:
        head = (f"HTTP/1.0 {code} {reason}\r\nServer: rosnet-tui\r\n"
                f"Content-Type: text/xml\r\nContent-Length: {len(body)}\r\n\r\n")
        try:
            self.wfile.write(head.encode("latin-1") + body)
        except OSError:
            pass


_caller = threading.local()


class _Server(socketserver.ThreadingTCPServer):
    daemon_threads = True
    block_on_close = False   # closing never waits for a slow caller
    allow_reuse_address = True

    def __init__(self, addr: Tuple[str, int]) -> None:
        self.functions: Dict[str, Any] = {}
        super().__init__(addr, _Handler)

    def register_function(self, fn: Any, name: str) -> None:
        self.functions[name] = fn


class ProbeNode:
    """A ROS node of our own for the probe's duration: a Slave API server on an ephemeral port,
    advertised the way a node started in *env* would advertise itself."""

    def __init__(self, master_uri: str, topic: str, role: str, *,
                 env: Optional[Dict[str, str]] = None, bashrc: Optional[str] = None,
                 call_timeout: float = 2.0, probe_id: Optional[str] = None) -> None:
        self.master_uri = master_uri
        self.topic = topic
        self.probe_id = probe_id or new_probe_id()
        self.caller_id = probe_caller_id(role, self.probe_id)
        self.call_timeout = call_timeout
        self.host, self.host_from = advertised_host(env, bashrc)
        self.bind = bind_address(self.host)
        self.master = MasterClient(master_uri, self.caller_id, call_timeout)
        self.report = ProbeReport(role, topic, master_uri, self.caller_id,
                                  advertised_from=self.host_from)
        self.stopping = threading.Event()
        self.updates = threading.Event()    # a publisherUpdate arrived
        self.callbacks: List[str] = []
        self.uri = ""
        self._lock = threading.Lock()
        self._server: Optional[_Server] = None
        self._threads: List[threading.Thread] = []

    # Slave API ---------------------------------------------------------------
    def _who(self, caller_id: str) -> str:
        addr = getattr(_caller, "addr", None)
        return f"{caller_id} from {addr[0]}:{addr[1]}" if addr else str(caller_id)

    def _request_topic(self, caller_id: str, topic: str, protocols: Any) -> List[Any]:
        return [-1, f"{self.caller_id} publishes nothing", []]

    def _publisher_update(self, caller_id: str, topic: str, publishers: Any) -> List[Any]:
        with self._lock:
            self.callbacks.append(f"publisherUpdate for {topic} by {self._who(caller_id)}")
        if topic == self.topic:
            self.updates.set()
        return [1, "", 0]

    def _shutdown(self, caller_id: str, msg: str = "") -> List[Any]:
        with self._lock:
            self.callbacks.append(f"shutdown requested by {self._who(caller_id)}: {msg}")
        self.stopping.set()
        return [1, "shutdown", 0]

    def _register(self, server: _Server) -> None:
        server.register_function(self._request_topic, "requestTopic")
        server.register_function(self._publisher_update, "publisherUpdate")
        server.register_function(self._shutdown, "shutdown")
        server.register_function(lambda c: [1, "", os.getpid()], "getPid")
        server.register_function(lambda c: [1, "", self.master_uri], "getMasterUri")
        server.register_function(lambda c: [1, "", []], "getBusInfo")
        server.register_function(lambda c: [1, "", []], "getBusStats")
        server.register_function(lambda c, *a: [1, "", 0], "paramUpdate")
        server.register_function(self._publications, "getPublications")
        server.register_function(self._subscriptions, "getSubscriptions")

    def _publications(self, caller_id: str) -> List[Any]:
        return [1, "", []]

    def _subscriptions(self, caller_id: str) -> List[Any]:
        return [1, "", []]

    def _thread(self, target: Any, *args: Any) -> threading.Thread:
        t = threading.Thread(target=target, args=args, daemon=True)
        t.start()
        self._threads.append(t)
        return t

    def start_server(self) -> None:
        server = _Server((self.bind, 0))
        self._register(server)
        self._server = server
        port = server.server_address[1]
        self.uri = f"http://{self.host}:{port}/"
        self.report.advertised_uri = self.uri
        self._thread(server.serve_forever, 0.02)   # stop_server waits at most this long

    def stop_server(self) -> None:
        self.stopping.set()
        if self._server is not None:
            self._server.shutdown()
            self._server.server_close()
            self._server = None

    def node_of(self, uri: str, deadline: float) -> Optional[str]:
        """The node whose Slave API is *uri*, asking the master (best effort, bounded)."""
        ct = self.call_timeout
        try:
            state = self.master.get_system_state(timeout=_left(deadline, ct))
            for node in state.publishers_of(self.topic):
                if same_uri(self.master.lookup_node(node, timeout=_left(deadline, ct)), uri):
                    return node
        except Exception:
            pass
        return None


def _left(deadline: float, cap: float, floor: float = 0.2) -> float:
    return max(floor, min(cap, deadline - time.monotonic()))


def same_uri(a: str, b: str) -> bool:
    """Whether two ROS URIs name the same endpoint (a trailing slash does not matter)."""
    return a.rstrip("/") == b.rstrip("/")


class ProbePublisher(ProbeNode):
    """Publishes std_msgs/String on *topic* to every subscriber that completes the TCPROS
    handshake, every *period* seconds, until stopped."""

    def __init__(self, master_uri: str, topic: str, **kw: Any) -> None:
        self.period = kw.pop("period", 0.1)
        self.prompt = kw.pop("prompt", True)     # the first message right after the handshake
        super().__init__(master_uri, topic, "pub", **kw)
        self._tcp: Optional[socket.socket] = None
        self._conns: List[Tuple[socket.socket, str]] = []
        self._per_conn: Dict[str, int] = {}
        self.registered = False
        self.master_error: Optional[str] = None  # describe_error kind when the master failed
        self._stopped = False
        self.served_closed = threading.Event()  # a subscriber got messages, then hung up
        self._sent = 0                           # messages numbered across subscribers

    def _request_topic(self, caller_id: str, topic: str, protocols: Any) -> List[Any]:
        who = self._who(caller_id)
        if topic != self.topic:
            return [-1, f"not a publisher of {topic}", []]
        if not any(p and p[0] == "TCPROS" for p in protocols or []):
            self.report.add("xmlrpc_callback", False, f"requestTopic by {who} offered no TCPROS")
            return [0, "no supported protocol implementations", []]
        port = self._tcp.getsockname()[1] if self._tcp else 0
        with self._lock:
            self.report.add("xmlrpc_callback", True,
                            f"requestTopic by {who} reached {self.uri}; answered TCPROS "
                            f"{self.host}:{port}")
        return [1, f"ready on {self.host}:{port}", ["TCPROS", self.host, port]]

    def _publications(self, caller_id: str) -> List[Any]:
        return [1, "", [[self.topic, STRING_TYPE]]]

    def start(self) -> bool:
        """Serve the Slave API and TCPROS, then register with the master. False when the
        registration failed (see the report)."""
        deadline = time.monotonic() + self.call_timeout
        if self.stopping.is_set():
            return False
        try:
            self._tcp = socket.create_server((self.bind, 0))
            self._tcp.settimeout(0.2)
            self.start_server()
        except OSError as exc:
            self.report.fail("registration",
                             f"cannot listen on {self.bind}: {describe_error(exc)[1]}",
                             self.caller_id, self.master_uri)
            return False
        try:
            subs = self.master.register_publisher(self.topic, STRING_TYPE, self.uri,
                                                  timeout=_left(deadline, self.call_timeout))
        except Exception as exc:
            self.master_error, words = describe_error(exc, self.call_timeout)
            self.report.fail("registration",
                             f"registerPublisher {self.topic} at {self.master_uri} failed: "
                             f"{words}", self.caller_id, self.master_uri)
            return False
        if self.stopping.is_set():  # stopped while we waited for the master: undo, quietly
            try:
                self.master.unregister_publisher(self.topic, self.uri,
                                                 timeout=min(1.0, self.call_timeout))
            except Exception:
                pass
            self._close()
            return False
        self.registered = True
        self.report.add("registration", True,
                        f"{self.caller_id} registered as publisher of {self.topic} with "
                        f"{self.master_uri}, advertising {self.uri} (host from "
                        f"{self.host_from}); {len(subs)} subscriber(s) known")
        self._thread(self._accept_loop)
        self._thread(self._publish_loop)
        return True

    def _accept_loop(self) -> None:
        assert self._tcp is not None
        while not self.stopping.is_set():
            try:
                conn, addr = self._tcp.accept()
            except socket.timeout:
                continue
            except OSError:
                return
            self._thread(self._handshake, conn, addr)

    def _handshake(self, conn: socket.socket, addr: Tuple[str, int]) -> None:
        conn.settimeout(max(0.5, self.call_timeout))
        where = f"{addr[0]}:{addr[1]}"
        try:
            hdr = read_header(conn)
            caller = hdr.get("callerid", "?")
            error = None
            if hdr.get("topic") != self.topic:
                error = f"topic {hdr.get('topic')!r} is not published here"
            elif hdr.get("md5sum") not in (STRING_MD5, "*"):
                error = f"md5sum {hdr.get('md5sum')} does not match {STRING_TYPE}"
            if error:
                conn.sendall(encode_header({"error": error}))
                self.report.add("tcpros", False, f"TCPROS from {caller} at {where}: {error}")
                conn.close()
                return
            conn.sendall(encode_header(publisher_header(self.caller_id, self.topic)))
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        except Exception as exc:
            self.report.add("tcpros", False,
                            f"TCPROS handshake from {where} failed: {describe_error(exc)[1]}")
            conn.close()
            return
        with self._lock:
            self.report.add("tcpros", True, f"TCPROS connection from {caller} at {where}: "
                                            "handshake done")
            self._conns.append((conn, caller))
        if self.prompt:
            try:   # the first message at once; then every period
                self._send(conn, caller)
            except OSError:
                pass    # the publish loop notices the hang-up

    def _send(self, conn: socket.socket, caller: str) -> None:
        # Counted before it leaves: the subscriber may read it and hang up before this thread
        # runs again, and the publish loop must then find it counted (served), or the probe
        # would wait for another subscriber to its timeout. A failed send is taken back.
        with self._lock:
            self._sent += 1
            frame = encode_string(f"rosnet-tui probe {self._sent} from {self.caller_id}")
            self.report.sent += 1
            self._per_conn[caller] = self._per_conn.get(caller, 0) + 1
        try:
            conn.sendall(frame)
        except OSError:
            with self._lock:
                self.report.sent -= 1
                self._per_conn[caller] -= 1
            raise

    def _publish_loop(self) -> None:
        while not self.stopping.is_set():
            with self._lock:
                conns = list(self._conns)
            if not conns:
                self.stopping.wait(min(self.period, 0.02))
                continue
            # Sleep a period, but wake at once when a subscriber hangs up (its socket becomes
            # readable at EOF): a served subscriber ends the probe without waiting.
            try:
                readable, _, _ = select.select([c for c, _ in conns], [], [], self.period)
            except (OSError, ValueError):
                readable = [c for c, _ in conns]
            if self.stopping.is_set():
                return
            for conn, caller in conns:
                gone = False
                try:
                    if conn in readable:
                        gone = not conn.recv(1)
                    else:
                        self._send(conn, caller)
                except OSError:
                    gone = True
                if gone:
                    with self._lock:
                        if (conn, caller) in self._conns:
                            self._conns.remove((conn, caller))
                    conn.close()
                    got = self._per_conn.get(caller, 0)
                    self.report.add("info", True,
                                    f"subscriber {caller} hung up after {got} message(s) sent")
                    if got:
                        self.report.served += 1
                        self.served_closed.set()

    def _close(self) -> None:
        """Close the subscriber connections, the TCPROS socket and the Slave API (idempotent)."""
        with self._lock:
            conns, self._conns = list(self._conns), []
        for conn, caller in conns:
            if self._per_conn.get(caller):
                self.report.served += 1
            conn.close()
        if self._tcp is not None:
            try:     # wakes the accept loop at once (a plain close would not)
                self._tcp.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            self._tcp.close()
        self.stop_server()

    def wait_served(self, timeout: float) -> bool:
        """True once a subscriber received messages and hung up, within *timeout*."""
        end = time.monotonic() + timeout
        while time.monotonic() < end and not self.stopping.is_set():
            if self.served_closed.wait(min(0.1, max(0.0, end - time.monotonic()))):
                return True
        return self.served_closed.is_set()

    def stop(self) -> ProbeReport:
        """Unregister (bounded), close everything; the report says what was seen."""
        if self._stopped:
            return self.report
        self._stopped = True
        self.stopping.set()
        if self.registered:
            try:
                self.master.unregister_publisher(self.topic, self.uri,
                                                 timeout=min(1.0, self.call_timeout))
            except Exception:
                pass
        self._close()
        for t in self._threads:
            t.join(timeout=0.5)
        rep = self.report
        with self._lock:
            for c in self.callbacks:
                rep.add("info", True, c)
        if not any(h.hop == "xmlrpc_callback" for h in rep.hops) and rep.failed_hop is None:
            rep.add("info", True, f"no subscriber called requestTopic on {self.uri}")
        rep.ok = rep.failed_hop is None and rep.served > 0
        return rep


class ProbeSubscriber(ProbeNode):
    """Subscribes to *topic* and waits for one std_msgs/String, hop by hop."""

    def __init__(self, master_uri: str, topic: str, **kw: Any) -> None:
        super().__init__(master_uri, topic, "sub", **kw)

    def _subscriptions(self, caller_id: str) -> List[Any]:
        return [1, "", [[self.topic, STRING_TYPE]]]

    def run(self, timeout: float) -> ProbeReport:
        """Register, find the publishers (registerSubscriber's answer, publisherUpdate, or
        asking the master again), call requestTopic, connect TCPROS, read one message."""
        deadline = time.monotonic() + timeout
        rep = self.report
        try:
            self.start_server()
        except OSError as exc:
            rep.fail("registration", f"cannot listen on {self.bind}: {describe_error(exc)[1]}",
                     self.caller_id, self.master_uri)
            return rep
        registered = False
        try:
            try:
                pubs = self.master.register_subscriber(
                    self.topic, STRING_TYPE, self.uri, timeout=_left(deadline, self.call_timeout))
                registered = True
            except Exception as exc:
                rep.fail("registration", f"registerSubscriber {self.topic} at {self.master_uri} "
                                         f"failed: {describe_error(exc, self.call_timeout)[1]}",
                         self.caller_id, self.master_uri)
                return rep
            rep.add("registration", True,
                    f"{self.caller_id} registered as subscriber of {self.topic} with "
                    f"{self.master_uri}, advertising {self.uri} (host from {self.host_from}); "
                    f"{len(pubs)} publisher(s) known")
            self._follow(pubs, deadline)
        finally:
            if registered:
                try:
                    self.master.unregister_subscriber(self.topic, self.uri,
                                                      timeout=min(1.0, self.call_timeout))
                except Exception:
                    pass
            self.stop_server()
            with self._lock:
                for c in self.callbacks:
                    rep.add("info", True, c)
        return rep

    def _follow(self, pubs: List[str], deadline: float) -> None:
        rep = self.report
        tried: Dict[str, int] = {}
        while time.monotonic() < deadline and not self.stopping.is_set():
            fresh = [u for u in pubs if tried.get(u, 0) < 2]
            for uri in fresh:
                tried[uri] = tried.get(uri, 0) + 1
                final = tried[uri] >= 2
                if self._try_publisher(uri, deadline, final):
                    return
            # Wait for a publisherUpdate, or ask the master again (both name only publishers the
            # master knows: we never connect to an address a caller handed us).
            self.updates.wait(min(0.3, max(0.0, deadline - time.monotonic())))
            via_callback = self.updates.is_set()
            self.updates.clear()
            try:
                known = self._publisher_uris(deadline)
            except Exception as exc:
                if time.monotonic() >= deadline - 0.05:
                    break
                rep.add("info", False, f"asking the master for publishers failed: "
                                       f"{describe_error(exc)[1]}")
                continue
            new = [u for u in known if u not in pubs]
            if new:
                how = "a publisherUpdate callback" if via_callback else "asking the master again"
                rep.add("info", True, f"learned of publisher(s) {', '.join(new)} via {how}")
            elif rep.failed_hop is not None and all(tried.get(u, 0) >= 2 for u in known):
                break  # every publisher known has failed for good
            pubs = known
        if rep.failed_hop is None:
            if not tried:
                rep.fail("registration", f"no publisher of {self.topic} registered with "
                                         f"{self.master_uri} within the time allowed",
                         None, self.master_uri)
            elif not rep.received:
                rep.fail("no_message", f"no message on {self.topic} within the time allowed")

    def _publisher_uris(self, deadline: float) -> List[str]:
        state = self.master.get_system_state(timeout=_left(deadline, self.call_timeout))
        uris = []
        for node in state.publishers_of(self.topic):
            uris.append(self.master.lookup_node(node, timeout=_left(deadline, self.call_timeout)))
        return uris

    def _try_publisher(self, uri: str, deadline: float, final: bool) -> bool:
        """One attempt at a publisher; True once a message arrived. A failed hop is recorded as
        the verdict only on the *final* attempt (or when time is up)."""
        rep = self.report
        t = _left(deadline, self.call_timeout)
        try:
            host, port = request_topic(uri, self.caller_id, self.topic, timeout=t)
        except Exception as exc:
            kind, words = describe_error(exc, t)
            detail = f"requestTopic to {uri} failed: {words}"
            if kind == "resolve":
                detail = f"requestTopic to {uri} failed: '{_host_of(uri)}' does not resolve here"
            self._hop_failed("xmlrpc_callback", detail, uri, deadline, final)
            return False
        rep.add("xmlrpc_callback", True, f"requestTopic to {uri} answered TCPROS {host}:{port}")
        t = _left(deadline, self.call_timeout)
        try:
            sock = socket.create_connection((host, port), timeout=t)
        except Exception as exc:
            kind, words = describe_error(exc, t)
            if kind == "resolve":
                words = f"'{host}' does not resolve here"
            self._hop_failed("tcpros", f"TCPROS connection to {host}:{port} failed: {words}",
                             uri, deadline, final)
            return False
        try:
            sock.settimeout(_left(deadline, self.call_timeout))
            sock.sendall(encode_header(subscriber_header(self.caller_id, self.topic)))
            hdr = read_header(sock)
            if "error" in hdr:
                self._hop_failed("tcpros", f"the publisher at {host}:{port} refused the "
                                           f"subscription: {hdr['error']}", uri, deadline, True)
                return False
            if hdr.get("md5sum") not in (STRING_MD5, "*"):
                self._hop_failed("tcpros", f"the publisher at {host}:{port} sends "
                                           f"{hdr.get('type')} (md5sum {hdr.get('md5sum')}), "
                                           f"not {STRING_TYPE}", uri, deadline, True)
                return False
            rep.add("tcpros", True, f"TCPROS handshake with {hdr.get('callerid', '?')} at "
                                    f"{host}:{port} done")
            while time.monotonic() < deadline:
                sock.settimeout(_left(deadline, 60.0, 0.05))
                try:
                    body = read_frame(sock)
                except (socket.timeout, TimeoutError):
                    break
                rep.received = decode_string(body)
                rep.add("no_message", True, f"received {rep.received!r}")
                # A message arrived: the path works (an earlier publisher may still have failed).
                rep.failed_hop = rep.node = rep.uri = None
                rep.ok = True
                return True
            self._hop_failed("no_message", f"connected to {host}:{port} but no message "
                                           "arrived in time", uri, deadline, True)
            return False
        except Exception as exc:
            self._hop_failed("tcpros", f"TCPROS exchange with {host}:{port} failed: "
                                       f"{describe_error(exc)[1]}", uri, deadline, final)
            return False
        finally:
            sock.close()

    def _hop_failed(self, hop: str, detail: str, uri: str, deadline: float, final: bool) -> None:
        if not final and deadline - time.monotonic() > 0.5:
            self.report.add("info", False, f"{detail} (will retry)")
            time.sleep(0.2)
            return
        self.report.fail(hop, detail, self.node_of(uri, deadline), uri)


def _host_of(uri: str) -> str:
    try:
        return split_uri(uri)[0]
    except ValueError:
        return uri


# --------------------------------------------------------------------------- one-shot probes
def run_subscriber(master_uri: str, topic: str, timeout: float, *,
                   env: Optional[Dict[str, str]] = None, bashrc: Optional[str] = None,
                   call_timeout: Optional[float] = None) -> ProbeReport:
    """Subscribe with a fresh probe node until one message arrives or *timeout* passes."""
    ct = call_timeout or max(0.5, min(3.0, timeout / 3))
    return ProbeSubscriber(master_uri, topic, env=env, bashrc=bashrc, call_timeout=ct).run(timeout)


def run_publisher(master_uri: str, topic: str, timeout: float, *,
                  env: Optional[Dict[str, str]] = None, bashrc: Optional[str] = None,
                  exit_after_served: bool = True, call_timeout: Optional[float] = None,
                  on_ready: Any = None) -> ProbeReport:
    """Publish with a fresh probe node for *timeout* seconds (or until a subscriber that got
    messages hangs up, with *exit_after_served*). *on_ready(pub)* runs once registered."""
    ct = call_timeout or max(0.5, min(3.0, timeout / 3))
    pub = ProbePublisher(master_uri, topic, env=env, bashrc=bashrc, call_timeout=ct)
    end = time.monotonic() + timeout
    if pub.start():
        if on_ready is not None:
            on_ready(pub)
        if exit_after_served:
            pub.wait_served(max(0.0, end - time.monotonic()))
        else:
            pub.stopping.wait(max(0.0, end - time.monotonic()))
    return pub.stop()


class NodeReach(Record):
    node: str
    uri: str = ""
    host: str = ""
    port: int = 0
    ip: str = ""
    reachable: Optional[bool] = None   # None: no verdict (the lookup failed, or no time left)
    reason: str = ""


def _twice(fn: Any, deadline: float, cap: float) -> Any:
    """fn(timeout) once more after a timeout or reset when time allows: a lost packet on a lossy
    link costs a retransmission, not a verdict."""
    try:
        return fn(_left(deadline, cap))
    except (socket.timeout, TimeoutError, ConnectionResetError):
        if deadline - time.monotonic() < 0.3:
            raise
    return fn(_left(deadline, cap))


def check_node_uris(master_uri: str, timeout: float, *, include: Iterable[str] = (),
                    exclude_prefix: str = PROBE_PREFIX, workers: int = 16) -> Dict[str, Any]:
    """Every node the master knows: lookupNode, resolve its URI's host, TCP-connect to it.

    Probe nodes of rosnet-tui (names starting with *exclude_prefix*) are left out unless listed
    in *include*. Returns {"ok", "error", "nodes": [NodeReach as dict], "excluded": [...]};
    a node's ``reachable`` is True, False (with the reason) or None (no verdict, with why).
    """
    deadline = time.monotonic() + timeout
    ct = max(0.3, min(3.0, timeout / 2))
    master = MasterClient(master_uri, "/rosnet_tui_nodes", ct)
    out: Dict[str, Any] = {"master": master_uri, "ok": False, "error": None, "nodes": [],
                           "excluded": []}
    try:
        state = _twice(master.get_system_state, deadline, ct)
    except Exception as exc:
        out["error"] = f"getSystemState at {master_uri} failed: {describe_error(exc, ct)[1]}"
        return out
    keep = set(include)
    names = [n for n in state.nodes if n in keep or not n.startswith(exclude_prefix)]
    out["excluded"] = [n for n in state.nodes if n not in names]
    for n in keep:
        if n not in names:
            names.append(n)

    def one(node: str) -> NodeReach:
        r = NodeReach(node)
        try:
            r.uri = _twice(lambda t: master.lookup_node(node, timeout=t), deadline, ct)
        except Exception as exc:
            r.reason = f"the master could not look it up: {describe_error(exc, ct)[1]}"
            return r
        try:
            r.host, r.port = split_uri(r.uri)
        except ValueError as exc:
            r.reachable, r.reason = False, str(exc)
            return r
        try:
            infos = socket.getaddrinfo(r.host, r.port, socket.AF_UNSPEC, socket.SOCK_STREAM)
            r.ip = infos[0][4][0]
        except Exception:
            r.reachable, r.reason = False, f"'{r.host}' does not resolve here"
            return r
        t = ct
        try:
            def connect(timeout: float) -> None:
                nonlocal t
                t = timeout
                socket.create_connection((r.ip, r.port), timeout=timeout).close()
            _twice(connect, deadline, ct)
            r.reachable = True
        except Exception as exc:
            r.reachable, r.reason = False, f"{r.ip}:{r.port}: {describe_error(exc, t)[1]}"
        return r

    # Plain daemon threads (concurrent.futures would cost this program's start ~5 ms of imports).
    todo, results, lock = list(names), {}, threading.Lock()

    def worker() -> None:
        while True:
            with lock:
                if not todo:
                    return
                name = todo.pop()
            r = one(name)
            with lock:
                results[name] = r

    threads = [threading.Thread(target=worker, daemon=True)
               for _ in range(max(1, min(workers, len(names))))]
    for t in threads:
        t.start()
    for t in threads:
        t.join(max(0.0, deadline - time.monotonic()))
    with lock:
        final = dict(results)
    for name in names:
        r = final.get(name) or NodeReach(name, reason="no verdict in time (timed out)")
        out["nodes"].append(r.to_dict())
    out["nodes"].sort(key=lambda d: d["node"])
    out["ok"] = all(d["reachable"] for d in out["nodes"])
    return out


# --------------------------------------------------------------------------- script mode
READY_KEY = "rosnet_probe_ready"


def _announce_ready(pub: ProbePublisher) -> None:
    """Tell whoever runs us (over SSH) that the publisher is registered and serving."""
    line = {READY_KEY: 1, "caller_id": pub.caller_id, "uri": pub.uri, "topic": pub.topic}
    sys.stdout.write(json.dumps(line) + "\n")
    sys.stdout.flush()


USAGE = ("usage: rosproto {sub|pub|nodes|whoami} [--master URI] [--timeout S] [--bashrc PATH]"
         " [--topic T (sub, pub)] [--linger (pub)] [--include NODE ... (nodes)]")


class _Args:
    cmd = ""
    master = ""
    timeout = 5.0
    bashrc = "~/.bashrc"     # rc file for ROS_IP/ROS_HOSTNAME absent from the environment
    topic = ""
    linger = False           # pub: publish for the whole timeout (default: stop once served)

    def __init__(self) -> None:
        self.include: List[str] = []


def parse_args(argv: List[str]) -> _Args:
    """The command line (argparse would cost every start ~7 ms of imports). ValueError when bad;
    ``--name value`` and ``--name=value`` both work."""
    args = _Args()
    if not argv or argv[0] not in ("sub", "pub", "nodes", "whoami"):
        raise ValueError("the first word must be sub, pub, nodes or whoami")
    args.cmd = argv[0]
    allowed = {"--master", "--timeout", "--bashrc"}
    allowed |= {"--topic"} if args.cmd in ("sub", "pub") else set()
    allowed |= {"--linger"} if args.cmd == "pub" else set()
    allowed |= {"--include"} if args.cmd == "nodes" else set()
    rest = list(argv[1:])
    while rest:
        word = rest.pop(0)
        name, eq, value = word.partition("=")
        if name not in allowed:
            raise ValueError(f"unrecognized argument {word!r}")
        if name == "--linger":
            if eq:
                raise ValueError("--linger takes no value")
            args.linger = True
            continue
        if not eq:
            if not rest:
                raise ValueError(f"{name} needs a value")
            value = rest.pop(0)
        if name == "--timeout":
            try:
                args.timeout = float(value)
            except ValueError:
                raise ValueError(f"--timeout: not a number: {value!r}") from None
            if args.timeout != args.timeout:
                raise ValueError("--timeout: not a number: nan")
        elif name == "--include":
            args.include.append(value)
        else:
            setattr(args, name[2:], value)
    if args.cmd in ("sub", "pub") and not args.topic:
        raise ValueError("--topic is required")
    return args


def main(argv: Optional[List[str]] = None) -> int:
    """``python3 - {sub|pub|nodes|whoami} ...``: run one probe, print one JSON line."""
    try:
        args = parse_args(sys.argv[1:] if argv is None else argv)
    except ValueError as exc:
        sys.stderr.write(f"{USAGE}\nrosproto: error: {exc}\n")
        return 2
    bashrc = os.path.expanduser(args.bashrc) if args.bashrc else None
    master = args.master or effective_ros_env(None, bashrc).get("ROS_MASTER_URI", ("", ""))[0]
    timeout = max(0.5, min(args.timeout, 600.0))
    result: Dict[str, Any] = {}

    def work() -> None:
        if args.cmd == "whoami":
            host, why = advertised_host(None, bashrc)
            result.update({REPORT_KEY: 1, "host": host, "from": why, "master": master,
                           "env": {k: v for k, (v, _) in effective_ros_env(None, bashrc).items()}})
        elif not master:
            result.update({REPORT_KEY: 1, "ok": False, "error": "no master URI given"})
        elif args.cmd == "sub":
            result.update(run_subscriber(master, args.topic, timeout, bashrc=bashrc).to_json())
        elif args.cmd == "pub":
            result.update(run_publisher(master, args.topic, timeout, bashrc=bashrc,
                                        exit_after_served=not args.linger,
                                        on_ready=_announce_ready).to_json())
        else:
            result.update(check_node_uris(master, timeout, include=args.include))
            result[REPORT_KEY] = 1

    worker = threading.Thread(target=work, daemon=True)
    worker.start()
    worker.join(timeout + 5.0)  # a watchdog: a hung name lookup must not hang the probe
    if not result:
        result = {REPORT_KEY: 1, "ok": False, "error": f"the probe did not finish within "
                                                       f"{timeout + 5.0:g} s"}
    sys.stdout.write(json.dumps(result) + "\n")
    sys.stdout.flush()
    code = 0 if result.get("ok", True) else 1
    if worker.is_alive():
        os._exit(code)  # do not wait for a thread stuck in a name lookup
    return code


if __name__ == "__main__":
    sys.exit(main())
