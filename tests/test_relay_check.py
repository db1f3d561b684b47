"""relay.router (issue 30) against a real relay: `rosnet-tui relay serve` (the Zenoh router of
eclipse-zenoh) on loopback with the fleet's mutual TLS. It passes with this component's fleet
certificate, fails naming the TLS refusal with a foreign one, fails within timeout_s + 0.5 s once
the relay is stopped, and the advisor's first finding then names the relay. ros2.router under a
relay checks the path to the relay."""

from __future__ import annotations

import asyncio
import signal
import time
from pathlib import Path

import pytest
import zenoh  # noqa: F401  a hard dependency: a broken install fails here, never skips

from rosnet_tui.core.advisor import advise
from rosnet_tui.core.checks import REGISTRY, CheckContext, load_builtin_checks, run_check
from rosnet_tui.core.config.paths import Paths
from rosnet_tui.core.config.settings_model import RelaySettings
from rosnet_tui.core.results import CheckResult, Status
from rosnet_tui.core.ros import fleet_tls, pairing, relay, ros2
from rosnet_tui.core.ssh.options import SshOptions
from tests.builders import ros2_master, ros2_member
from tests.test_relay import _free_port, _wait_line, serve


@pytest.fixture
def fleet(tmp_path, monkeypatch):
    """A fleet CA (the master's), the relay's certificate naming "localhost" (the relay's name
    here), this component's (sami's) under XDG_CONFIG_HOME, and a relay serving on loopback."""
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg"))
    port = _free_port()
    mp = fleet_tls.tls_paths(tmp_path / "m")
    pairing.prepare_master(ros2_master(), mp)

    def signed(paths, name):
        ca, cert = fleet_tls.sign_request(mp, fleet_tls.make_request(paths, name),
                                          master="turtlebot", members=["sami"], relay="localhost")
        fleet_tls.install(paths, ca, cert)
        return paths

    rp = signed(fleet_tls.tls_paths(tmp_path / "relay"), "localhost")
    mine = signed(fleet_tls.tls_paths(tmp_path / "xdg" / "rosnet-tui"), "sami")
    cfg = relay.relay_router_config("localhost", port, rp)
    cfg["listen"]["endpoints"] = [f"tls/127.0.0.1:{port}"]          # loopback only in tests
    path = tmp_path / "relay.json5"
    path.write_text(ros2.render_json5(cfg, []))
    proc = serve(path)
    try:
        _wait_line(proc, "Relay router")
        s = ros2_member()
        s.relay = RelaySettings(host="localhost", zenoh_port=port)   # a name that resolves here
        yield type("Fleet", (), {"proc": proc, "settings": s, "port": port, "mine": mine,
                                 "tmp": tmp_path})
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait(5)


def ctx_of(tmp_path: Path, s, timeout: float = 2.0, env: dict | None = None) -> CheckContext:
    rc = tmp_path / "bashrc"
    rc.write_text("")
    return CheckContext(settings=s, timeout_s=timeout, env=env or {},
                        paths=Paths(state_dir=tmp_path / "state", hosts_path=tmp_path / "hosts",
                                    bashrc_path=rc), upnp=False,
                        ssh_options=SshOptions(ssh_agent=False, ssh_dir=tmp_path / "no-ssh"))


def run(ctx: CheckContext, cid: str) -> CheckResult:
    load_builtin_checks()
    return asyncio.run(run_check(REGISTRY[cid], ctx))


def test_relay_router_passes_with_the_fleet_certificate_and_says_why_not(fleet):
    res = run(ctx_of(fleet.tmp, fleet.settings), "relay.router")
    assert res.status is Status.PASS, (res.summary, res.evidence)
    assert res.data["reachable"] and res.data["router_zid"]
    assert res.data["endpoint"] == f"tls/localhost:{fleet.port}"
    # without [relay]: skipped
    assert run(ctx_of(fleet.tmp, ros2_member()), "relay.router").status is Status.SKIP
    # this component's certificate from another CA: the relay refuses it, and the check says so
    foreign = fleet_tls.make_test_ca(fleet.tmp / "f", "someone else")
    other = fleet_tls.tls_paths(fleet.tmp / "fm")
    fleet_tls.issue_test_cert(foreign, other, "sami")
    fleet.mine.node_key.write_bytes(other.node_key.read_bytes())
    fleet.mine.node_crt.write_bytes(other.node_crt.read_bytes())
    res = run(ctx_of(fleet.tmp, fleet.settings), "relay.router")
    assert res.status is Status.FAIL and res.data["failure"] == "not_zenoh"
    assert res.data["tls"]["handshake"] == "rejected_foreign", res.evidence
    assert "relay's router refused" in res.summary


