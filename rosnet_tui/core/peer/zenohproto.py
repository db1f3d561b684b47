"""ROS 2 over rmw_zenoh, on the wire: keys, liveliness tokens, attachments, CDR strings, and the
probe programs of the ros2.* checks.

What rmw_zenoh puts on the wire (its design document and ``liveliness_utils.cpp``):

- topic data under ``<domain>/<topic without leading slash>/<type>/<type hash>``, CDR payload,
  and a 33-byte attachment: int64 LE sequence number, int64 LE source timestamp (ns), one byte
  16 (the GID's length) and the 16-byte GID;
- the ROS graph as liveliness tokens ``@ros2_lv/<domain>/<zid>/<nid>/<id>/<kind>/<enclave>/
  <namespace>/<node>[/<topic>/<type>/<hash>/<qos>]``, kind NN (node), MP/MS (publisher,
  subscription), SS/SC (service server, client); ``/`` inside a field becomes ``%``.

Humble's rmw_zenoh writes ``TypeHashNotSupported`` where later distros write an RIHS01 hash, so
the two discover each other but never match each other's data keys.

This file runs on its own too (``<python> - sub|pub|graph ...`` fed on stdin over SSH), with the
interpreter of the rosnet-tui installed on the peer (its virtual environment has eclipse-zenoh;
peer/commands.py finds it), whatever that rosnet-tui's version. It imports only the standard
library at the top; ``zenoh`` is imported when a session is opened.
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import queue
import re
import secrets
import stat
import struct
import sys
import threading
import time
from typing import Any

STRING_TYPE = "std_msgs::msg::dds_::String_"
STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
HUMBLE_HASH = "TypeHashNotSupported"
LV_PREFIX = "@ros2_lv"
DEFAULT_QOS = "::,:,:,:,,"        # every QoS field at rmw's default
PROBE_PREFIX = "rosnet_tui_probe"  # the probes' node names start with it
REPORT_MARK = "ROSNET_ZENOH "
READY_MARK = "ROSNET_ZENOH_READY"
NO_ZENOH_EXIT = 3                  # the peer program's exit status when zenoh is missing
ENV_KEYS = ("RMW_IMPLEMENTATION", "ROS_DOMAIN_ID", "ROS_DISTRO", "ZENOH_CONFIG_OVERRIDE",
            "ZENOH_ROUTER_CONFIG_URI", "ZENOH_SESSION_CONFIG_URI")


# --------------------------------------------------------------------------- names and keys
def mangle(field: str) -> str:
    """A name as a key chunk: ``/`` becomes ``%`` (an empty name, or ``/``, becomes ``%``)."""
    return field.replace("/", "%") or "%"


def demangle(chunk: str) -> str:
    return chunk.replace("%", "/")


def topic_key(domain: int, topic: str, type_name: str = STRING_TYPE,
              type_hash: str = STRING_HASH) -> str:
    """The data key of *topic* (``0/chatter/std_msgs::msg::dds_::String_/RIHS01_...``)."""
    return f"{domain}/{topic.strip('/')}/{type_name}/{type_hash}"


def node_token(domain: int, zid: str, nid: str, name: str, namespace: str = "/",
               enclave: str = "/") -> str:
    return (f"{LV_PREFIX}/{domain}/{zid}/{nid}/{nid}/NN/{mangle(enclave)}/{mangle(namespace)}/"
            f"{mangle(name)}")


def endpoint_token(domain: int, zid: str, nid: str, eid: str, kind: str, name: str, topic: str,
                   type_name: str = STRING_TYPE, type_hash: str = STRING_HASH,
                   namespace: str = "/", enclave: str = "/", qos: str = DEFAULT_QOS) -> str:
    if kind not in ("MP", "MS", "SS", "SC"):
        raise ValueError(f"unknown endpoint kind {kind!r}")
    return (f"{LV_PREFIX}/{domain}/{zid}/{nid}/{eid}/{kind}/{mangle(enclave)}/{mangle(namespace)}/"
            f"{mangle(name)}/{mangle(topic)}/{mangle(type_name)}/{mangle(type_hash)}/{qos}")


def ros_type(wire: str) -> str:
    """A type name as ROS 2 users write it (``ros2 topic list -t``): ``std_msgs/msg/String``
    for the DDS form on the wire, ``std_msgs::msg::dds_::String_``. The ``dds_`` part and its
    trailing ``_`` may be missing; anything else comes back as it was (never raises)."""
    text = str(wire)
    if "::" not in text:
        return text
    head, sep, last = text.rpartition("dds_::")
    if sep:                                   # <pkg>::<msg|srv|action>::dds_::<Type>_
        last = last[:-1] if last.endswith("_") and len(last) > 1 else last
    return "/".join(p for p in (head + last if sep else text).split("::") if p) or text


def parse_token(key: str) -> dict[str, Any] | None:
    """A liveliness token's fields, or None when *key* is not an rmw_zenoh token. The type of
    an endpoint is given as ROS 2 users write it (:func:`ros_type`)."""
    parts = str(key).split("/")
    if len(parts) < 9 or parts[0] != LV_PREFIX or not all(parts[:9]):
        return None
    kind = parts[5]
    out: dict[str, Any] = {"domain": parts[1], "zid": parts[2], "nid": parts[3], "id": parts[4],
                           "kind": kind, "enclave": demangle(parts[6]),
                           "namespace": demangle(parts[7]), "name": demangle(parts[8])}
    if kind == "NN":
        return out if len(parts) == 9 else None
    if kind not in ("MP", "MS", "SS", "SC") or len(parts) < 13:
        return None
    out.update(topic=demangle(parts[9]), type=ros_type(demangle(parts[10])),
               hash=demangle(parts[11]),
               qos="/".join(parts[12:]))
    return out


def fq_name(namespace: str, name: str) -> str:
    """``/ns/name`` (``/name`` in the root namespace)."""
    ns = namespace.rstrip("/")
    return f"{ns}/{name}" if ns else f"/{name}"


# --------------------------------------------------------------------------- payloads
def encode_string(text: str) -> bytes:
    """A std_msgs/String in CDR (little endian): header, uint32 length with the NUL, bytes, NUL."""
    data = text.encode("utf-8") + b"\0"
    return b"\x00\x01\x00\x00" + struct.pack("<I", len(data)) + data


def decode_string(payload: bytes) -> str | None:
    if len(payload) < 8 or payload[:2] != b"\x00\x01":
        return None
    (n,) = struct.unpack_from("<I", payload, 4)
    if n < 1 or 8 + n > len(payload):
        return None
    return payload[8:8 + n - 1].decode("utf-8", "replace")


def make_gid(token: str) -> bytes:
    """A 16-byte GID derived from an entity's token (rmw_zenoh hashes the token too)."""
    return hashlib.blake2b(token.encode(), digest_size=16).digest()


