"""Removing a member from a ROS 2 fleet under mutual TLS is one command on the master
(tests/lab/fleet_ros2.py, three sites): `rosnet-tui ros pair --remove member2` makes a new CA,
re-pairs sami over SSH (sami's key stays on sami), and after the routers restart sami links
again while member2's router, still holding the old CA's certificate, is refused."""

from __future__ import annotations

import time

import pytest

from rosnet_tui.core.ros import fleet_tls

pytestmark = pytest.mark.lab
FLEET_SITES = 3


def test_removing_a_member_rotates_the_ca_and_re_pairs_the_rest(fleet_ros2_world):
    lab = fleet_ros2_world.lab
    master = lab.master
    sami_key = fleet_ros2_world.tls_paths("sami").node_key.read_bytes()
    old_ca = fleet_tls.ca_key_id(fleet_ros2_world.tls_paths(master).ca_crt)
    t0 = time.monotonic()
    r = lab.rosnet(master, "ros", "pair", "--remove", "member2", "--yes", "--config",
                   str(fleet_ros2_world.config_path(master)), env=fleet_ros2_world.env(master), timeout=60)
    took = time.monotonic() - t0
    print(f"remove + re-pair of 1 member: {took:.2f} s (whole CLI process)\n{r.stdout}")
    assert r.returncode == 0, r.stdout + r.stderr
    assert "sami: re-paired" in r.stdout and "member2:" not in r.stdout   # not re-paired
    new_ca = fleet_tls.ca_key_id(fleet_ros2_world.tls_paths(master).ca_crt)
    assert new_ca != old_ca
    sami = fleet_ros2_world.tls_paths("sami")
    assert sami.node_key.read_bytes() == sami_key          # the member's key never moved
    assert fleet_tls.cert_summary(sami.node_crt)["issuer_key_id"] == new_ca
    assert fleet_tls.ca_key_id(fleet_ros2_world.tls_paths("member2").ca_crt) == old_ca
    for h in lab.COMPUTERS:
        fleet_ros2_world.stop_router(h)
    fleet_ros2_world.start_routers()
    deadline = time.monotonic() + 20
    links = fleet_ros2_world.linked(timeout=2.0)
    while time.monotonic() < deadline and not links.get("sami"):
        time.sleep(0.5)
        links = fleet_ros2_world.linked(timeout=2.0)
    assert links == {"sami": True, "member2": False}, links
