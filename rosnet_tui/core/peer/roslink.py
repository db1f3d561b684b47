"""ROS 1's link measured (ros.link): both ends of it, over TCPROS through the forwards.

Each end is a ROS node of our own (:class:`LinkNode`, a :class:`rosproto.ProbeNode`): it publishes
one std_msgs/String topic and subscribes to the other end's, through the master (registration,
requestTopic, the TCPROS handshake), as any node does. The two ends then speak a small protocol in
the text of those messages, so every byte measured is a real ROS message on the wire:

- ``p ID`` / ``q ID``: a ping and its echo (the round trip);
- ``d SEQ ...``: a message of a burst; ``k SEQ BYTES N SPAN FIRST``: the receiver has it, with
  what it received of the burst so far (bytes, messages, seconds from the first to the last, the
  first one's bytes); ``b SECONDS CAP``: "send me a burst"; ``z``: my burst is over;
- ``L SIZE ...``: a large message (whole when its text is SIZE characters long); ``a SIZE``: it
  arrived whole; ``s SIZE``: "send me one"; ``e``: the end.

A burst is paced by the acknowledgements: at most a window of data is on its way, and the window
grows only as the other end acknowledges, to under a second of what arrived so far, so a thin
link holds less than a second of it when the burst ends. TCP loses nothing: what is not
acknowledged is still on its way.

On a peer this runs in the round's ROS 1 agent (stdlib only) as the program ``rlink``: the source
below :data:`BODY_MARK`, loaded on a copy of rosproto's names (this module's imports are those
names there), with ``run_link`` as its entry. Python 3.8 syntax.
"""
# The peer's python3 may be 3.8: keep typing's generics and socket.timeout (not yet TimeoutError).
# ruff: noqa: UP006, UP035, UP041, UP045

from __future__ import annotations

from rosnet_tui.core.peer.rosproto import (
    READY_KEY,
    REPORT_KEY,
    STRING_MD5,
    STRING_TYPE,
    TYPE_CHECKING,
    ProbeNode,
    decode_string,
    describe_error,
    effective_ros_env,
    encode_header,
    publisher_header,
    read_frame,
    read_header,
    request_topic,
    subscriber_header,
)

BODY_MARK = "# ---- the program's body: what a peer's agent loads on rosproto's names"
# ---- the program's body: what a peer's agent loads on rosproto's names
import json  # noqa: E402
import os  # noqa: E402
import queue  # noqa: E402
import socket  # noqa: E402
import struct  # noqa: E402
import sys  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402

if TYPE_CHECKING:
    from typing import Any, Dict, List, Optional

CHUNK = 4096              # bytes of a burst's first messages (they grow with the window)
MAX_CHUNK = 65536         # ... and at most
MAX_FRAME = (1 << 20) + 4096   # the largest message this link takes (1 MB and its head)
ACK_EVERY_S = 0.001       # a receiver acknowledges at most this often
QUEUED_S = 0.8            # a burst keeps at most about this much of what arrives on its way
_PAD = b"x" * MAX_FRAME


def link_frame(kind: str, size: int, head: str = "") -> bytes:
    """The TCPROS frame of a std_msgs/String of *size* characters: *kind*, *size*, *head*, then
    padding."""
    lead = f"{kind} {size} {head} ".encode()
    body = lead + _PAD[:max(0, size - len(lead))]
    return struct.pack("<II", len(body) + 4, len(body)) + body


def text_frame(text: str) -> bytes:
    data = text.encode("utf-8")
    return struct.pack("<II", len(data) + 4, len(data)) + data


def whole_size(text: str) -> int:
    """The size a large message says it has, when it arrived whole (else 0)."""
    parts = text.split(" ", 2)
    try:
        size = int(parts[1])
    except (IndexError, ValueError):
        return 0
    return size if len(text) == size else 0


def _within(deadline: float, cap: float) -> float:
    return max(0.05, min(cap, deadline - time.monotonic()))