def encode_attachment(seq: int, ts_ns: int, gid: bytes) -> bytes:
    """The 33-byte attachment every rmw_zenoh message carries."""
    if len(gid) != 16:
        raise ValueError("a GID has 16 bytes")
    return struct.pack("<qqB", seq, ts_ns, 16) + gid


def decode_attachment(data: bytes | None) -> tuple[int, int, bytes] | None:
    """(sequence, timestamp ns, GID) of an attachment, or None when it is not rmw_zenoh's."""
    if data is None or len(data) != 33 or data[16] != 16:
        return None
    seq, ts = struct.unpack_from("<qq", data, 0)
    return seq, ts, bytes(data[17:33])


# --------------------------------------------------------------------------- the environment
_EXPORT = re.compile(r"""^\s*(?:export\s+)?([A-Z_][A-Z0-9_]*)=("[^"\n]*"|'[^'\n]*'|[^\s;#]*)""")



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

def read_exports(path: str) -> dict[str, str]:
    """``export NAME=value`` lines of a shell file (the last one of each name wins)."""
    out: dict[str, str] = {}
    try:
        lines = read_small_text(path, 512 * 1024).splitlines()
    except OSError:
        return out
    for line in lines:
        m = _EXPORT.match(line)
        if m:
            value = m.group(2)
            if len(value) >= 2 and value[0] == value[-1] and value[0] in "\"'":
                value = value[1:-1]
            out[m.group(1)] = value
    return out


_SOURCED = re.compile(r"^\s*(?:source|\.)\s+/opt/ros/([a-z]+)/(?:local_)?setup\.\w+", re.M)


