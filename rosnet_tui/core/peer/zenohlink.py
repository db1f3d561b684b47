"""ROS 2's link measured (ros2.link): both ends of it, on rmw_zenoh's keys and messages.

Each end is a subscription and a publisher of its own (:class:`zenohproto.ProbeNode`: tokens, the
topic's data key, CDR strings, the 33-byte attachment) and speaks a small protocol in the text of
those messages, so every byte measured is a real rmw_zenoh message through the routers:

- ``p ID`` / ``q ID``: a ping and its echo (the round trip);
- ``d SIZE SEQ ...``: a message of a burst; ``k SEQ``: the receiver has it (acknowledgements,
  every 2 ms at most); ``b SECONDS CAP STALL [MIN]``: "send me a burst"; ``z``: my burst is over
  (all of it acknowledged or given up); ``f`` / ``r JSON``: "what did you receive" and the answer;
- ``L SIZE ...``: a large message (whole when its text is SIZE characters long); ``a SIZE``: it
  arrived whole; ``s SIZE``: "send me one"; ``e``: the end.

A burst is paced by the acknowledgements: at most a window of data is on its way, and the window
grows only as the other end acknowledges, to under a second of what arrived so far. It ends at
its time or cap, or as soon as its rate is known: after its least time, when its last half and its
last quarter were acknowledged at rates within 15 % of each other, with enough messages to tell
(on a fast link a few tens of milliseconds; a thin one uses its time). What is on its way is given
up after its stall time without an acknowledgement (shorter on a fast link). The receiver's rate is that
of the later half of what arrived, past the window's growth, when that half holds enough. A thin
link thus holds less than a second of our data when the burst ends, and data messages go with
congestion control *drop*, as rmw_zenoh's default QoS does, so a full queue drops them instead of
blocking anyone. Control messages go at a higher priority than data.

On a peer this runs in the round's agent as the program ``zlink``: the source below
:data:`BODY_MARK`, loaded on a copy of zenohproto's names (this module's imports are those names
there), with ``run_link`` as its entry.
"""

from __future__ import annotations

from rosnet_tui.core.peer.zenohproto import (
    READY_MARK,
    REPORT_MARK,
    ProbeNode,
    control_priority,
    decode_string,
    probe_name,
    run_program,
)

BODY_MARK = "# ---- the program's body: what a peer's agent loads on zenohproto's names"
# ---- the program's body: what a peer's agent loads on zenohproto's names
import bisect  # noqa: E402
import json  # noqa: E402
import queue  # noqa: E402
import time  # noqa: E402
from typing import Any  # noqa: E402

CHUNK = 4096              # bytes of text in one burst message
ACK_EVERY_S = 0.002       # a receiver acknowledges at most this often
QUEUED_S = 0.8            # a burst keeps at most about this much of what arrives on its way
STEADY = 0.15             # a burst ends when its last half's and last quarter's rates differ less
STEADY_N = 16             # ... the quarter with at least this many messages acknowledged
TAIL_N = 16               # messages the later half of a burst needs for its rate to be used


def link_text(kind: str, size: int, head: str = "") -> str:
    """A message text of *size* characters: *kind*, *size*, *head*, then padding."""
    lead = f"{kind} {size} {head} "
    return lead + "x" * (size - len(lead)) if size > len(lead) else lead


def whole_size(text: str) -> int:
    """The size a large message says it has, when it arrived whole (else 0)."""
    parts = text.split(" ", 2)
    try:
        size = int(parts[1])
    except (IndexError, ValueError):
        return 0
    return size if len(text) == size else 0


