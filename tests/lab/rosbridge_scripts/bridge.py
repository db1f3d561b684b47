"""A stand-in for rosbridge_server (rosbridge_websocket) in the network lab, bridging to the lab's
real roscore. No rosbridge installs here (Debian has none), so this small server follows the
rosbridge v2 protocol specification (RobotWebTools/rosbridge_suite, ROSBRIDGE_PROTOCOL.md) and
RFC 6455 for the WebSocket, and does what the real bridge does for the operations a browser's
first steps use, through rospy (Debian's python3-rospy, run with /usr/bin/python3):

- the HTTP upgrade on any path (a plain GET gets 400, as tornado answers);
- ``advertise`` / ``publish`` / ``unadvertise`` (a rospy Publisher per topic), ``subscribe`` /
  ``unsubscribe`` (a rospy Subscriber whose messages go back as ``publish`` ops);
- ``call_service /rosapi/topics``, answered as rosapi does (every topic the master knows, with its
  type), or, with ``--no-rosapi``, as rosbridge answers a service nobody offers
  (``service_response`` with ``result: false`` and "Service /rosapi/topics does not exist", after a
  ``status`` error); other services are answered the same way;
- ``status`` messages for errors (an unknown op, a type it cannot load).

Message types are those rospy can load (std_msgs here), named ``pkg/Type`` or ``pkg/msg/Type``.
Usage: bridge.py [--port 9090] [--no-rosapi]   (ROS_MASTER_URI from the environment)
"""

from __future__ import annotations

import argparse
import base64
import hashlib
import json
import socket
import struct
import sys
import threading

import rospy
from roslib.message import get_message_class

GUID = "258EAFA5-E914-47DA-95CA-C5AB0DC85B11"   # RFC 6455, section 1.3
MAX_HEADER = 16384
MAX_FRAME = 8 << 20


class Closed(Exception):
    pass


def recv_exact(conn: socket.socket, n: int) -> bytes:
    buf = b""
    while len(buf) < n:
        chunk = conn.recv(n - len(buf))
        if not chunk:
            raise Closed()
        buf += chunk
    return buf