def ros_env(env: dict[str, str] | None = None, bashrc: str | None = None) -> dict[str, str]:
    """The ROS 2 variables nodes started here get: the environment first, then ~/.bashrc (where
    ``source /opt/ros/<distro>/setup.bash`` gives ROS_DISTRO)."""
    env = dict(os.environ if env is None else env)
    path = bashrc or os.path.join(os.path.expanduser("~"), ".bashrc")
    rc = read_exports(path)
    if "ROS_DISTRO" not in rc:
        try:
            found = _SOURCED.findall(read_small_text(path, 512 * 1024))
            if found:
                rc["ROS_DISTRO"] = found[-1]
        except OSError:
            pass
    return {k: env.get(k, rc.get(k, "")) for k in ENV_KEYS if env.get(k, rc.get(k, ""))}


# --------------------------------------------------------------------------- sessions
class ZenohMissing(Exception):
    """The eclipse-zenoh package is not installed for this python3."""


class OpenFailed(Exception):
    """No Zenoh session could be opened on the endpoint (nothing answered, or not Zenoh)."""


def _zenoh():
    try:
        import zenoh  # noqa: PLC0415 - only when a session is needed
    except ImportError as exc:
        raise ZenohMissing(str(exc)) from None
    return zenoh


def open_client(endpoint: str, timeout: float, mode: str = "client",
                tls: dict[str, Any] | None = None) -> Any:
    """A session on *endpoint* within about *timeout* s, or OpenFailed.

    ``client`` (the default) talks to the router only. ``peer`` is what rmw_zenoh's nodes are: a
    peer attached to a router (listening on loopback only, as theirs do), so a probe meets the
    same routing as a real node, peer-mode traps included. Multicast and gossip scouting are off:
    the endpoint is the only way in.
    """
    zenoh = _zenoh()
    c = zenoh.Config()
    c.insert_json5("mode", json.dumps(mode))
    c.insert_json5("connect/endpoints", json.dumps([endpoint]))
    c.insert_json5("connect/timeout_ms", str(max(100, int(timeout * 1000))))
    c.insert_json5("connect/exit_on_failure", "true")
    c.insert_json5("scouting/multicast/enabled", "false")
    c.insert_json5("scouting/gossip/enabled", "false")
    try:   # as rmw_zenoh's nodes by default: payloads go on the wire, not in shared memory
        c.insert_json5("transport/shared_memory/enabled", "false")
    except Exception:  # noqa: BLE001, S110 - a zenoh built without shared memory
        pass
    # A probe's own hop to its router (loopback) is not the link measured: a large message's
    # fragments wait there up to 1 s for room, not 50 ms (a busy machine is no lost message).
    c.insert_json5("transport/link/tx/queue/congestion_control/drop/"
                   "max_wait_before_drop_fragments", "1000000")
    for key, value in (tls or {}).items():   # a tls/ endpoint: this component's certificate
        c.insert_json5(f"transport/link/tls/{key}", json.dumps(value))
    if mode == "peer":
        c.insert_json5("listen/endpoints", '["tcp/127.0.0.1:0"]')
        c.insert_json5("scouting/delay", "0")
    try:
        return zenoh.open(c)
    except Exception as exc:  # zenoh.ZError: the reason is in the text
        text = str(exc).split(" at /", 1)[0].strip()
        if text.startswith("Unable to connect"):
            text = (f"no Zenoh router answered at {endpoint} within {timeout:.1f} s (nothing "
                    "listens there, or the port is not reachable)")
            if endpoint.startswith("tls/"):
                text = (f"no Zenoh session over TLS at {endpoint} within {timeout:.1f} s "
                        "(nothing listens there, the port is not reachable, or the TLS handshake "
                        "failed: a certificate missing, expired or from another CA, or the "
                        "router's certificate does not name the host dialled)")
        raise OpenFailed(text or type(exc).__name__) from None


def control_priority() -> Any:
    """Zenoh's priority for small control messages, above the data queue (zenohlink's)."""
    return _zenoh().Priority.INTERACTIVE_HIGH


def _admin_body(reply: Any) -> dict[str, Any] | None:
    """A router's admin space reply as a JSON object (None: an error, or not one)."""
    if reply.ok is None:
        return None
    try:   # stdlib only (this also runs on peers): too deep is a decode error
        body = json.loads(reply.ok.payload.to_bytes().decode("utf-8", "replace"))
    except (ValueError, RecursionError):
        return None
    return body if isinstance(body, dict) else None