class LinkNode(ProbeNode):
    """A node that publishes *topic* to the other end and subscribes to *their_topic*; what
    arrives is queued in :attr:`received` as (text, bytes, monotonic time)."""

    def __init__(self, master_uri: str, topic: str, their_topic: str, **kw: Any) -> None:
        super().__init__(master_uri, topic, "link", **kw)
        self.their_topic = their_topic
        self.received: queue.Queue = queue.Queue()
        self.outbox: queue.Queue = queue.Queue()
        self.connected_out = threading.Event()   # the other end subscribed to our topic
        self.connected_in = threading.Event()    # we are subscribed to theirs
        self.registered: List[str] = []          # "pub", "sub": what to undo at the end
        self.why_not = ""                        # why a connection failed, in words
        self.failed_hop = ""                     # registration | xmlrpc_callback | tcpros
        self._tcp: Optional[socket.socket] = None
        self._conns: List[socket.socket] = []
        self._writer: Optional[threading.Thread] = None

    # Slave API --------------------------------------------------------------------------
    def _request_topic(self, caller_id: str, topic: str, protocols: Any) -> List[Any]:
        if topic != self.topic or self._tcp is None:
            return [-1, f"not a publisher of {topic}", []]
        if not any(p and p[0] == "TCPROS" for p in protocols or []):
            return [0, "no supported protocol implementations", []]
        port = self._tcp.getsockname()[1]
        return [1, f"ready on {self.host}:{port}", ["TCPROS", self.host, port]]

    def _publisher_update(self, caller_id: str, topic: str, publishers: Any) -> List[Any]:
        if topic == self.their_topic:
            self.updates.set()      # a signal only: the publishers are asked of the master
        return [1, "", 0]

    def _publications(self, caller_id: str) -> List[Any]:
        return [1, "", [[self.topic, STRING_TYPE]]]

    def _subscriptions(self, caller_id: str) -> List[Any]:
        return [1, "", [[self.their_topic, STRING_TYPE]]]

    # publishing -------------------------------------------------------------------------
    def publish(self) -> bool:
        """Serve the Slave API and TCPROS, register our topic with the master; False with
        :attr:`why_not` when that failed."""
        try:
            self._tcp = socket.create_server((self.bind, 0))
            self._tcp.settimeout(0.2)
            self.start_server()
        except OSError as exc:
            return self._failed("registration", f"cannot listen on {self.bind}: "
                                                f"{describe_error(exc)[1]}")
        try:
            self.master.register_publisher(self.topic, STRING_TYPE, self.uri)
        except Exception as exc:
            return self._failed("registration", f"registerPublisher {self.topic} at "
                                                f"{self.master_uri} failed: "
                                                f"{describe_error(exc, self.call_timeout)[1]}")
        self.registered.append("pub")
        if self.stopping.is_set():      # closed while the master answered: undo it
            self._unregister()
            return False
        self._thread(self._accept_loop)
        return True

    def _accept_loop(self) -> None:
        assert self._tcp is not None
        while not self.stopping.is_set():
            try:
                conn, _addr = self._tcp.accept()
            except socket.timeout:
                continue
            except OSError:
                return
            self._conns.append(conn)
            self._thread(self._handshake, conn)

    def _handshake(self, conn: socket.socket) -> None:
        conn.settimeout(max(0.5, self.call_timeout))
        try:
            hdr = read_header(conn)
            if hdr.get("topic") != self.topic or hdr.get("md5sum") not in (STRING_MD5, "*") \
                    or self.connected_out.is_set():
                conn.sendall(encode_header({"error": "not the link's other end"}))
                conn.close()
                return
            conn.sendall(encode_header(publisher_header(self.caller_id, self.topic)))
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            conn.settimeout(None)
        except Exception:  # noqa: BLE001 - not the other end: it is not ours to serve
            conn.close()
            return
        self.connected_out.set()
        self._writer = self._thread(self._write_loop, conn)

    def _write_loop(self, conn: socket.socket) -> None:
        while True:
            frame = self.outbox.get()
            if frame is None:
                return
            try:
                conn.sendall(frame)
            except OSError:
                return

    def put(self, text: str) -> None:
        """Send *text* to the other end (queued until it subscribed; never blocks)."""
        self.outbox.put(text_frame(text))

    def put_frame(self, frame: bytes) -> None:
        self.outbox.put(frame)

    # subscribing ------------------------------------------------------------------------
    def subscribe(self, deadline: float) -> bool:
        """Register as a subscriber of the other end's topic and connect to its publisher (as
        the master names it) by *deadline*; False with :attr:`why_not` when that failed. Its
        calls may take twice the call timeout: a thin link is busy starting the peer's side."""
        slow = 2 * self.call_timeout
        try:
            pubs = self.master.register_subscriber(self.their_topic, STRING_TYPE, self.uri,
                                                   timeout=_within(deadline, slow))
        except Exception as exc:
            return self._failed("registration", f"registerSubscriber {self.their_topic} at "
                                                f"{self.master_uri} failed: "
                                                f"{describe_error(exc, self.call_timeout)[1]}")
        self.registered.append("sub")
        if self.stopping.is_set():      # closed while the master answered: undo it
            self._unregister()
            return False
        while time.monotonic() < deadline and not self.stopping.is_set():
            for uri in pubs:
                if self._connect(uri, deadline):
                    return True
            self.updates.wait(_within(deadline, 0.2))
            self.updates.clear()
            try:    # the master's list again (one call; registering twice changes nothing)
                pubs = self.master.register_subscriber(
                    self.their_topic, STRING_TYPE, self.uri,
                    timeout=_within(deadline, slow))
            except Exception as exc:  # noqa: BLE001 - said below, or tried again
                self.why_not = self.why_not or f"the master did not answer: {describe_error(exc)[1]}"
        if not self.why_not:
            self._failed("registration", f"no publisher of {self.their_topic} came in time")
        return False

    def _connect(self, uri: str, deadline: float) -> bool:
        t = _within(deadline, 2 * self.call_timeout)
        try:
            host, port = request_topic(uri, self.caller_id, self.their_topic, timeout=t)
        except Exception as exc:
            return self._failed("xmlrpc_callback", f"requestTopic to {uri} failed: "
                                                   f"{describe_error(exc, t)[1]}")
        try:
            sock = socket.create_connection((host, port), timeout=_within(deadline, t))
        except Exception as exc:
            return self._failed("tcpros", f"TCPROS connection to {host}:{port} failed: "
                                          f"{describe_error(exc, t)[1]}")
        try:
            sock.settimeout(_within(deadline, t))
            sock.sendall(encode_header(subscriber_header(self.caller_id, self.their_topic)))
            hdr = read_header(sock)
            if "error" in hdr:
                raise ValueError(hdr["error"])
            sock.settimeout(None)
        except Exception as exc:
            sock.close()
            return self._failed("tcpros", f"TCPROS handshake with {host}:{port} failed: "
                                          f"{describe_error(exc)[1]}")
        self._conns.append(sock)
        self.connected_in.set()
        self._thread(self._read_loop, sock)
        return True

    def _read_loop(self, sock: socket.socket) -> None:
        while True:
            try:
                body = read_frame(sock, MAX_FRAME)
                text = decode_string(body)
            except Exception:  # noqa: BLE001 - closed, or not a String: the end of it
                self.received.put(("e", 0, time.monotonic()))   # the other end is gone
                return
            self.received.put((text, len(body), time.monotonic()))

    # the end ----------------------------------------------------------------------------
    def _failed(self, hop: str, words: str) -> bool:
        self.failed_hop, self.why_not = self.failed_hop or hop, words
        return False

    def _unregister(self) -> None:
        """Undo our registrations with the master, both at once (bounded)."""
        t = min(1.0, self.call_timeout)

        def undo(what: str) -> None:
            try:
                if what == "pub":
                    self.master.unregister_publisher(self.topic, self.uri, timeout=t)
                else:
                    self.master.unregister_subscriber(self.their_topic, self.uri, timeout=t)
            except Exception:  # noqa: BLE001, S110 - the master forgets a dead node anyway
                pass

        todo, self.registered = list(self.registered), []
        threads = [threading.Thread(target=undo, args=(w,), daemon=True) for w in todo]
        for th in threads:
            th.start()
        for th in threads:
            th.join(t + 0.5)

    def close(self, linger: float = 0.5, wait: bool = True) -> None:
        """Let what is queued leave (*linger* s at most), unregister, close everything; with
        *wait* False, the Slave API's server is left to end with its poll (a program about to
        exit)."""
        self.stopping.set()
        self.outbox.put(None)       # the writer sends what is queued, then ends
        stopping = threading.Thread(target=self.stop_server, daemon=True)   # up to its poll
        stopping.start()
        if self._writer is not None:
            self._writer.join(linger)
        self._unregister()
        for conn in self._conns:
            try:
                conn.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            conn.close()
        if self._tcp is not None:
            try:
                self._tcp.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            self._tcp.close()
        if wait:
            stopping.join(1.0)


