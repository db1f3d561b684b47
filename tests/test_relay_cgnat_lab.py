"""Both sites behind carrier NAT, joined through the relay the user owns (issue 30's "done when"),
set up on the lab with the product's own commands only (tests/lab/relay_cgnat.py): `ros apply`
and `relay apply` on the master, the relay's unit's `relay serve` on the relay, `relay tunnel` on
both computers, `ros apply` on the member (pairing through the relay). Then:

- from both seats `rosnet-tui check` exits 0 and every check passes (ros2.*, relay.*, linux.ssh
  through the jump, security.*);
- an outsider on the lab's internet gets no Zenoh session at the relay (plain TCP, TLS without a
  certificate, with a foreign CA's) and no password prompt from the relay's sshd;
- the tunnel's connection killed on the relay: the member's linux.ssh to the robot passes again
  within 10 s."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys

import pytest

from tests.lab import outsider
from tests.lab.relay_cgnat import TUNNELS, RelayCgnat
from tests.lab.topology import ADDR, COMPUTERS
from tests.lab.verdicts import explain

pytestmark = pytest.mark.lab


@pytest.fixture(scope="module")
def world(lab):
    with RelayCgnat(lab) as w:
        yield w


def check(w: RelayCgnat, host: str, timeout: float = 180):
    """`rosnet-tui check --json` on *host*, every step: (exit code, {id: entry})."""
    r = w.lab.rosnet(host, "check", "--json", env=w.env(host), timeout=timeout)
    assert r.stdout.strip(), r.stderr
    return r.returncode, {c["id"]: c for c in json.loads(r.stdout)["checks"]}


# linux.ssh as `check` runs it, on the member: once (READY), then after a line on stdin again
# and again until it passes or 10 s went by (DONE): the interpreter starts before the clock does.
POLL = r"""
import json, sys, time
from rosnet_tui.core.checks.runner import RunOptions, run_now, select
from rosnet_tui.core.config.paths import default_config_path
from rosnet_tui.core.saved.settings import load_settings
s = load_settings(default_config_path())
specs = select(ids=["linux.ssh"])
def once():
    return run_now(s, specs, RunOptions(upnp=False))[0]
print("READY " + once().status.value, flush=True)
sys.stdin.readline()
t0, tries = time.monotonic(), []
while True:
    r = once()
    tries.append([round(time.monotonic() - t0, 2), r.status.value])
    if r.status.value == "pass" or time.monotonic() - t0 > 10:
        break
    time.sleep(0.1)
print("DONE " + json.dumps({"status": r.status.value, "took": time.monotonic() - t0,
                            "tries": tries, "evidence": r.evidence}), flush=True)
"""


def test_the_sites_cannot_reach_each_other_only_the_relay(world):
    lab = world.lab
    said = world.said["robot: ros apply --yes --no-checks"].stdout
    assert "Next, the relay relay: `rosnet-tui relay apply`" in said, said    # what comes next
    assert lab.public_ip("robot") == ADDR.CARRIER_PUBLIC
    assert lab.public_ip("laptop") == ADDR.LAPTOP_CARRIER_PUBLIC
    for host in COMPUTERS:    # nothing of the other site answers at its settings' public IP
        other = "laptop" if host == "robot" else "robot"
        r = lab.run(host, ["ssh", "-o", "BatchMode=yes", "-o", "ConnectTimeout=2",
                           f"root@{lab.settings_public_ip(other)}", "true"], timeout=15)
        assert r.returncode != 0


def test_every_check_passes_from_both_seats(world):
    for host in COMPUTERS:
        rc, results = check(world, host)
        bad = {i: c for i, c in results.items() if c["status"] not in ("pass", "skip")}
        assert rc == 0 and not bad, explain(results)
        # isp.cgnat states a fact (the site is behind a carrier's NAT) that the relay answers:
        # no problem, nothing asked.
        assert results["isp.cgnat"]["status"] == "pass", explain(results)
        assert "dials out to the relay" in results["isp.cgnat"]["summary"], explain(results)
        for must in ("relay.router", "relay.tunnel", "ros2.router", "ros2.graph",
                     "ros2.pubsub_out", "ros2.pubsub_in", "linux.ssh", "security.outsider",
                     "security.ssh_auth"):
            assert results[must]["status"] == "pass", (must, explain(results))
        assert "through the relay" in results["linux.ssh"]["evidence"][0], explain(results)


def test_an_outsider_gets_no_session_at_the_relay_and_no_password_prompt(world):
    lab = world.lab
    ca = world.tls_paths("robot").ca_crt       # the fleet's CA certificate is no secret
    tries = {"plain": outsider.zenoh_session(lab, ADDR.RELAY_IP, 7447),
             "no certificate": outsider.zenoh_session(lab, ADDR.RELAY_IP, 7447,
                                                      no_cert_ca=str(ca)),
             "foreign CA": outsider.zenoh_session(lab, ADDR.RELAY_IP, 7447, tls=True)}
    for how, got in tries.items():
        assert got["session"] is False and got.get("error"), (how, got)
    got = outsider.ssh_auth_none(lab, ADDR.RELAY_IP)
    assert got.get("methods") == ["publickey"], got          # no password, no keyboard prompt


def _tunnel_sessions(w: RelayCgnat, port: int) -> list[int]:
    """The relay's sshd processes holding the reverse tunnel's listening port (``ss``)."""
    r = w.lab.run("relay", ["ss", "-Htlnp", f"sport = :{port}"], timeout=10)
    return sorted({int(pid) for pid in re.findall(r"pid=(\d+)", r.stdout)})


def test_a_tunnel_killed_on_the_relay_is_back_within_10_s(world):
    poll = world.lab.spawn("laptop", [sys.executable, "-c", POLL], env=world.env("laptop"),
                           stdin=subprocess.PIPE)
    try:
        ready = world.lab.wait_output(poll, r"READY \w+", timeout=30)
        assert ready is not None and ready.group(0) == "READY pass", world.lab.output(poll)
        held = _tunnel_sessions(world, TUNNELS["robot"])
        assert held, "no sshd on the relay holds the robot's tunnel"
        for pid in held:
            os.kill(pid, signal.SIGKILL)
        poll.stdin.write("go\n")
        poll.stdin.flush()
        done = world.lab.wait_output(poll, r"DONE (.*)", timeout=40)
        assert done is not None, world.lab.output(poll)
        got = json.loads(done.group(1))
        assert got["status"] == "pass" and got["took"] <= 10.0, got
        again = _tunnel_sessions(world, TUNNELS["robot"])
        assert again and not set(again) & set(held), (held, again)    # a new tunnel session
    finally:
        world.lab.kill(poll)


def test_the_relay_stopped_fails_relay_router_in_time_and_advice_names_the_relay(world):
    world.stop_relay()
    try:
        results = world.check("laptop")
        relay = results["relay.router"]
        assert relay["status"] == "fail", explain(results)
        timeout = world.settings("laptop").checks.timeout_s
        assert relay["duration_s"] <= timeout + 0.5, explain(results)
        advice = relay.get("advice") or []
        assert advice and advice[0]["rule"] == "relay.router.down", explain(results)
    finally:
        world.start_relay()