class Client:
    """One WebSocket connection: its frames, and the ROS side of its operations."""

    def __init__(self, conn: socket.socket, rosapi: bool) -> None:
        self.conn = conn
        self.rosapi = rosapi
        self.lock = threading.Lock()
        self.pubs: dict[str, rospy.Publisher] = {}
        self.subs: dict[str, rospy.Subscriber] = {}
        self.types: dict[str, type] = {}

    # ---------------------------------------------------------------- WebSocket
    def handshake(self) -> bool:
        data = b""
        while b"\r\n\r\n" not in data:
            chunk = self.conn.recv(4096)
            if not chunk or len(data) > MAX_HEADER:
                return False
            data += chunk
        head = data.split(b"\r\n\r\n", 1)[0].decode("latin-1").split("\r\n")
        headers = {}
        for line in head[1:]:
            name, _, value = line.partition(":")
            headers[name.strip().lower()] = value.strip()
        key = headers.get("sec-websocket-key", "")
        if (not head[0].startswith("GET ") or "websocket" not in headers.get("upgrade", "").lower()
                or not key):
            body = b'Can "Upgrade" only to "WebSocket".'
            self.conn.sendall(b"HTTP/1.1 400 Bad Request\r\nContent-Type: text/plain\r\n"
                              b"Content-Length: " + str(len(body)).encode() + b"\r\n"
                              b"Connection: close\r\n\r\n" + body)
            return False
        accept = base64.b64encode(hashlib.sha1((key + GUID).encode()).digest()).decode()
        self.conn.sendall(("HTTP/1.1 101 Switching Protocols\r\nUpgrade: websocket\r\n"
                           f"Connection: Upgrade\r\nSec-WebSocket-Accept: {accept}\r\n\r\n"
                           ).encode())
        return True

    def send_frame(self, opcode: int, payload: bytes) -> None:
        n = len(payload)
        if n < 126:
            head = struct.pack("!BB", 0x80 | opcode, n)
        elif n < 1 << 16:
            head = struct.pack("!BBH", 0x80 | opcode, 126, n)
        else:
            head = struct.pack("!BBQ", 0x80 | opcode, 127, n)
        with self.lock:
            self.conn.sendall(head + payload)

    def send(self, msg: dict) -> None:
        try:
            self.send_frame(0x1, json.dumps(msg).encode())
        except OSError:
            pass

    def read_message(self) -> str | None:
        """The next text message (None: the client closed)."""
        parts: list[bytes] = []
        while True:
            b1, b2 = recv_exact(self.conn, 2)
            fin, opcode = b1 & 0x80, b1 & 0x0F
            n = b2 & 0x7F
            if n == 126:
                n = struct.unpack("!H", recv_exact(self.conn, 2))[0]
            elif n == 127:
                n = struct.unpack("!Q", recv_exact(self.conn, 8))[0]
            if n > MAX_FRAME:
                raise Closed()
            mask = recv_exact(self.conn, 4) if b2 & 0x80 else b"\0\0\0\0"
            data = bytes(c ^ mask[i % 4] for i, c in enumerate(recv_exact(self.conn, n)))
            if opcode == 0x8:
                self.send_frame(0x8, data[:2])
                return None
            if opcode == 0x9:
                self.send_frame(0xA, data)
                continue
            if opcode in (0x1, 0x2, 0x0):
                parts.append(data)
                if fin:
                    return b"".join(parts).decode("utf-8", "replace")

    # ---------------------------------------------------------------- rosbridge v2
    def status(self, level: str, text: str, mid=None) -> None:
        msg = {"op": "status", "level": level, "msg": text}
        if mid is not None:
            msg["id"] = mid
        self.send(msg)

    def msg_class(self, type_name: str):
        parts = [p for p in type_name.split("/") if p]
        if len(parts) == 3 and parts[1] == "msg":
            parts = [parts[0], parts[2]]
        cls = get_message_class("/".join(parts)) if len(parts) == 2 else None
        if cls is None:
            raise ValueError(f"Unable to load the message type {type_name}")
        return cls

    def handle(self, msg: dict) -> None:
        op, mid = msg.get("op"), msg.get("id")
        try:
            if op == "advertise":
                topic = msg["topic"]
                cls = self.msg_class(msg["type"])
                if topic not in self.pubs:
                    self.pubs[topic] = rospy.Publisher(topic, cls, queue_size=10)
                    self.types[topic] = cls
            elif op == "unadvertise":
                pub = self.pubs.pop(msg["topic"], None)
                if pub is not None:
                    pub.unregister()
            elif op == "publish":
                topic = msg["topic"]
                if topic not in self.pubs:
                    raise ValueError(f"publish on {topic}: not advertised")
                self.pubs[topic].publish(self.types[topic](**(msg.get("msg") or {})))
            elif op == "subscribe":
                topic = msg["topic"]
                cls = self.msg_class(msg["type"])
                if topic not in self.subs:
                    self.subs[topic] = rospy.Subscriber(
                        topic, cls, lambda m, t=topic: self.send(
                            {"op": "publish", "topic": t,
                             "msg": {s: getattr(m, s) for s in m.__slots__}}))
            elif op == "unsubscribe":
                sub = self.subs.pop(msg["topic"], None)
                if sub is not None:
                    sub.unregister()
            elif op == "call_service":
                self.call_service(msg)
            else:
                self.status("error", f"Unknown operation: {op}", mid)
        except Exception as exc:  # what rosbridge does: a status message, the op dropped
            self.status("error", f"{op}: {exc}", mid)

    def call_service(self, msg: dict) -> None:
        service, mid = msg.get("service"), msg.get("id")
        out = {"op": "service_response", "service": service}
        if mid is not None:
            out["id"] = mid
        if service == "/rosapi/topics" and self.rosapi:
            master = rospy.get_master()
            _c, _m, state = master.getSystemState()
            _c, _m, types = master.getTopicTypes()
            known = dict(types)
            topics = sorted({t for t, _ in state[0]} | {t for t, _ in state[1]})
            out.update(values={"topics": topics, "types": [known.get(t, "") for t in topics]},
                       result=True)
        else:
            why = f"Service {service} does not exist"
            self.status("error", f"call_service InvalidServiceException: {why}", mid)
            out.update(values=why, result=False)
        self.send(out)

    def run(self) -> None:
        try:
            if not self.handshake():
                return
            while True:
                text = self.read_message()
                if text is None:
                    return
                try:
                    msg = json.loads(text)
                except ValueError:
                    self.status("error", "Unable to parse the message")
                    continue
                if isinstance(msg, dict):
                    self.handle(msg)
        except (Closed, OSError):
            pass
        finally:
            for s in self.subs.values():
                s.unregister()
            for p in self.pubs.values():
                p.unregister()
            self.conn.close()


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--port", type=int, default=9090)
    ap.add_argument("--no-rosapi", action="store_true")
    args = ap.parse_args()
    rospy.init_node("rosbridge_websocket", disable_signals=True)
    srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    srv.bind(("0.0.0.0", args.port))
    srv.listen(16)
    print(f"rosbridge stand-in on port {args.port} (rosapi {'off' if args.no_rosapi else 'on'})",
          flush=True)
    while True:
        conn, _ = srv.accept()
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        threading.Thread(target=Client(conn, not args.no_rosapi).run, daemon=True).start()


if __name__ == "__main__":
    sys.exit(main())
