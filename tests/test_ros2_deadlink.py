"""Issue 31, a dead link seen in seconds: what the router configs `ros apply` writes choose (lease,
keep-alive, connect retry), and on the lab that a member's router drops the master's when the
master's modem goes silent and links again by itself when it comes back (the timings are
bench row 9, bench/deadlink_row.py)."""

from __future__ import annotations

import json

import pytest

from rosnet_tui.core.ros import ros2
from tests.builders import ros2_master, ros2_member

pytest_plugins = ["tests.lab.fixtures"]


@pytest.mark.parametrize("security", ["none", "mtls"])
def test_the_written_router_configs_drop_a_silent_link_within_10_s_and_redial_every_4_s(
        security, tmp_path):
    from rosnet_tui.core.ros import fleet_tls

    paths = fleet_tls.tls_paths(tmp_path)
    for s in (ros2_master(security=security), ros2_member(security=security)):
        cfg = ros2.loads_json5(ros2.render_router_config(s, paths))
        tx = cfg["transport"]["link"]["tx"]
        assert (tx["lease"], tx["keep_alive"]) == (10_000, 4)    # a keep-alive every 2.5 s
        assert cfg["connect"]["retry"] == {"period_init_ms": 1000, "period_max_ms": 4000,
                                           "period_increase_factor": 2}


def test_the_lease_keys_are_zenohs_own():
    """Zenoh ignores a key it does not know without a word: the ones written must be its own."""
    import zenoh
    tx = json.loads(zenoh.Config().get_json("transport/link/tx"))
    assert {"lease", "keep_alive"} <= set(tx)
    assert "retry" in json.loads(zenoh.Config().get_json("connect"))
    cfg = zenoh.Config.from_json5(json.dumps(ros2.router_config(ros2_member(security="none"))))
    assert json.loads(cfg.get_json("transport/link/tx/lease")) == 10_000
    assert json.loads(cfg.get_json("connect/retry")) == ros2.CONNECT_RETRY


@pytest.mark.lab
def test_a_silent_master_is_dropped_and_relinked_by_itself_when_it_returns(ros2):
    """The master's modem drops everything both ways (no reset, no ICMP): the member's router
    drops the master's after its lease, `check` reports the master's router gone, and once the
    modem forwards again the member's router links again and the talker's data arrives, with no
    restart."""
    from bench.deadlink_row import measure_once

    r = measure_once(ros2)
    assert r["router_notice_s"] is not None, r
    assert r["check_router"] == "fail", r
    assert r["relinked_s"] is not None and r["data_again_s"] is not None, r
    print({k: v for k, v in r.items() if k.endswith("_s")})
