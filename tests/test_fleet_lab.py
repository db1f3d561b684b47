"""The fleet lab at its largest (tests/lab/fleet.py): nine sites, a master and eight members, each a
computer behind its own modem on the lab's internet. The network works as the procedure says from
every site, ROS 2 runs on it with every member's router linked to the master's, and a full ros2.*
verification passes from the master and from a member.
"""

from __future__ import annotations

import json
import os
import tempfile
import time
from pathlib import Path

import pytest

from tests.lab import procs
from tests.lab.firewall import apply_firewall, remove_firewall
from tests.lab.fleet import Fleet
from tests.lab.fleet_ros2 import ROS2_IDS, FleetRos2
from tests.lab.verdicts import explain

pytestmark = pytest.mark.lab
FLEET_SITES = 9
SSH = ["ssh", "-o", "BatchMode=yes", "-o", "StrictHostKeyChecking=yes", "-o", "ConnectTimeout=5"]


def test_nine_sites_build_fast_and_each_shows_its_own_public_address(fleet):
    print(f"fleet of {len(fleet.sites)} built in {fleet.build_s['total']:.2f} s: "
          + ", ".join(f"{k} {v:.2f}" for k, v in fleet.build_s.items() if k != "total"))
    # The network itself: typically 0.3-0.7 s; generous for a loaded machine. Installing
    # rosnet-tui in every home is apart: the first build of a source tree makes the cached
    # virtual environment (about 15 s), later builds link it (about 1 s for 9 homes).
    network = fleet.build_s["total"] - fleet.build_s["install"]
    assert network < 10.0
    assert len(fleet.members) == 8 and fleet.master == "turtlebot"
    publics = [fleet.public_ip(h) for h in fleet.COMPUTERS]
    assert len(set(publics)) == 9
    assert all(ip.startswith(("192.0.2.", "198.51.100.", "203.0.113.")) for ip in publics)
    for host in fleet.COMPUTERS:
        status, body = fleet.http_get(host, "http://probe.lab.test/ip")
        assert (status, body.strip()) == (200, fleet.public_ip(host)), (host, body)


def test_every_computer_reaches_every_other_by_name_over_ssh_with_a_verified_key(fleet):
    fleet.reset()
    for host, other in (("member8", "member2"), ("member2", "turtlebot"), ("turtlebot", "member8"),
                        ("sami", "member5")):
        r = fleet.run(host, [*SSH, f"root@{other}", "hostname; echo $HOME"], timeout=20)
        assert r.returncode == 0, r.stderr
        assert r.stdout.split() == [other, str(fleet.home(other))]
    # The hosts file names the others by their public address: the key is known by name only.
    r = fleet.run("member8", [*SSH, f"root@{fleet.public_ip('member2')}", "true"], timeout=20)
    assert r.returncode != 0 and "Host key verification failed" in r.stderr, r.stderr


def test_a_member_modem_forwards_only_what_its_mode_says(fleet):
    fleet.reset()
    try:
        fleet.set_forwarding("member3", "none")
        r = fleet.run("member4", [*SSH[:-1], "ConnectTimeout=1", "root@member3", "true"],
                      timeout=20)
        assert r.returncode != 0 and "timed out" in r.stderr, r.stderr
        fleet.set_forwarding("member3", "ssh")
        r = fleet.run("member4", [*SSH, "root@member3", "true"], timeout=20)
        assert r.returncode == 0, r.stderr
    finally:
        fleet.reset()


def test_the_masters_modem_gets_a_new_public_address_and_reset_puts_the_old_back(fleet):
    """Fleet.set_public_ip (bench row 8's sync fan-out): the new address is what the internet
    sees and what reaches the master; the hosts files are not touched; reset() restores."""
    fleet.reset()
    built = fleet.public_ip("turtlebot")
    hosts = fleet.hosts_path("member5").read_text()
    try:
        fleet.set_public_ip("turtlebot", "203.0.113.77")
        assert fleet.http_get("turtlebot", "http://probe.lab.test/ip")[1].strip() == "203.0.113.77"
        r = fleet.run("member5", [*SSH, "-o", "HostKeyAlias=turtlebot", "root@203.0.113.77",
                                  "hostname"], timeout=20)   # the key verified by name
        assert (r.returncode, r.stdout.strip()) == (0, "turtlebot"), r.stderr
        assert fleet.hosts_path("member5").read_text() == hosts
        with pytest.raises(ValueError):
            fleet.set_public_ip("turtlebot", "10.0.0.1")   # not a lab public address
        with pytest.raises(ValueError):
            fleet.set_public_ip("turtlebot", fleet.public_ip("member2"))   # taken
    finally:
        fleet.reset()
    assert fleet.http_get("turtlebot", "http://probe.lab.test/ip")[1].strip() == built
    r = fleet.run("member5", [*SSH, "root@turtlebot", "hostname"], timeout=20)
    assert (r.returncode, r.stdout.strip()) == (0, "turtlebot"), r.stderr


