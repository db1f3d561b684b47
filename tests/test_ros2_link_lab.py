"""ros2.link on the network lab (issue 31): the link to each peer measured through the real Zenoh
routers (round trip, throughput each way, the largest message delivered whole), with the robot's
modem shaped by `tc tbf` both ways (this kernel has no netem), a need from [[link.topic]] compared,
and large messages dropped on the way named as such."""

from __future__ import annotations

import json
import time

import pytest

from rosnet_tui.core.ros import ros2 as ros2_cfg
from tests.lab.verdicts import (
    explain,
    measured_delay,
    measured_thin,
    measured_unshaped,
    needing,
    own_verdict,
    within,
)

pytestmark = pytest.mark.lab


def rules(entry: dict) -> list[str]:
    return [a["rule"] for a in entry.get("advice") or []]


def _linked_check(ros2, host: str) -> dict:
    """*host*'s check once its router is linked again after a restart (connect retry: up to 4 s
    between tries), bounded: the last results."""
    deadline = time.monotonic() + 40
    while True:
        results = ros2.check(host)
        if results["ros2.pubsub_in"]["status"] == "pass" or time.monotonic() > deadline:
            return results
        time.sleep(1)


def test_unshaped_the_link_passes_with_its_figures(ros2):
    for host, peer in (("laptop", "turtlebot"), ("robot", "sami")):
        measured_unshaped(ros2.check(host), "ros2.link", peer)


def test_shaped_to_2_mbit_each_way_the_rates_a_round_trip_and_the_need(ros2):
    ros2.shape_robot("2mbit")
    # From the robot, with a need of 10 x 50 kB (4.0 Mbit/s): the rates and a warning with them.
    results = ros2.check("robot", config=needing(ros2.settings("robot"), ros2.lab.home("robot"), 50_000, 10))
    link = results["ros2.link"]
    d = link["data"]["peers"]["sami"]
    assert within(d["out_bps"], 2e6, 0.25) and within(d["in_bps"], 2e6, 0.25), explain(results)
    assert d["rtt_ms"] is not None and link["data"]["need_bps"] == 4e6, explain(results)
    own_verdict(link, results)
    assert link["status"] in ("warn", "fail"), explain(results)
    assert "needs 4.0 Mbit/s up, measured " in link["summary"], explain(results)
    assert "needs 4.0 Mbit/s down, measured " in link["summary"], explain(results)
    thin = next(a for a in link["advice"] if a["rule"] == "ros2.link.too_thin")
    assert "4.0 Mbit/s" in thin["meaning"] and "downsampling" in " ".join(thin["actions"])
    # From the laptop, no need: the rates each way (up is the laptop's: the robot's download).
    results = ros2.check("laptop")
    link = results["ros2.link"]
    d = link["data"]["peers"]["turtlebot"]
    assert within(d["out_bps"], 2e6, 0.25) and within(d["in_bps"], 2e6, 0.25), explain(results)
    assert d["rtt_ms"] is not None, explain(results)
    own_verdict(link, results)


def test_large_messages_dropped_on_the_way_are_named_before_the_path(ros2):
    """A size filter on the master's router (its WAN link, what leaves it): small messages pass,
    1 MB ones do not; the first advice names large messages dropped."""
    try:
        cfg = ros2_cfg.loads_json5(ros2.router_config_path("robot").read_text())
        cfg["low_pass_filter"] = [{"id": "wan", "link_protocols": ["tls"], "flows": ["egress"],
                                   "messages": ["put"], "key_exprs": ["**"],
                                   "size_limit": 200_000}]
        ros2.write_router_config("robot", json.dumps(cfg, indent=2))
        ros2.start_router("robot")
        results = _linked_check(ros2, "laptop")
        assert results["ros2.pubsub_out"]["status"] == "pass", explain(results)
        assert results["ros2.pubsub_in"]["status"] == "pass", explain(results)
        link = results["ros2.link"]
        d = link["data"]["peers"]["turtlebot"]
        assert d["largest_in"] < 1 << 20 and d["tried_in"] == 1 << 20, explain(results)
        assert d["largest_out"] == 1 << 20, explain(results)
        assert link["status"] == "warn", explain(results)
        assert rules(link)[0] == "ros2.link.large_dropped", explain(results)
        first = link["advice"][0]
        assert "1 MB message sent that way never arrived whole" in first["meaning"], explain(results)
        assert "low_pass_filter" in " ".join(first["actions"]), explain(results)
    finally:    # the robot's router back on its own config (healthy() restarts no live router)
        ros2.write_router_config("robot")
        ros2.start_router("robot")      # the next test's fixture waits for the link again


def test_at_64_kbit_the_check_ends_in_its_budget_and_reports_what_it_measured(ros2):
    """At 64 kbit/s (a deep buffer, as a thin mobile link has) the round's peer agent starts in
    time (its programs go compressed: about 20 kB, not 58), so ros2.link reaches the other side:
    it ends within its budget with the round trip and the rates it measured, says the large
    messages were not tried and why, and never floods the line past its budget."""
    ros2.shape_robot("64kbit", latency="2s")
    results = ros2.check("laptop", timeout=180)
    assert "turtlebot" in results["ros2.link"]["data"]["peers"], explain(results)
    measured_thin(results, "ros2.link", 64e3, 0.5, "64 kB")


def test_on_a_thin_link_it_reports_what_it_measured_in_its_budget(ros2):
    """At 256 kbit/s the pings and both bursts fit the budget, 1 MB does not (about 33 s): the
    rates are reported, and the large message is said not tried, with why."""
    ros2.shape_robot("256kbit", latency="1s")
    measured_thin(ros2.check("laptop", timeout=180), "ros2.link", 256e3, 0.35, "1 MB")



@pytest.mark.parametrize("delay_ms", [40, 120])
def test_the_round_trip_follows_a_delay_added_on_the_path(ros2, delay_ms):
    """A userspace hop on the robot's modem (this kernel has no netem) holds every chunk
    *delay_ms* each way between the laptop's router and the master's: the round trip ros2.link
    measures is the added 2 x delay (plus the lab's own, about a millisecond) within 20 %."""
    results = _linked_check(ros2, "laptop")
    base = results["ros2.link"]["data"]["peers"]["turtlebot"]["rtt_ms"]
    assert base is not None, explain(results)
    with ros2.delay_to_master(delay_ms):
        results = _linked_check(ros2, "laptop")     # its router linked again, through the hop
    measured_delay(results, "ros2.link", base, delay_ms)