class LinkEnd:
    """One end of the measured link: answers the other end (echoes, acknowledgements, what it
    asks to be sent) and sends its own burst under a window (see the module's text)."""

    def __init__(self, node: Any) -> None:
        self.node = node
        self.got: Dict[str, Any] = {"bytes": 0, "n": 0, "first": None, "last": None, "seq": 0,
                                    "first_bytes": 0}
        self.pongs: Dict[str, float] = {}
        self.stats: Optional[Dict[str, float]] = None   # the other end's, from its last ack
        self.largest_in = 0                             # the largest "L" received whole
        self.arrived: set = set()                       # sizes of theirs we got whole
        self.delivered: set = set()                     # sizes of ours the other end got whole
        self.burst: Optional[Dict[str, Any]] = None
        self.stop = False
        self.last_ack = 0.0
        self.ack_due = False
        self.their_burst_over = False

    def put(self, text: str) -> None:
        self.node.put(text)

    def start_burst(self, seconds: float, cap: int) -> None:
        now = time.monotonic()
        self.burst = {"until": now + seconds, "cap": cap, "seq": 0, "acked": 0, "sent": 0,
                      "acked_bytes": 0, "sizes": {}, "window": CHUNK, "start": now}

    def sending(self) -> bool:
        """A burst is still being sent (its time and cap not used up)."""
        b = self.burst
        return b is not None and time.monotonic() < b["until"] and b["sent"] < b["cap"]

    def in_flight(self) -> bool:
        """Data of our burst is on its way, not acknowledged."""
        b = self.burst
        return b is not None and b["acked"] < b["seq"]

    def _send_some(self) -> bool:
        b = self.burst
        if b is None or not self.sending() or b["sent"] - b["acked_bytes"] >= b["window"]:
            return False
        size = max(CHUNK, min(MAX_CHUNK, b["window"] // 4))
        b["seq"] += 1
        b["sent"] += size
        b["sizes"][b["seq"]] = b["sent"]
        self.node.put_frame(link_frame("d", size, str(b["seq"])))
        return True

    def _acked(self, seq: int) -> None:
        b = self.burst
        if b is None or seq <= b["acked"] or seq > b["seq"]:
            return
        now = time.monotonic()
        done = b["sizes"].get(seq, b["acked_bytes"])
        grown = b["window"] + (done - b["acked_bytes"])          # doubles each round trip
        rate = done / max(1e-3, now - b["start"])                  # what arrived so far, per second
        b["window"] = int(max(CHUNK, min(grown, rate * QUEUED_S)))
        b["acked"], b["acked_bytes"] = seq, done

    def handle(self, text: str, size: int, at: float) -> None:
        kind, _, rest = text.partition(" ")
        f = rest[:80].split(" ")    # the fields come first (then a large one's padding)
        try:
            if kind == "d":
                g = self.got
                if not g["n"]:
                    g["first"], g["first_bytes"] = at, size
                g["bytes"] += size
                g["n"] += 1
                g["last"] = at
                g["seq"] = max(g["seq"], int(f[1]))
                self.ack_due = True
            elif kind == "k":
                self.stats = {"bytes": float(f[1]), "n": float(f[2]), "span": float(f[3]),
                              "first_bytes": float(f[4])}
                self._acked(int(f[0]))
            elif kind == "p":
                self.put(f"q {f[0]}")
            elif kind == "q":
                self.pongs[f[0]] = at
            elif kind == "L" and whole_size(text):
                self.largest_in = max(self.largest_in, whole_size(text))
                self.arrived.add(whole_size(text))
                self.put(f"a {whole_size(text)}")
            elif kind == "a":
                self.delivered.add(int(f[0]))
            elif kind == "s":
                self.node.put_frame(link_frame("L", min(int(f[0]), MAX_FRAME - 64)))
            elif kind == "b":
                self.start_burst(float(f[0]), int(f[1]))
            elif kind == "z":
                self.their_burst_over = True
            elif kind == "e":
                self.stop = True
        except (IndexError, ValueError):    # not ours, or cut: ignored
            pass

    def received(self) -> Dict[str, Any]:
        """What this end received of the other's burst: bytes, messages, seconds from the first
        to the last, the first one's bytes, the largest whole message."""
        g = self.got
        span = (g["last"] - g["first"]) if g["n"] > 1 else 0.0
        return {"bytes": g["bytes"], "n": g["n"], "span": span, "first_bytes": g["first_bytes"],
                "largest": self.largest_in}

    def pump(self, until: float, done: Any = None) -> None:
        """Answer and send until *until* (monotonic), the other end says ``e``, or *done()*."""
        rx = self.node.received
        while not self.stop and time.monotonic() < until and not (done and done()):
            if self.ack_due and time.monotonic() - self.last_ack >= ACK_EVERY_S:
                r = self.received()
                self.put(f"k {self.got['seq']} {r['bytes']} {r['n']} {r['span']:.6f} "
                         f"{r['first_bytes']}")
                self.ack_due, self.last_ack = False, time.monotonic()
            sent = self._send_some()
            b = self.burst
            if b is not None and not sent and not b.get("told") and not self.sending() \
                    and not self.in_flight():
                self.put("z")
                b["told"] = True
            try:
                item = rx.get_nowait() if sent else rx.get(timeout=0.002 if self.ack_due else 0.01)
            except queue.Empty:
                continue
            self.handle(*item)


def rate_bps(stats: Optional[Dict[str, Any]]) -> Optional[float]:
    """Bits per second a receiver's stats show (None: fewer than two messages arrived)."""
    if not stats or stats.get("n", 0) < 2 or stats.get("span", 0) <= 0:
        return None
    return (stats["bytes"] - stats.get("first_bytes", 0)) * 8.0 / stats["span"]


def _say(obj: Dict[str, Any]) -> None:
    sys.stdout.write(json.dumps(obj) + "\n")
    sys.stdout.flush()


def run_link(argv: List[str]) -> int:
    """``link --master URI --topic BASE --timeout S --connect S [--bashrc PATH]``: the peer's
    side. It publishes BASE/in, subscribes to BASE/out, answers until told ``e`` or the
    timeout; says it is ready once registered, then one report line."""
    a: Dict[str, str] = {"--bashrc": "~/.bashrc"}
    words = list(argv[1:] if argv and argv[0] == "link" else argv)
    while len(words) >= 2 and words[0] in ("--master", "--topic", "--timeout", "--connect",
                                           "--bashrc"):
        a[words[0]] = words[1]
        words = words[2:]
    try:
        timeout = max(0.5, min(float(a.get("--timeout", "5")), 600.0))
        connect = max(0.3, min(float(a.get("--connect", "3")), timeout))
    except ValueError:
        words = ["--timeout"]
    if words or not a.get("--master") or not a.get("--topic"):
        sys.stderr.write("usage: rlink link --master URI --topic BASE --timeout S --connect S "
                         "[--bashrc PATH]\n")
        return 2
    start = time.monotonic()
    bashrc = os.path.expanduser(a["--bashrc"])
    master = a["--master"] or effective_ros_env(None, bashrc).get("ROS_MASTER_URI", ("", ""))[0]
    node = LinkNode(master, a["--topic"] + "/in", a["--topic"] + "/out", bashrc=bashrc,
                    call_timeout=max(0.3, min(2.0, connect * 0.8)))
    end = LinkEnd(node)
    report: Dict[str, Any] = {REPORT_KEY: 1, "ok": False, "caller_id": node.caller_id}
    try:
        if node.publish():
            _say({READY_KEY: 1, "caller_id": node.caller_id, "uri": node.uri})
            if node.subscribe(start + connect):
                report["ok"] = True
                end.pump(start + timeout - 0.2)
    finally:
        node.close(wait=False)
    report.update(link=end.received(), failed_hop=node.failed_hop or None,
                  error=node.why_not or None, advertised_uri=node.uri,
                  advertised_from=node.host_from)
    _say(report)
    return 0 if report["ok"] else 1