def test_nine_site_ros2_every_member_linked_and_every_check_passes_from_master_and_member(fleet):
    with FleetRos2(fleet) as w:
        print(f"ROS 2 on {len(fleet.sites)} sites: routers up and linked in {w.start_s:.2f} s")
        assert w.linked() == dict.fromkeys(fleet.members, True)
        w.node("turtlebot", "talker")
        w.node("member4", "talker", name="talker4", topic="/status")
        listener = w.node("member8", "listener")
        assert fleet.wait_output(listener, r"heard: hello from turtlebot \d+ \(attachment ok\)",
                                 timeout=15), fleet.output(listener)
        expected = {"/talker": "turtlebot", "/talker4": "member4", "/listener": "member8"}
        for host in ("turtlebot", "member8"):
            t0 = time.monotonic()
            results = w.check(host)
            took = time.monotonic() - t0
            print(f"ros2.* from {host} with {len(fleet.sites) - 1} peers: {took:.2f} s")
            assert list(results) == ROS2_IDS, explain(results)
            assert all(c["status"] == "pass" for c in results.values()), explain(results)
            graph = results["ros2.graph"]["data"]
            others = [h for h in fleet.COMPUTERS if h != host]
            assert graph["probe_seen"] == dict.fromkeys(others, True), explain(results)
            assert {n["name"]: n["component"] for n in graph["nodes"]} == expected, explain(results)
            for cid in ("ros2.pubsub_out", "ros2.pubsub_in"):
                assert sorted(results[cid]["data"]["peers"]) == sorted(others), explain(results)
        for host in ("turtlebot", "member8"):    # every step: nothing fails or warns
            results = full_check(fleet, host, w.env(host))
            assert not [c for c in results.values() if c["status"] in ("fail", "warn")], \
                explain(results)
            assert all(results[cid]["status"] == "pass" for cid in ROS2_IDS), explain(results)


def test_nine_site_ros1_every_check_passes_from_master_and_member(fleet):
    fleet.reset()                     # ROS 1: every modem forwards 1024-65000 to its computer
    fleet.start_roscore()
    try:
        fleet.talker("member8")
        listener = fleet.listener("sami")
        assert fleet.wait_output(listener, r"heard: hello from member8 \d+", timeout=20), \
            fleet.output(listener)
        for host in ("turtlebot", "member8"):
            apply_firewall(fleet, host, fleet_config(fleet, host))  # ROS 1 as set up
            t0 = time.monotonic()
            try:
                results = full_check(fleet, host, fleet.ros_env(host))
            finally:
                remove_firewall(fleet, host)
            print(f"ROS 1, every check from {host} with {len(fleet.sites) - 1} peers: "
                  f"{time.monotonic() - t0:.2f} s")
            assert results and all(c["status"] == "pass" for c in results.values()), \
                explain(results)
            assert "ros.pubsub_in" in results
    finally:
        fleet.stop_roscore()
        fleet.reset()


def fleet_config(fleet: Fleet, host: str) -> Path:
    return fleet.home(host) / ".config" / "rosnet-tui" / "config.toml"


def full_check(fleet: Fleet, host: str, env: dict[str, str]) -> dict[str, dict]:
    """`rosnet-tui check --json` (every step) on *host*: {check id: entry}."""
    r = fleet.rosnet(host, "check", "--json", "--config", str(fleet_config(fleet, host)),
                     env=env, timeout=120)
    assert r.stdout.strip(), r.stderr
    return {c["id"]: c for c in json.loads(r.stdout)["checks"]}


def test_a_fleet_tears_down_to_nothing(lab_session):
    other = Fleet(2).build()
    prefix, inodes = other.prefix, list(other._netns_inodes)
    try:
        other.spawn("sami", ["sleep", "300"])
        pids = other.lab_pids()
        assert len(pids) >= 5   # 2 sshd, probe, dns, sleep
    finally:
        other.destroy()
    left = [n for n in os.listdir("/run/netns") if n.startswith(prefix)] if \
        os.path.isdir("/run/netns") else []
    left += [str(d) for d in Path(tempfile.gettempdir()).glob(prefix + "*")]
    left += [n for n in os.listdir("/etc/netns") if n.startswith(prefix)] if \
        os.path.isdir("/etc/netns") else []
    assert left == []
    assert procs.pids_in_netns(inodes) == []
    assert [p for p in pids if procs.alive(p)] == []