def router_info(session: Any, timeout: float, *, others: bool = False) -> dict[str, Any]:
    """What the router(s) this session is attached to say in their admin space (id, version,
    metadata, listen locators, attached sessions); {} when they do not answer (admin space
    disabled). With *others*, ``routers`` also maps every router reachable through it (its
    linked routers, theirs...) to its ``version`` and ``metadata``."""
    out: dict[str, Any] = {}
    try:
        zids = [str(z) for z in session.info.routers_zid()]
    except Exception:  # noqa: BLE001
        return out
    for zid in zids[:1]:
        out["zid"] = zid
        try:
            for reply in session.get(f"@/{zid}/router", timeout=timeout):
                body = _admin_body(reply)
                if body is None:
                    continue
                out["version"] = str(body.get("version", "")).split(" ")[0]
                out["metadata"] = body.get("metadata") if isinstance(body.get("metadata"),
                                                                     dict) else None
                out["locators"] = [str(x) for x in body.get("locators") or []]
                out["sessions"] = [{"zid": str(x.get("peer", "")), "whatami": x.get("whatami"),
                                    "links": [str(ln.get("dst", "")) for ln in x.get("links") or []]}
                                   for x in body.get("sessions") or [] if isinstance(x, dict)]
        except Exception:  # noqa: BLE001 - a router without admin space still routes
            pass
    if others and out.get("version"):
        out["routers"] = _other_routers(session, out["zid"], timeout)
    return out


def _other_routers(session: Any, own: str, timeout: float) -> dict[str, dict[str, Any]]:
    """{zid: {version, metadata}} of every other router answering ``@/*/router``."""
    found: dict[str, dict[str, Any]] = {}
    try:
        for reply in session.get("@/*/router", timeout=timeout):
            body = _admin_body(reply)
            zid = str((body or {}).get("zid", ""))
            if body is None or not zid or zid.lstrip("0") == own.lstrip("0"):
                continue
            meta = body.get("metadata")
            found[zid] = {"version": str(body.get("version", "")).split(" ")[0] or None,
                          "metadata": meta if isinstance(meta, dict) else None}
    except Exception:  # noqa: BLE001 - what answered so far is what is known
        pass
    return found


def graph(session: Any, domain: int, timeout: float) -> list[dict[str, Any]]:
    """Every rmw_zenoh liveliness token of *domain* visible through *session* (parsed)."""
    out = []
    for reply in session.liveliness().get(f"{LV_PREFIX}/{domain}/**", timeout=timeout):
        if reply.ok is None:
            continue
        tok = parse_token(str(reply.ok.key_expr))
        if tok is not None:
            out.append(tok)
    return out


class ProbeNode:
    """A ROS 2 node of our own on *session*: a node token, and a publisher or subscription token on
    *topic* with rmw_zenoh's key, payload and attachment (what `ros2 node list` and a real
    listener/talker see)."""

    def __init__(self, session: Any, domain: int, name: str, topic: str,
                 type_hash: str = STRING_HASH) -> None:
        self.session, self.domain, self.name, self.topic = session, domain, name, topic
        self.zid = str(session.zid())
        self.nid = str(secrets.randbelow(10_000))
        self.key = topic_key(domain, topic, STRING_TYPE, type_hash)
        self.type_hash = type_hash
        self._tokens = [session.liveliness().declare_token(
            node_token(domain, self.zid, self.nid, name))]
        self.gid = b""
        self.seq = 0
        self.received: queue.Queue = queue.Queue()
        self._sub = None

    def publisher(self) -> None:
        tok = endpoint_token(self.domain, self.zid, self.nid, str(int(self.nid) + 1), "MP",
                             self.name, self.topic, type_hash=self.type_hash)
        self._tokens.append(self.session.liveliness().declare_token(tok))
        self.gid = make_gid(tok)

    def subscription(self) -> None:
        tok = endpoint_token(self.domain, self.zid, self.nid, str(int(self.nid) + 2), "MS",
                             self.name, self.topic, type_hash=self.type_hash)
        self._tokens.append(self.session.liveliness().declare_token(tok))

        def on_sample(sample: Any) -> None:   # (payload, attachment, when it arrived)
            att = sample.attachment
            self.received.put((bytes(sample.payload.to_bytes()),
                               bytes(att.to_bytes()) if att is not None else None,
                               time.monotonic()))

        self._sub = self.session.declare_subscriber(self.key, on_sample)

    def publish(self, text: str, **put: Any) -> None:
        """One message of *text*; *put*: more of session.put's options (priority ...)."""
        self.seq += 1
        self.session.put(self.key, encode_string(text),
                         attachment=encode_attachment(self.seq, time.time_ns(), self.gid), **put)

    def close(self) -> None:
        for t in self._tokens:
            try:
                t.undeclare()
            except Exception:  # noqa: BLE001
                pass
        if self._sub is not None:
            try:
                self._sub.undeclare()
            except Exception:  # noqa: BLE001
                pass


