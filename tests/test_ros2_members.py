"""Issue 31, from the master: which members' routers are linked to its router right now, read
from that router's own admin space (no SSH), and a member on another Zenoh release named.

The admin space is read from real Zenoh routers (eclipse-zenoh in router mode, what rmw_zenohd
is) on loopback, started from the configs `ros apply` writes; the version skew, which one Zenoh
install here cannot show, from the admin space's JSON as a router gives it."""

from __future__ import annotations

import json
import socket
import time
from dataclasses import replace

from rosnet_tui.core.checks.ros2 import linked_members, member_label, version_skew
from rosnet_tui.core.config.settings_model import Peer
from rosnet_tui.core.peer import zenohproto
from rosnet_tui.core.ros import ros2
from tests.builders import ros2_master, ros2_member

V_MASTER = "v1.8.0-3f2ac1d"


def _fleet():
    """The master turtlebot and two members: sami (198.51.100.2) and member2 (203.0.113.9)."""
    s = ros2_master(security="none")
    return replace(s, peers=[*s.peers, Peer(name="member2", public_ip="203.0.113.9",
                                            ssh_user="me")])


def _info(*members: tuple[str, str, str | None, dict | None]) -> dict:
    """The master router's info as router_info(others=True) returns it: (zid, link dst,
    version, metadata) per member router, and a client session besides."""
    return {"zid": "aa01", "version": V_MASTER,
            "sessions": [{"zid": "cc07", "whatami": "client", "links": ["tcp/127.0.0.1:40000"]},
                         *[{"zid": z, "whatami": "router", "links": [dst]}
                           for z, dst, _v, _m in members]],
            "routers": {z: {"version": v, "metadata": m} for z, _d, v, m in members}}


def test_members_are_named_by_their_metadata_else_by_the_public_ip_they_came_from():
    info = _info(("0b1", "tcp/198.51.100.2:51220", V_MASTER, {"name": "sami", "role": "member"}),
                 ("0b2", "tcp/203.0.113.9:40122", V_MASTER, None),
                 ("0b3", "tcp/192.0.2.50:33000", None, {"name": 7}))
    got = linked_members(info, _fleet())
    assert got == [
        {"zid": "0b1", "name": "sami", "version": V_MASTER, "address": "198.51.100.2:51220"},
        {"zid": "0b2", "name": "member2", "version": V_MASTER, "address": "203.0.113.9:40122"},
        {"zid": "0b3", "name": None, "version": None, "address": "192.0.2.50:33000"}]
    assert member_label(got[2]) == "router 0b3 from 192.0.2.50:33000"


def test_a_member_on_another_zenoh_release_is_named_and_only_that_one():
    info = _info(("0b1", "tcp/198.51.100.2:51220", "v1.8.0-3f2ac1d", {"name": "sami"}),
                 ("0b2", "tcp/203.0.113.9:40122", "v1.4.0", {"name": "member2"}),
                 ("0b3", "tcp/192.0.2.50:33000", None, None))
    members = linked_members(info, _fleet())
    # the same release built from another commit is no skew; an unknown version is not either
    assert version_skew(members, V_MASTER) == ["member2"]
    info["routers"]["0b3"]["version"] = "v1.10.2-cc83980"
    assert version_skew(linked_members(info, _fleet()), V_MASTER) == [
        "member2", "router 0b3 from 192.0.2.50:33000"]
    assert version_skew(members, None) == []       # the master's own version unknown


def test_a_members_metadata_name_is_shown_safely():
    info = _info(("0b1", "tcp/198.51.100.2:51220", V_MASTER, {"name": "sa\x1b[2Jmi" + "x" * 200}))
    name = linked_members(info, _fleet())[0]["name"]
    assert "\x1b" not in name and len(name) <= 64


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _router(cfg: dict, listen: str, connect: list[str]):
    import zenoh

    cfg = dict(cfg, listen={"endpoints": [listen]}, connect={"endpoints": connect})
    return zenoh.open(zenoh.Config.from_json5(json.dumps(cfg)))


def test_the_masters_router_lists_its_linked_members_with_name_version_and_address():
    """Three real routers from the written configs (the members dial the master's on loopback):
    the master's admin space lists both members' routers, named by the metadata their configs
    carry, with Zenoh's version and the address each came from."""
    port = _free_port()
    mcfg = ros2.router_config(ros2_master(security="none"))
    assert mcfg["metadata"] == {"name": "turtlebot", "role": "master"}
    routers = [_router(mcfg, f"tcp/127.0.0.1:{port}", [])]
    client = None
    try:
        for name in ("sami", "member2"):
            s = ros2_member(security="none")
            s = replace(s, this=replace(s.this, name=name))
            cfg = ros2.router_config(s)
            assert cfg["metadata"] == {"name": name, "role": "member"}
            routers.append(_router(cfg, f"tcp/127.0.0.1:{_free_port()}",
                                   [f"tcp/127.0.0.1:{port}"]))
        client = zenohproto.open_client(f"tcp/127.0.0.1:{port}", 5.0)
        deadline = time.monotonic() + 15
        while True:
            info = zenohproto.router_info(client, 1.0, others=True)
            members = linked_members(info, _fleet())
            if len(members) == 2 and all(m["version"] for m in members) \
                    or time.monotonic() > deadline:
                break
            time.sleep(0.1)
        assert sorted(m["name"] for m in members) == ["member2", "sami"], info
        assert all(m["version"] == info["version"] for m in members), info
        assert all(m["address"].startswith("127.0.0.1:") for m in members), members
        assert version_skew(members, info["version"]) == []
    finally:
        if client is not None:
            client.close()
        for r in reversed(routers):
            r.close()
