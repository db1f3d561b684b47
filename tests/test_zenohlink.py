"""The link protocol of ros2.link (core/peer/zenohlink.py) between two real Zenoh sessions through
a real Zenoh router on loopback: echoes, a burst paced by acknowledgements and its account, a
large message delivered whole, and a burst that never outruns its window."""

from __future__ import annotations

import json
import threading
import time

import pytest
import zenoh

from rosnet_tui.core.peer import zenohproto
from rosnet_tui.core.peer.zenohlink import (
    CHUNK,
    STEADY_N,
    LinkEnd,
    link_text,
    rate_bps,
    steady,
    whole_size,
)
from tests.builders import free_port


@pytest.fixture
def ends():
    port = free_port()
    cfg = zenoh.Config.from_json5(json.dumps({
        "mode": "router", "listen": {"endpoints": [f"tcp/127.0.0.1:{port}"]},
        "scouting": {"multicast": {"enabled": False}},
        "transport": {"shared_memory": {"enabled": False}}}))
    router = zenoh.open(cfg)
    sessions = [zenohproto.open_client(f"tcp/127.0.0.1:{port}", 3.0) for _ in range(2)]
    nodes = []
    pair = []
    for s, (rx, tx) in zip(sessions, (("in", "out"), ("out", "in")), strict=True):
        a = zenohproto.ProbeNode(s, 0, zenohproto.probe_name(), f"rosnet_tui/link_t/{rx}")
        a.subscription()
        b = zenohproto.ProbeNode(s, 0, zenohproto.probe_name(), f"rosnet_tui/link_t/{tx}")
        b.publisher()
        nodes += [a, b]
        pair.append(LinkEnd(a, b))
    here, there = pair
    server = threading.Thread(target=there.pump, args=(time.monotonic() + 20,), daemon=True)
    server.start()
    yield here, there
    here.put("e")
    server.join(5)
    for n in nodes:
        n.close()
    for s in sessions:
        s.close()
    router.close()


def _ping(here: LinkEnd) -> None:
    deadline = time.monotonic() + 5
    n = 0
    while not here.pongs and time.monotonic() < deadline:
        n += 1
        here.put(f"p w{n}")
        here.pump(time.monotonic() + 0.2, lambda: bool(here.pongs))
    assert here.pongs, "no echo within 5 s"


def test_messages_are_sized_and_told_whole():
    text = link_text("L", 65536)
    assert len(text) == 65536 and whole_size(text) == 65536
    assert whole_size(text[:-1]) == 0 and whole_size("L x") == 0 and whole_size("") == 0
    assert rate_bps({"bytes": 9000, "n": 3, "span": 1.0, "first_bytes": 1000}) == 64000
    assert rate_bps({"bytes": 9000, "n": 1, "span": 0.0}) is None and rate_bps(None) is None