def wait_message(node: ProbeNode, timeout: float, expect: str | None = None
                 ) -> tuple[str | None, bool | None, int]:
    """(first text received, its attachment was rmw_zenoh's, samples seen) within *timeout*."""
    deadline = time.monotonic() + timeout
    seen = 0
    while True:
        left = deadline - time.monotonic()
        if left <= 0:
            return None, None, seen
        try:
            payload, att, _at = node.received.get(timeout=min(left, 0.1))
        except queue.Empty:
            continue
        seen += 1
        text = decode_string(payload)
        if text is not None and (expect is None or expect in text):
            return text, decode_attachment(att) is not None, seen


def sees(session: Any, domain: int, kind: str, topic: str, timeout: float,
         zid: str | None = None) -> bool:
    """Whether a *kind* token on *topic* (of session *zid*, when given) is visible."""
    for tok in graph(session, domain, timeout):
        if tok["kind"] == kind and tok.get("topic", "").strip("/") == topic.strip("/") and \
                (zid is None or tok["zid"] == zid):
            return True
    return False


def _sees_as_client(endpoint: str, domain: int, kind: str, topic: str) -> bool:
    """Whether the graph, read as ``ros2 node list`` does (a client of the router), has the token."""
    try:
        viewer = open_client(endpoint, 0.5)
    except (OpenFailed, ZenohMissing):
        return False
    try:
        return sees(viewer, domain, kind, topic, 0.3)
    finally:
        viewer.close()


def probe_name() -> str:
    return f"{PROBE_PREFIX}_{secrets.token_hex(4)}"


# --------------------------------------------------------------------------- the peer program
def _args(argv: list[str]) -> dict[str, str]:
    out, i = {}, 0
    while i < len(argv):
        if argv[i].startswith("--") and i + 1 < len(argv):
            out[argv[i][2:]] = argv[i + 1]
            i += 2
        else:
            i += 1
    return out


def _report(**fields: Any) -> None:
    print(REPORT_MARK + json.dumps(fields), flush=True)


def parse_report(text: str) -> dict[str, Any] | None:
    """The peer program's report line in *text* (None when it printed none)."""
    for line in reversed((text or "").splitlines()):
        if line.startswith(REPORT_MARK):
            try:
                value = json.loads(line[len(REPORT_MARK):])
            except (ValueError, RecursionError):   # stdlib only: too deep is a decode error
                return None
            return value if isinstance(value, dict) else None
    return None


def peer_endpoint(env: dict[str, str], local: str) -> tuple[str, str]:
    """(endpoint, how) a node on this machine uses: ``router`` (a peer of the local router, the
    default), or what ZENOH_CONFIG_OVERRIDE says: ``client`` or ``peer`` straight to another
    machine's router (a lone node)."""
    override = env.get("ZENOH_CONFIG_OVERRIDE", "")
    m = re.search(r'(?:^|;)\s*mode\s*=\s*"(client|peer)"', override)
    ep = re.search(r'connect/endpoints\s*=\s*\[\s*"([^"]+)"', override)
    if m and ep:
        return ep.group(1), m.group(1)
    return local, "router"


def override_tls(env: dict[str, str]) -> dict[str, Any]:
    """The ``transport/link/tls/*`` keys of ZENOH_CONFIG_OVERRIDE (a lone node under mutual TLS:
    its certificate, written by ``ros apply --client``), as a tls dict for open_client."""
    out: dict[str, Any] = {}
    for m in re.finditer(r'transport/link/tls/(\w+)\s*=\s*("(?:[^"\\]|\\.)*"|true|false)',
                         env.get("ZENOH_CONFIG_OVERRIDE", "")):
        v = m.group(2)
        out[m.group(1)] = v == "true" if v in ("true", "false") else v[1:-1]
    return out


def session_mode(how: str) -> str:
    """The Zenoh mode of a node that connects *how* (``router`` means: a peer of that router)."""
    return "client" if how == "client" else "peer"


