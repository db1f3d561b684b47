"""Step 4, both ROS versions: the path a browser takes to the robot (ros.rosbridge).

Robot Web Tools (roslibjs) opens a WebSocket to rosbridge_server and speaks the rosbridge v2 JSON
protocol. The check does what such a browser does, from a component that does not run the bridge:
the host's name, TCP through its modem's forward, the HTTP upgrade to WebSocket, the topic list
(``call_service /rosapi/topics``), and a ``publish`` from a second connection that a ``subscribe``
on the first receives, on a probe topic. A failure names the hop: ``name``, ``forward``,
``upgrade``, ``bridge``, ``rosapi`` or ``round_trip``.

The WebSocket client is the ``websockets`` package (its asyncio client), imported when the check
runs, never at start-up.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import socket
import time
from typing import Any

from rosnet_tui.core import jsonsafe
from rosnet_tui.core.checks import CheckContext, check
from rosnet_tui.core.checks.probes.budget import budget
from rosnet_tui.core.config.settings_model import Settings
from rosnet_tui.core.net.connect import tcp_failure_kind
from rosnet_tui.core.peer import rosproto
from rosnet_tui.core.results import Outcome, Status
from rosnet_tui.core.ros import rosbridge
from rosnet_tui.core.ssh.connection import resolve_ipv4

MAX_TOPICS = 200          # topics kept in the data (a big robot lists hundreds)
PUBLISH_EVERY_S = 0.1     # the probe message is repeated until it arrives (subscriptions settle)
CLOSE_S = 0.1             # the WebSockets' closing handshake, at most (then dropped)
MARGIN_S = 0.25           # the exchange ends this long before the check's budget (closing fits)


class HopFailed(Exception):
    """The exchange broke at *hop*; the message says what was seen."""

    def __init__(self, hop: str, words: str, tcp: str | None = None, *,
                 quotes_bridge: bool = False) -> None:
        super().__init__(words)
        self.hop = hop
        self.tcp = tcp                   # how the TCP connection went, when it was the hop
        self.quotes_bridge = quotes_bridge  # the words already quote the bridge's last status


async def _tcp(addr: str, port: int, t: float) -> tuple[socket.socket | None, str, str]:
    """(connected socket or None, TcpKind, words)."""
    loop = asyncio.get_running_loop()
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setblocking(False)
    try:
        await asyncio.wait_for(loop.sock_connect(sock, (addr, port)), max(0.05, t))
        return sock, "connected", "connected"
    except (OSError, asyncio.TimeoutError) as exc:
        sock.close()
        kind = tcp_failure_kind(exc)
        words = {"timeout": f"no answer within {t:.1f} s (dropped)",
                 "refused": "connection refused"}.get(kind, getattr(exc, "strerror", None)
                                                      or str(exc) or type(exc).__name__)
        return None, kind, words


class _Browser:
    """One WebSocket connection to the bridge, as one browser tab holds it."""

    def __init__(self, ws: Any) -> None:
        self.ws = ws
        self.status: list[str] = []      # the bridge's "status" messages (errors, warnings)

    @classmethod
    async def open(cls, url: str, sock: socket.socket, t: float) -> _Browser:
        from websockets.asyncio.client import connect
        from websockets.exceptions import InvalidHandshake, InvalidStatus

        try:
            ws = await asyncio.wait_for(
                connect(url, sock=sock, open_timeout=None, close_timeout=CLOSE_S, ping_interval=None,
                        compression=None, proxy=None, max_size=8 << 20,
                        user_agent_header="rosnet-tui (ros.rosbridge)"),
                max(0.05, t))
        except asyncio.TimeoutError:
            sock.close()
            raise HopFailed("upgrade", f"the HTTP upgrade to WebSocket got no answer within "
                                       f"{t:.1f} s") from None
        except InvalidStatus as exc:
            code = exc.response.status_code
            raise HopFailed("upgrade", f"HTTP {code} {exc.response.reason_phrase} instead of the "
                                       "WebSocket upgrade (101)") from None
        except (InvalidHandshake, OSError, EOFError) as exc:
            raise HopFailed("upgrade", f"no WebSocket upgrade: {exc or type(exc).__name__}"
                            ) from None
        return cls(ws)

    async def send(self, msg: dict) -> None:
        from websockets.exceptions import ConnectionClosed

        try:
            await self.ws.send(json.dumps(msg))
        except ConnectionClosed:
            raise HopFailed("bridge", f"the bridge closed the WebSocket (sending {msg['op']})"
                            ) from None

    async def wait_for(self, match, deadline: float, hop: str, waiting: str) -> dict:
        """The first message *match* accepts (status messages are kept); HopFailed(*hop*) when
        none comes before *deadline* (loop time) or the connection ends."""
        from websockets.exceptions import ConnectionClosed

        loop = asyncio.get_running_loop()
        while True:
            left = deadline - loop.time()
            if left <= 0:
                seen = f"; the bridge said: {self.status[-1]}" if self.status else ""
                raise HopFailed(hop, f"no {waiting} before the timeout{seen}",
                                quotes_bridge=bool(self.status))
            try:
                raw = await asyncio.wait_for(self.ws.recv(), left)
            except asyncio.TimeoutError:
                continue
            except ConnectionClosed as exc:
                raise HopFailed(hop, f"the bridge closed the WebSocket while waiting for "
                                     f"{waiting} ({exc.rcvd.code if exc.rcvd else 'no close frame'})"
                                ) from None
            try:
                msg = jsonsafe.loads_bounded(raw if isinstance(raw, str) else
                                             raw.decode("utf-8", "replace"), unique_keys=False)
            except jsonsafe.JsonInputError:
                raise HopFailed("bridge", "the WebSocket answered something that is not "
                                          "rosbridge's JSON") from None
            if not isinstance(msg, dict):
                continue
            if msg.get("op") == "status":
                self.status.append(f"{msg.get('level')}: {str(msg.get('msg'))[:200]}")
            if match(msg):
                return msg

    async def close(self) -> None:
        """Close, briefly: a slow peer's closing handshake is not waited for (the verdict is
        already known), the connection is dropped instead."""
        try:
            await asyncio.wait_for(self.ws.close(), CLOSE_S)
        except Exception:
            with contextlib.suppress(Exception):
                self.ws.transport.abort()


async def _connect(addr: str, port: int, url: str, deadline: float) -> _Browser:
    loop = asyncio.get_running_loop()
    sock, kind, words = await _tcp(addr, port, deadline - loop.time())
    if sock is None:
        raise HopFailed("forward" if kind != "refused" else "bridge", words, tcp=kind)
    return await _Browser.open(url, sock, deadline - loop.time())


async def _topics(b: _Browser, deadline: float, probe_id: str) -> list[str]:
    """The topic list through rosapi; HopFailed at 'bridge' (no answer) or 'rosapi'."""
    cid = f"rosnet-tui-topics-{probe_id}"
    await b.send({"op": "call_service", "id": cid, "service": rosbridge.TOPICS_SERVICE,
                  "args": []})
    msg = await b.wait_for(lambda m: m.get("op") == "service_response" and m.get("id") == cid,
                           deadline, "bridge", f"answer to call_service {rosbridge.TOPICS_SERVICE}")
    values = msg.get("values")
    if msg.get("result") is not True:
        raise HopFailed("rosapi", f"call_service {rosbridge.TOPICS_SERVICE} failed: "
                                  f"{str(values)[:200]}")
    topics = values.get("topics") if isinstance(values, dict) else None
    if not isinstance(topics, list):
        raise HopFailed("rosapi", f"{rosbridge.TOPICS_SERVICE} answered without a topic list: "
                                  f"{str(values)[:200]}")
    return [str(x) for x in topics]


async def _round_trip(sub: _Browser, pub: _Browser, topic: str, type_: str, deadline: float
                      ) -> float:
    """Seconds from the first publish until the subscriber got the probe message."""
    loop = asyncio.get_running_loop()
    token = f"rosnet-tui probe {rosproto.new_probe_id()}"
    await sub.send({"op": "subscribe", "id": f"sub-{topic}", "topic": topic, "type": type_})
    await pub.send({"op": "advertise", "id": f"adv-{topic}", "topic": topic, "type": type_})
    got = asyncio.ensure_future(sub.wait_for(
        lambda m: m.get("op") == "publish" and m.get("topic") == topic
        and isinstance(m.get("msg"), dict) and m["msg"].get("data") == token,
        deadline, "round_trip", f"message on {topic} through the bridge"))
    first = loop.time()
    try:
        while not got.done() and loop.time() < deadline:
            await pub.send({"op": "publish", "topic": topic, "msg": {"data": token}})
            await asyncio.wait({got}, timeout=min(PUBLISH_EVERY_S, max(0.0, deadline - loop.time())))
        await got
    except HopFailed as exc:
        said = [*sub.status, *pub.status]
        raise HopFailed("round_trip", str(exc) + (f" (bridge status: {said[-1]})"
                                                  if said and not exc.quotes_bridge else "")
                        ) from None
    except BaseException:
        got.cancel()
        raise
    return loop.time() - first


@check("ros.rosbridge", "ros", "A browser's path: rosbridge over WebSocket, by name", 1.0,
       switch="rosbridge")
async def check_rosbridge(ctx: CheckContext) -> Outcome:
    s = ctx.settings
    host, port = s.rosbridge_host, s.rosbridge.port
    url = rosbridge.url(s)
    data: dict[str, Any] = {"host": host, "url": url, "address": None, "tcp": None,
                            "upgraded": False, "rosapi": False, "topics": [],
                            "round_trip": False, "round_trip_ms": None, "failed_hop": None,
                            "detail": None}
    if not host:
        return Outcome(Status.SKIP, "skipped: no component is named to run rosbridge "
                                    "([rosbridge] host, else [ros] master)", [], data)
    if s.hosts_rosbridge:
        others = ", ".join(p.name for p in s.peers) or "the other components"
        return Outcome(Status.SKIP, f"skipped: {host} runs rosbridge; the check runs from the "
                                    f"other components ({others}), as a browser would", [], data)
    loop = asyncio.get_running_loop()
    t = budget(ctx, "ros.rosbridge")
    deadline = loop.time() + max(0.2, t - MARGIN_S)
    ev: list[str] = []
    browsers: list[_Browser] = []
    start = time.monotonic()

    def fail(hop: str, words: str) -> Outcome:
        data.update(failed_hop=hop, detail=words)
        hint = _hint(s, hop, data)
        return Outcome(Status.FAIL, f"{url}: {hop.replace('_', ' ')} hop: {words}"
                                    + (f"; {hint}" if hint else ""), ev, data)

    addrs, err = await resolve_ipv4(host, min(1.0, t * 0.25))
    if not addrs:
        return fail("name", f"the name {host} does not resolve here ({err})")
    addr = data["address"] = addrs[0]
    ev.append(f"{host} resolves to {addr}")
    try:
        try:
            first = await _connect(addr, port, url, deadline)
        except HopFailed as exc:
            data["tcp"] = exc.tcp or "connected"
            raise
        data.update(tcp="connected", upgraded=True)
        browsers.append(first)
        ev.append(f"TCP {addr}:{port} connected; HTTP upgrade to WebSocket accepted")
        probe_id = rosproto.new_probe_id()
        second_task = asyncio.ensure_future(_connect(addr, port, url, deadline))
        try:
            topics = await _topics(first, deadline, probe_id)
        except BaseException:
            second_task.cancel()
            await asyncio.wait({second_task})
            if not second_task.cancelled() and second_task.exception() is None:
                browsers.append(second_task.result())
            raise
        ours = [x for x in topics if x.startswith(rosproto.PROBE_PREFIX)]
        shown = [x for x in topics if x not in ours]
        data.update(rosapi=True, topics=shown[:MAX_TOPICS])
        ev.append(f"{rosbridge.TOPICS_SERVICE}: {len(shown)} topic(s)"
                  + (f": {', '.join(shown[:8])}" + (" ..." if len(shown) > 8 else "")
                     if shown else ""))
        try:
            second = await second_task
        except HopFailed as exc:
            raise HopFailed("bridge", f"a second WebSocket (the publisher) failed: {exc}"
                            ) from None
        browsers.append(second)
        topic = f"{rosproto.PROBE_PREFIX}/bridge_{probe_id}"
        type_ = rosbridge.PROBE_TYPE[2 if s.ros2 else 1]
        took = await _round_trip(first, second, topic, type_, deadline)
        data.update(round_trip=True, round_trip_ms=round(took * 1000, 1))
        ev.append(f"published on {topic} ({type_}) through one WebSocket, received through "
                  f"another after {took * 1000:.0f} ms")
    except HopFailed as exc:
        return fail(exc.hop, str(exc))
    finally:
        await asyncio.gather(*(b.close() for b in browsers), return_exceptions=True)
    ev.append(f"total {time.monotonic() - start:.2f} s")
    return Outcome(Status.PASS, f"a browser reaches rosbridge at {url} ({addr}): topic list "
                                f"({len(data['topics'])}) and a message through the bridge in "
                                f"{data['round_trip_ms']:.0f} ms", ev, data)


def _hint(s: Settings, hop: str, data: dict) -> str:
    host, port = s.rosbridge_host, s.rosbridge.port
    launch = rosbridge.launch_command(s)
    if hop == "name":
        return f"add {host} to /etc/hosts (Linux step)"
    if hop == "forward":
        return f"is TCP {port} forwarded to {host} on its modem?"
    if hop == "bridge" and data.get("tcp") == "refused":
        return (f"{host}'s address answers but nothing takes TCP {port}: is rosbridge running "
                f"there (`{launch}`)?")
    if hop == "upgrade":
        return f"something other than rosbridge answers on TCP {port} of {host}"
    if hop == "bridge":
        return f"the WebSocket opened but rosbridge did not answer: restart `{launch}` on {host}"
    if hop == "rosapi":
        return (f"rosapi is not running on {host}: the launch file starts it "
                f"(`{launch}`), or `rosrun rosapi rosapi_node`")
    return ("the bridge answers but a message published through it does not come back: "
            f"is the ROS master reachable from rosbridge on {host}?")
