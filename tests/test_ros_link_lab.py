"""ros.link on the network lab (issue 31, ROS 1): the link to each peer measured over TCPROS
through the modems' forwards (round trip, throughput each way, the largest message delivered
whole), with the robot's modem shaped by `tc tbf` both ways (this kernel has no netem) and a
need from [[link.topic]] compared. The ROS 2 twin is tests/test_ros2_link_lab.py."""

from __future__ import annotations

import pytest

from tests.lab.delay_sites import delay_between_sites
from tests.lab.firewall import secured
from tests.lab.verdicts import (
    explain,
    lab_check,
    measured_delay,
    measured_thin,
    measured_unshaped,
    needing,
    own_verdict,
    within,
)

pytestmark = pytest.mark.lab


def test_unshaped_the_link_passes_with_its_figures(ros1_lab):
    lab = ros1_lab
    lab.reset()
    with secured(lab):                     # ROS 1 as the product sets it up: the firewall on
        both = {h: lab_check(lab, h, step="ros") for h in ("laptop", "robot")}
    for host, peer in (("laptop", "turtlebot"), ("robot", "sami")):
        measured_unshaped(both[host], "ros.link", peer)


def test_shaped_to_2_mbit_each_way_the_rates_a_round_trip_and_the_need(ros1_lab):
    lab = ros1_lab
    lab.reset()
    lab.shape_robot("2mbit")
    try:
        # From the robot, a need of 10 x 50 kB (4.0 Mbit/s): the rates and a warning with them.
        results = lab_check(lab, "robot", step="ros", config=needing(lab.settings("robot"), lab.home("robot"), 50_000, 10))
        link = results["ros.link"]
        d = link["data"]["peers"]["sami"]
        assert within(d["out_bps"], 2e6, 0.25) and within(d["in_bps"], 2e6, 0.25), \
            explain(results)
        assert d["rtt_ms"] is not None and link["data"]["need_bps"] == 4e6, explain(results)
        own_verdict(link, results)
        assert link["status"] in ("warn", "fail"), explain(results)
        assert "needs 4.0 Mbit/s up, measured 1." in link["summary"] or \
            "needs 4.0 Mbit/s up, measured 2." in link["summary"], explain(results)
        assert "needs 4.0 Mbit/s down, measured" in link["summary"], explain(results)
        thin = next(a for a in link["advice"] if a["rule"] == "ros2.link.too_thin")
        assert "4.0 Mbit/s" in thin["meaning"] and "compressed" in " ".join(thin["actions"])
        assert "downsampling" not in " ".join(thin["actions"]), thin   # Zenoh's: not ROS 1's
        # From the laptop, no need: the rates each way (up is the laptop's: the robot's download).
        results = lab_check(lab, "laptop", step="ros")
        link = results["ros.link"]
        d = link["data"]["peers"]["turtlebot"]
        assert within(d["out_bps"], 2e6, 0.25) and within(d["in_bps"], 2e6, 0.25), \
            explain(results)
        assert d["rtt_ms"] is not None, explain(results)
        own_verdict(link, results)
    finally:
        lab.reset()


def test_on_a_thin_link_it_reports_what_it_measured_in_its_budget(ros1_lab):
    """At 256 kbit/s the pings and both bursts fit the budget, 1 MB does not (about 33 s): the
    rates are reported, and the large message is said not tried, with why."""
    lab = ros1_lab
    lab.reset()
    lab.shape_robot("256kbit", latency="1s")
    try:
        measured_thin(lab_check(lab, "laptop", step="ros", timeout=180), "ros.link", 256e3,
                      0.35, "1 MB")
    finally:
        lab.reset()


def test_at_64_kbit_the_check_ends_in_its_budget_and_says_what_it_has(ros1_lab):
    """At 64 kbit/s (a deep buffer, as a thin mobile link has) the round's peer agent takes
    seconds to start (its programs go over SSH): ros.link still ends within its budget with a
    verdict that says what it measured or why not, never a bare timeout."""
    lab = ros1_lab
    lab.reset()
    lab.shape_robot("64kbit", latency="2s")
    try:
        results = lab_check(lab, "laptop", step="ros", timeout=180)
        link = results["ros.link"]
        print(explain({"ros.link": link}))
        own_verdict(link, results)
        assert link["summary"], explain(results)
        d = link["data"]["peers"].get("turtlebot") or {}
        if link["status"] == "pass":      # measured: the rates are about the shaping's
            assert d["out_bps"] is None or d["out_bps"] < 128e3, explain(results)
    finally:
        lab.reset()


@pytest.mark.parametrize("delay_ms", [40, 120])
def test_the_round_trip_follows_a_delay_added_on_the_path(ros1_lab, delay_ms):
    """A userspace hop on the robot's modem (this kernel has no netem) holds every chunk
    *delay_ms* each way on every TCP connection between the sites (XML-RPC to the master and the
    nodes, TCPROS between the probe nodes, both directions; tests/lab/delay_sites.py): the round
    trip ros.link measures is the added 2 x delay (plus the lab's own) within 20 %."""
    lab = ros1_lab
    lab.reset()
    results = lab_check(lab, "laptop", step="ros")
    base = results["ros.link"]["data"]["peers"]["turtlebot"]["rtt_ms"]
    assert base is not None, explain(results)
    with delay_between_sites(lab, delay_ms):
        results = lab_check(lab, "laptop", step="ros")
    measured_delay(results, "ros.link", base, delay_ms)