def run_program(argv: list[str], more: dict[str, Any] | None = None) -> int:
    """``sub``, ``pub`` or ``graph`` on this machine, as its own ROS 2 nodes would; one report line.
    *more*: other commands, ``name: function(session, args, base, deadline)`` (zenohlink's)."""
    cmd = argv[0] if argv else ""
    a = _args(argv[1:])
    timeout = float(a.get("timeout", "3"))
    deadline = time.monotonic() + timeout
    env = ros_env()
    base = {"env": env, "host": os.uname().nodename, "python": sys.executable}
    if cmd == "info":
        _report(**base)
        return 0
    try:
        _zenoh()
    except ZenohMissing:
        _report(error="no_zenoh", detail=f"{sys.executable} has no eclipse-zenoh (it comes with "
                                         "rosnet-tui: reinstall it as its README says)", **base)
        return NO_ZENOH_EXIT
    endpoint, how = peer_endpoint(env, a.get("local", "tcp/127.0.0.1:7447"))
    domain = int(a.get("domain", env.get("ROS_DOMAIN_ID") or "0") or 0)
    base.update(endpoint=endpoint, how=how, domain=domain)
    try:
        session = open_client(endpoint, min(2.0, timeout * 0.4), session_mode(how),
                              override_tls(env) if endpoint.startswith("tls/") else None)
    except OpenFailed as exc:
        _report(error="open", detail=f"{endpoint}: {exc}", **base)
        return 0
    try:
        base["router"] = router_info(session, min(1.0, timeout * 0.2))
        topic = a.get("topic", "")
        if how == "router" and a.get("member") == "1" and not [
                x for x in base["router"].get("sessions") or [] if x.get("whatami") == "router"]:
            _report(error="no_link", detail="its router has no link to the master's router",
                    **base)
            return 0
        if cmd == "graph":
            name = a.get("name", probe_name())
            acked = threading.Event()  # the other side has seen our probe node: we may go
            # Subscribed before the probe node shows, so the checker's ack finds us.
            ack = session.declare_subscriber(f"rosnet_tui/ack/{name}", lambda _s: acked.set())
            node = ProbeNode(session, domain, name, "rosnet_tui/graph")
            print(READY_MARK, flush=True)
            want = a.get("expect", "")
            seen: list[dict[str, Any]] = []
            while time.monotonic() < deadline:
                seen = graph(session, domain, max(0.2, min(1.0, deadline - time.monotonic())))
                if not want or any(t["name"] == want for t in seen):
                    break
                time.sleep(0.1)
            acked.wait(max(0.0, deadline - time.monotonic()))
            ack.undeclare()
            node.close()
            _report(tokens=seen, own_zid=node.zid, **base)
        elif cmd == "sub":
            node = ProbeNode(session, domain, a.get("name", probe_name()), topic,
                             a.get("hash", STRING_HASH))
            node.subscription()
            print(READY_MARK, flush=True)
            text, att_ok, count = wait_message(node, max(0.1, deadline - time.monotonic() - 0.3),
                                               a.get("expect"))
            saw_pub = text is not None or _sees_as_client(endpoint, domain, "MP", topic)
            node.close()
            _report(received=text, attachment_ok=att_ok, samples=count, saw_publisher=saw_pub,
                    **base)
        elif cmd == "pub":
            node = ProbeNode(session, domain, a.get("name", probe_name()), topic,
                             a.get("hash", STRING_HASH))
            node.publisher()
            acked = threading.Event()
            ack = session.declare_subscriber(f"rosnet_tui/ack/{a.get('ack', 'x')}",
                                             lambda _s: acked.set())
            print(READY_MARK, flush=True)
            sent = 0
            while time.monotonic() < deadline and not acked.is_set():
                node.publish(f"{a.get('text', 'hello')} {sent}")
                sent += 1
                acked.wait(0.1)
            saw_sub = acked.is_set() or _sees_as_client(endpoint, domain, "MS", topic)
            ack.undeclare()
            node.close()
            _report(published=sent, acked=acked.is_set(), saw_subscriber=saw_sub, **base)
        elif more and cmd in more:
            more[cmd](session, a, base, deadline)
        else:
            _report(error="usage", detail=f"unknown command {cmd!r}", **base)
            return 2
    finally:
        session.close()
    return 0


if __name__ == "__main__":
    sys.exit(run_program(sys.argv[1:]))