class LinkEnd:
    """One end of the measured link: answers the other end (echoes, acknowledgements, its stats,
    what it asks to be sent) and sends its own burst under a window (see the module's text)."""

    def __init__(self, rx: ProbeNode, tx: ProbeNode) -> None:
        self.rx, self.tx = rx, tx
        self.got: dict[str, Any] = {"bytes": 0, "n": 0, "first": None, "last": None, "seq": 0}
        self.arrivals: list[tuple[float, int]] = []   # (when, bytes so far) of each burst message
        self.pongs: dict[str, float] = {}
        self.stats: dict[str, Any] | None = None     # the other end's "r"
        self.largest_in = 0                          # the largest "L" received whole
        self.delivered: set[int] = set()             # sizes of ours the other end got whole
        self.burst: dict[str, Any] | None = None
        self.stop = False
        self.last_ack = 0.0
        self.ack_due = False        # data arrived since the last acknowledgement
        self.their_burst_over = False   # the other end said "z"

    def put(self, text: str, control: bool = True) -> None:
        """Send *text*: a control message (above the data queue), or with *control* False as
        data."""
        self.tx.publish(text, **({"priority": control_priority()} if control else {}))

    def start_burst(self, seconds: float, cap: int, stall_s: float, least_s: float = 0.0) -> None:
        """Send a burst for *seconds* at most, *cap* bytes at most, ended earlier once its rate is
        steady after *least_s* s (0: never earlier)."""
        now = time.monotonic()
        self.burst = {"until": now + seconds, "cap": cap, "seq": 0, "acked": 0,
                      "window": CHUNK, "start": now, "progress": now,
                      "stall": max(0.2, stall_s), "least": least_s, "acks": ([now], [0])}

    def sending(self) -> bool:
        """A burst is still being sent (its time and cap not used up)."""
        b = self.burst
        return b is not None and time.monotonic() < b["until"] and b["seq"] * CHUNK < b["cap"]

    def in_flight(self) -> bool:
        """Data of our burst is on its way, not acknowledged (nor given up after a stall)."""
        b = self.burst
        return b is not None and b["acked"] < b["seq"]

    def _send_some(self) -> bool:
        b = self.burst
        if b is None:
            return False
        now = time.monotonic()
        if b["acked"] < b["seq"] and now - b["progress"] > self._stall(b, now):
            b["acked"], b["progress"] = b["seq"], now      # lost on the way: given up
            b["window"] = max(CHUNK, b["window"] // 2)
        if not self.sending() or (b["seq"] - b["acked"]) * CHUNK >= b["window"]:
            return False
        b["seq"] += 1
        self.tx.publish(link_text("d", CHUNK, str(b["seq"])))
        return True

    @staticmethod
    def _stall(b: dict[str, Any], now: float) -> float:
        """Seconds without an acknowledgement after which what is on its way is given up: the
        burst's stall time, shorter on a fast link (20 messages' time at the rate acknowledged so
        far, 50 ms at least), so a lost last message does not hold a fast burst's end."""
        if not b["acked"]:
            return b["stall"]
        per_msg = (now - b["start"]) / b["acked"]
        return max(0.05, min(b["stall"], 20 * per_msg))

    def _acked(self, seq: int) -> None:
        b = self.burst
        if b is None or seq <= b["acked"]:
            return
        now = time.monotonic()
        grown = b["window"] + (seq - b["acked"]) * CHUNK      # doubles each round trip
        rate = seq * CHUNK / max(1e-3, now - b["start"])       # what arrived so far, per second
        b["window"] = int(max(CHUNK, min(grown, rate * QUEUED_S)))
        b["acked"], b["progress"] = seq, now
        times, seqs = b["acks"]
        times.append(now)
        seqs.append(seq)
        if b["least"] and now - b["start"] >= b["least"] and steady(times, seqs):
            b["until"] = now        # the rate is known: the burst ends here

    def handle(self, payload: bytes, at: float) -> None:
        text = decode_string(payload) or ""
        kind, _, rest = text.partition(" ")
        f = rest.split(" ", 2)
        try:
            if kind == "d":
                g = self.got
                g["bytes"] += len(payload)
                g["n"] += 1
                g["first"] = g["first"] or at
                g["last"] = at
                g["seq"] = max(g["seq"], int(f[1]))
                self.arrivals.append((at, g["bytes"]))
                self.ack_due = True
            elif kind == "k":
                self._acked(int(f[0]))
            elif kind == "p":
                self.put(f"q {f[0]}")
            elif kind == "q":
                self.pongs[f[0]] = at
            elif kind == "L" and whole_size(text):
                self.largest_in = max(self.largest_in, whole_size(text))
                self.put(f"a {whole_size(text)}")
            elif kind == "a":
                self.delivered.add(int(f[0]))
            elif kind == "s":
                self.put(link_text("L", int(f[0])), control=False)
            elif kind == "b":
                b = rest.split()
                self.start_burst(float(b[0]), int(b[1]), float(b[2]),
                                 float(b[3]) if len(b) > 3 else 0.0)
            elif kind == "f":
                self.put("r " + json.dumps(self.received()))
            elif kind == "r":      # the other end's stats: a flat object of numbers, or none
                got = json.loads(rest)
                self.stats = got if isinstance(got, dict) and all(
                    isinstance(v, (int, float)) and not isinstance(v, bool)
                    for v in got.values()) else None
            elif kind == "z":
                self.their_burst_over = True
            elif kind == "e":
                self.stop = True
        except (IndexError, ValueError, RecursionError):   # not ours, cut, too deep: ignored
            pass

    def received(self) -> dict[str, Any]:
        """What this end received of the other's burst: bytes, messages, seconds from the first
        to the last, the largest whole message."""
        g = self.got
        span = (g["last"] - g["first"]) if g["n"] > 1 else 0.0
        out = {"bytes": g["bytes"], "n": g["n"], "span": span,
               "first_bytes": g["bytes"] // max(1, g["n"]), "largest": self.largest_in}
        if span > 0:        # the later half: what arrived once the window had grown
            times = [a[0] for a in self.arrivals]
            i = bisect.bisect_left(times, g["first"] + span / 2)
            if len(times) - i > TAIL_N and i > 0:
                out["tail_bytes"] = g["bytes"] - self.arrivals[i - 1][1]
                out["tail_span"] = g["last"] - self.arrivals[i - 1][0]
        return out

    def pump(self, until: float, done: Any = None) -> None:
        """Answer and send until *until* (monotonic), the other end says ``e``, or *done()*."""
        while not self.stop and time.monotonic() < until and not (done and done()):
            if self.ack_due and time.monotonic() - self.last_ack >= ACK_EVERY_S:
                self.put(f"k {self.got['seq']}")
                self.ack_due, self.last_ack = False, time.monotonic()
            sent = self._send_some()
            b = self.burst
            if b is not None and not sent and not b.get("told") and not self.sending() \
                    and not self.in_flight():
                self.put("z")
                b["told"] = True
            try:
                payload, _att, at = (self.rx.received.get_nowait() if sent else
                                     self.rx.received.get(timeout=0.005))
            except queue.Empty:
                continue
            self.handle(payload, at)


def steady(times: list[float], seqs: list[int]) -> bool:
    """Whether acknowledgements (*times*, *seqs*: ascending) show a steady rate: over the last
    half of the time since the first and over its last quarter, each with STEADY_N messages or
    more, at rates within STEADY of each other."""
    start, now = times[0], times[-1]
    q = (now - start) / 4
    if q <= 0:
        return False

    def seq_at(t: float) -> int:
        return seqs[max(0, bisect.bisect_right(times, t) - 1)]

    half = (seqs[-1] - seq_at(now - 2 * q)) / 2      # per quarter, over the last half
    last = seqs[-1] - seq_at(now - q)
    return last >= STEADY_N and abs(half - last) <= STEADY * max(half, last)


def rate_bps(stats: dict[str, Any] | None) -> float | None:
    """Bits per second a receiver's stats show (None: fewer than two messages arrived): those of
    the later half of the burst when the stats hold it, else from the first message to the last."""
    if not stats or stats.get("n", 0) < 2 or stats.get("span", 0) <= 0:
        return None
    if stats.get("tail_span", 0) > 0 and stats.get("tail_bytes", 0) > 0:
        return stats["tail_bytes"] * 8.0 / stats["tail_span"]
    return (stats["bytes"] - stats.get("first_bytes", 0)) * 8.0 / stats["span"]


def serve_link(session: Any, a: dict[str, str], base: dict[str, Any], deadline: float) -> None:
    """The peer's side: answer the checker until it says ``e`` or the deadline; one report."""
    domain, topic = base["domain"], a.get("topic", "rosnet_tui/link")
    rx = ProbeNode(session, domain, probe_name(), topic + "/out")
    rx.subscription()
    tx = ProbeNode(session, domain, probe_name(), topic + "/in")
    tx.publisher()
    print(READY_MARK, flush=True)
    end = LinkEnd(rx, tx)
    try:
        end.pump(deadline - 0.2)
    finally:
        rx.close()
        tx.close()
    print(REPORT_MARK + json.dumps({"link": end.received(), **base}), flush=True)


def run_link(argv: list[str]) -> int:
    """``link --topic T --timeout S``: the peer program's entry (zenohproto's run_program)."""
    return run_program(argv, {"link": serve_link})