def test_a_burst_ends_when_its_rate_is_steady_and_the_later_half_gives_the_rate():
    """ros2.link's speed: a burst on a fast link ends as soon as its acknowledgements show one
    rate (the last half and its last quarter alike, with enough messages), not at its time."""
    even = [i * 0.001 for i in range(101)], list(range(0, 101 * 2, 2))   # 2 per ms, steady
    assert steady(*even)
    growing = [i * 0.001 for i in range(101)], [2 ** (i // 10) for i in range(101)]  # doubling
    assert not steady(*growing)
    few = [0.0, 0.5, 1.0], [0, STEADY_N // 2, STEADY_N]       # steady, but too few to tell
    assert not steady(*few)
    assert not steady([1.0], [0])
    # The later half's rate when the stats hold it (past the window's growth), else the whole.
    stats = {"bytes": 9000, "n": 30, "span": 1.0, "first_bytes": 1000,
             "tail_bytes": 6000, "tail_span": 0.5}
    assert rate_bps(stats) == 96000
    assert rate_bps({**stats, "tail_span": 0}) == 64000


def test_a_burst_is_acknowledged_and_accounted_for_and_a_large_message_arrives_whole(ends):
    here, there = ends
    _ping(here)
    here.start_burst(0.5, 2 * 1024 * 1024, 0.3)
    here.pump(time.monotonic() + 3, lambda: not here.sending() and not here.in_flight())
    assert not here.in_flight() and here.burst["seq"] > 1
    deadline = time.monotonic() + 3
    while here.stats is None and time.monotonic() < deadline:
        here.put("f")
        here.pump(time.monotonic() + 0.2, lambda: here.stats is not None)
    # Data goes with congestion control "drop" (as rmw_zenoh's default): on a busy machine some
    # chunks are dropped even on loopback, so the receiver counts what arrived, never more than
    # was sent, and the sender is not left waiting for the rest (acknowledged or given up).
    assert 1 < here.stats["n"] <= here.burst["seq"], (here.stats, here.burst)
    assert here.stats["bytes"] >= here.stats["n"] * CHUNK and rate_bps(here.stats) > 1e6
    # theirs, asked for: the other way, and the end of it said ("z")
    here.put(f"b 0.3 {512 * 1024} 0.3")
    here.pump(time.monotonic() + 3, lambda: here.their_burst_over)
    assert here.their_burst_over and here.got["n"] > 1 and rate_bps(here.received()) > 1e6
    # one megabyte each way, whole
    here.put(f"s {1 << 20}")
    here.put(link_text("L", 1 << 20), control=False)
    here.pump(time.monotonic() + 5, lambda: (1 << 20) in here.delivered
              and here.largest_in == 1 << 20)
    assert (1 << 20) in here.delivered and here.largest_in == 1 << 20


def test_asked_for_a_burst_with_a_least_time_the_other_end_stops_once_its_rate_is_steady(ends):
    """"b SECONDS CAP STALL LEAST": a 10 s burst with no cap in reach on loopback ends long
    before its time, once its acknowledgements are steady; the rate is the later half's."""
    here, there = ends
    _ping(here)
    t0 = time.monotonic()
    here.put(f"b 10 {1 << 30} 0.3 0.02")
    here.pump(t0 + 12, lambda: here.their_burst_over)
    assert here.their_burst_over and time.monotonic() - t0 < 8, there.burst
    got = here.received()
    assert got["n"] > 1 and got["tail_span"] > 0 and rate_bps(got) > 1e6, got


def test_a_burst_never_has_more_than_its_window_on_the_way(ends):
    """Nobody acknowledges (the other end gone): the sender stops at its first window and
    gives it up after its stall time, instead of flooding."""
    here, there = ends
    _ping(here)
    there.stop = True               # the other end stops answering
    time.sleep(0.2)
    here.start_burst(1.0, 8 * 1024 * 1024, 0.3)
    here.pump(time.monotonic() + 1.2)
    assert here.burst["seq"] * CHUNK <= 8 * CHUNK, here.burst    # a window or a few, not 8 MB


@pytest.mark.parametrize("stats", ["[" * 100_000 + "]" * 100_000, "[1, 2]", '{"n": "3"}',
                                   '{"n": true}', '{"n": {"deep": 1}}'])
def test_the_other_ends_stats_are_a_flat_object_of_numbers_or_nothing(stats):
    """The other end's "r" answer comes from another machine: too deep, not an object, or not
    numbers is no stats (never a RecursionError out of the peer program, nor a crash in the
    rate)."""
    here = LinkEnd(rx=None, tx=None)    # "r" is only read: nothing is sent
    here.handle(zenohproto.encode_string("r " + stats), time.monotonic())
    assert here.stats is None and rate_bps(here.stats) is None
    here.handle(zenohproto.encode_string('r {"n": 3, "span": 0.5, "bytes": 1000}'), 0.0)
    assert here.stats == {"n": 3, "span": 0.5, "bytes": 1000} and rate_bps(here.stats) == 16000.0
