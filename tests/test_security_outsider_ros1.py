"""security.outsider under ROS 1 on loopback: a real sshd as the peer (the insider), a small web
server as the echoip-style port checker (the outsider), our listener on a spare port of the range.
"""

from __future__ import annotations

import socket
from dataclasses import replace

from rosnet_tui.core.checks import REGISTRY, load_builtin_checks, run_check
from rosnet_tui.core.config.settings_model import (
    ProbeSettings,
    RosSettings,
    Settings,
    ThisComponent,
)
from rosnet_tui.core.net import listener
from tests.builders import free_port


def _settings(ssh_client, web) -> Settings:
    return Settings(this=ThisComponent(name="robot", role="master", profile="remote",
                                       local_ip="127.0.0.1", public_ip="127.0.0.1"),
                    peers=[ssh_client.peer()],
                    ros=RosSettings(master="robot", port=free_port(), version=1,
                                    security="firewall"),
                    probe=ProbeSettings(port_check_url=web.url("")))


async def test_a_spare_port_already_taken_is_passed_over(ssh_client, web, monkeypatch):
    # A busy port of the range (here: one we hold; on a robot: a connection's ephemeral port)
    # used to end the check with "cannot listen on port N": the next candidate is taken instead.
    web.fallback = lambda path: (200, '{"reachable": false}')
    busy = socket.socket()
    busy.bind(("0.0.0.0", 0))
    busy.listen()
    taken, free = busy.getsockname()[1], free_port()
    real = listener.random_ports
    monkeypatch.setattr(listener, "random_ports",
                        lambda n, avoid=(): [taken, free, *real(n, avoid)][:max(n, 2)])
    load_builtin_checks()
    try:
        r = await run_check(REGISTRY["security.outsider"], ssh_client.ctx(_settings(ssh_client,
                                                                                     web)))
    finally:
        busy.close()
    assert r.status.value == "pass", (r.summary, r.evidence)
    assert r.data["ports"] == [free], r.data
    assert f"/port/{free}" in " ".join(web.hits)


# ---- issue 29: the set-up screen asks for no public IP; isp.public_ip measures it
def _wizard_settings(ssh_client, web, urls: list[str]) -> Settings:
    s = _settings(ssh_client, web)
    return replace(s, this=replace(s.this, public_ip=""),
                   probe=replace(s.probe, public_ip_urls=urls))


async def test_without_a_public_ip_in_the_settings_the_measured_one_is_tested(ssh_client, web):
    web.routes["/ip"] = (200, "127.0.0.1\n")
    web.fallback = lambda path: (200, '{"reachable": false}')
    load_builtin_checks()
    r = await run_check(REGISTRY["security.outsider"],
                        ssh_client.ctx(_wizard_settings(ssh_client, web, [web.url("/ip")])))
    assert r.status.value == "pass", (r.summary, r.evidence)
    assert r.data["target"] == "127.0.0.1" and all(r.data["insider_reachable"].values()), r.data
    assert "/ip" in web.hits


async def test_the_rounds_own_measurement_is_read_not_asked_again(ssh_client, web):
    web.routes["/ip"] = (200, "127.0.0.1\n")
    web.fallback = lambda path: (200, '{"reachable": false}')
    load_builtin_checks()
    ctx = ssh_client.ctx(_wizard_settings(ssh_client, web, [web.url("/ip")]))
    measured = await run_check(REGISTRY["isp.public_ip"], ctx)
    assert measured.data["public_ip"] == "127.0.0.1", measured
    ctx.results[measured.id] = measured           # what run_checks does as a result lands
    asked = web.hits.count("/ip")
    r = await run_check(REGISTRY["security.outsider"], ctx)
    assert r.status.value == "pass", (r.summary, r.evidence)
    assert r.data["target"] == "127.0.0.1"
    assert web.hits.count("/ip") == asked         # the round's address, no second ask


async def test_no_public_ip_anywhere_skips_saying_why(ssh_client, web):
    web.routes["/ip"] = (503, "busy")
    web.fallback = lambda path: (200, '{"reachable": false}')
    load_builtin_checks()
    r = await run_check(REGISTRY["security.outsider"],
                        ssh_client.ctx(_wizard_settings(ssh_client, web, [web.url("/ip")])))
    assert r.status.value == "skip", (r.summary, r.evidence)
    assert "public IP is unknown" in r.summary and "isp.public_ip" in r.summary, r.summary
    assert not any(h.startswith("/port/") for h in web.hits)   # nothing asked of the checker