def test_security_outsider_under_a_relay_judges_the_relay(fleet):
    res = run(ctx_of(fleet.tmp, fleet.settings, 3.0), "security.outsider")
    assert res.status is Status.PASS, (res.summary, res.evidence)
    assert res.data["target"] == f"localhost:{fleet.port}" and res.data["from"] == "here"
    assert {k: a["result"] != "accepted" for k, a in res.data["attempts"].items()} == \
        {"no_cert": True, "foreign": True, "plain": True, "insider": False}


def test_ros2_router_under_a_relay_checks_the_path_to_the_relay(fleet):
    s = fleet.settings
    env = {"ZENOH_CONFIG_OVERRIDE": ros2.client_override(s, fleet.mine)}   # a lone node here
    res = run(ctx_of(fleet.tmp, s, env=env), "ros2.router")
    assert res.status is Status.PASS, (res.summary, res.evidence)
    assert res.data["endpoint"] == f"tls/localhost:{fleet.port}"
    assert "relay" in res.summary


def test_a_stopped_relay_fails_within_the_timeout_and_is_named_first(fleet):
    fleet.proc.send_signal(signal.SIGTERM)
    assert fleet.proc.wait(10) == 0
    timeout = 1.0
    t0 = time.monotonic()
    res = run(ctx_of(fleet.tmp, fleet.settings, timeout), "relay.router")
    took = time.monotonic() - t0
    assert res.status is Status.FAIL and res.data["failure"] == "refused"
    assert took <= timeout + 0.5, took
    router = CheckResult("ros2.router", "ros", Status.FAIL, "no router", [], 0.1, 1.0,
                         {"failure": "refused", "endpoint": res.data["endpoint"],
                          "address": "127.0.0.1", "reachable": False})
    cgnat = CheckResult("isp.cgnat", "isp", Status.WARN, "carrier NAT", [], 0.1, 1.0,
                        {"cgnat": True})
    findings = advise([cgnat, res, router], fleet.settings)
    first = findings[0]
    assert first.rule == "relay.router.down" and "localhost" in first.meaning
    assert "relay serve" in " ".join(first.actions)
    assert "ros2.router" in first.check_ids
    assert not any(f.rule in ("ros2.router.not_running", "ros2.port.not_forwarded")
                   for f in findings)
    nat = next(f for f in findings if f.rule == "ros2.cgnat")
    assert nat.severity == "info" and "relay" in nat.meaning


def test_router_port_open_under_a_relay_tests_the_relay_s_port(fleet):
    """Under a relay no modem forwards anything (the master's neither): router.port_open was
    skipped, so a relay with its port shut in its provider's firewall went untested in the
    Router step. It now tests the relay's zenoh_port by name from here, master or member."""
    for s in (fleet.settings, ros2_master(security="mtls")):
        s.relay = RelaySettings(host="localhost", zenoh_port=fleet.port)
        res = run(ctx_of(fleet.tmp, s), "router.port_open")
        assert res.status is Status.PASS, (res.summary, res.evidence)
        assert res.data["zenoh_port_open"] is True and res.data["public_ip"] == "127.0.0.1"
        assert f"the relay's TCP {fleet.port} (localhost" in res.summary
        assert "no modem of the fleet forwards anything" in res.summary
    fleet.proc.send_signal(signal.SIGTERM)
    assert fleet.proc.wait(10) == 0
    res = run(ctx_of(fleet.tmp, fleet.settings, 1.0), "router.port_open")
    assert res.status is Status.FAIL and res.data["zenoh_port_open"] is False, res.summary
    assert "relay serve" in res.summary
    relay_res = run(ctx_of(fleet.tmp, fleet.settings, 1.0), "relay.router")
    first = advise([res, relay_res], fleet.settings)[0]
    assert first.rule == "relay.router.down" and "router.port_open" in first.check_ids


def test_router_upnp_does_not_call_a_relayed_master_a_member(tmp_path):
    """Under a relay the master's modem forwards nothing either: router.upnp's skip said "turtlebot
    is a ROS 2 member" of the master."""
    s = ros2_master(security="mtls")
    s.relay = RelaySettings(host="relay")
    ctx = ctx_of(tmp_path, s)
    ctx.upnp = True                  # skipped before any modem is asked
    res = run(ctx, "router.upnp")
    assert res.status is Status.SKIP and "member" not in res.summary, res.summary
    assert "under the relay every router connects out to relay, turtlebot's too" in res.summary
    ctx = ctx_of(tmp_path, ros2_member())       # a member without a relay: as before
    ctx.upnp = True
    plain = run(ctx, "router.upnp")
    assert plain.status is Status.SKIP and "sami is a ROS 2 member" in plain.summary
