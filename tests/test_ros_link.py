"""ros.link (issue 31, ROS 1): the link measured over TCPROS, on loopback with a real roscore.

Two probe nodes of core/peer/roslink.py register with the master, subscribe to each other through
requestTopic and the TCPROS handshake, and measure; then the check end to end with the peer's side
run by the round's ROS 1 agent over a real sshd (this machine itself as the peer).
"""

from __future__ import annotations

import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from rosnet_tui.core.checks import REGISTRY, CheckContext, checks_for, run_check
from rosnet_tui.core.checks.probes.agents import ROSLINK_SOURCE, ROSPROTO_SOURCE
from rosnet_tui.core.config.settings_model import LinkTopic, RosSettings
from rosnet_tui.core.peer import rosproto
from rosnet_tui.core.peer.roslink import LinkEnd, LinkNode, link_frame, rate_bps
from rosnet_tui.core.results import Status
from tests.plugins.roscore import RosCore
from tests.plugins.ssh import ros_sshd
from tests.test_checks_ros import loopback_env, loopback_settings, make_ctx

ENV = {"ROS_IP": "127.0.0.1"}


@pytest.fixture(scope="module")
def sshd(tmp_path_factory: pytest.TempPathFactory):
    """The ssh plugin's loopback sshd with ROS_IP=127.0.0.1 in its sessions."""
    yield from ros_sshd(tmp_path_factory)


def _pair(core: RosCore) -> tuple[LinkNode, LinkNode, str]:
    base = f"{rosproto.PROBE_PREFIX}/link_{rosproto.new_probe_id()}"
    here = LinkNode(core.uri, base + "/out", base + "/in", env=ENV, call_timeout=2.0)
    there = LinkNode(core.uri, base + "/in", base + "/out", env=ENV, call_timeout=2.0)
    return here, there, base


def _serve(there: LinkNode, until: float) -> threading.Thread:
    """The peer's side in a thread: subscribe to ours, answer until told ``e`` or *until*."""
    def run() -> None:
        if there.subscribe(min(until, time.monotonic() + 5)):
            LinkEnd(there).pump(until)
    t = threading.Thread(target=run, daemon=True)
    t.start()
    return t


def test_two_probe_nodes_connect_through_the_master_and_measure_each_way(roscore: RosCore):
    here, there, _ = _pair(roscore)
    try:
        assert here.publish() and there.publish(), (here.why_not, there.why_not)
        server = _serve(there, time.monotonic() + 20)
        assert here.subscribe(time.monotonic() + 5), here.why_not
        assert here.connected_out.wait(5)
        end = LinkEnd(here)
        sent = time.monotonic()
        end.put("p r0")
        end.pump(sent + 5, lambda: "r0" in end.pongs)
        assert "r0" in end.pongs and end.pongs["r0"] > sent
        end.start_burst(2.0, 2 << 20)      # our burst: ended by its cap, all of it acknowledged
        end.pump(time.monotonic() + 10, lambda: not end.sending() and not end.in_flight())
        assert end.burst["acked_bytes"] >= 2 << 20
        assert end.stats["bytes"] >= 2 << 20 and rate_bps(end.stats) > 10e6, end.stats
        end.put(f"b 2 {1 << 20}")          # theirs
        end.pump(time.monotonic() + 10, lambda: end.their_burst_over)
        assert end.got["bytes"] >= 1 << 20 and rate_bps(end.received()) > 10e6
        end.put("s 1048576")               # 1 MB each way, whole
        end.node.put_frame(link_frame("L", 1 << 20))
        end.pump(time.monotonic() + 10, lambda: end.largest_in and end.delivered)
        assert end.largest_in == 1 << 20 and end.delivered == {1 << 20}
        end.put("e")
        server.join(5)
        assert not server.is_alive()
    finally:
        here.close()
        there.close()
    state = rosproto.MasterClient(roscore.uri).get_system_state()
    assert here.caller_id not in state.nodes and there.caller_id not in state.nodes


def test_a_burst_is_paced_by_what_arrives(roscore: RosCore):
    """The window stays under QUEUED_S of the rate acknowledged: with the receiver reading slowly
    (a thin link's effect), under two seconds of it is on its way when the burst's time is up."""
    here, there, _ = _pair(roscore)
    try:
        assert here.publish() and there.publish()
        assert there.subscribe(time.monotonic() + 5) and here.subscribe(time.monotonic() + 5)
        assert here.connected_out.wait(5) and there.connected_out.wait(5)
        slow, end = LinkEnd(there), LinkEnd(here)
        stop = threading.Event()

        def read_slowly() -> None:     # about 400 kB/s: one 4 kB message each 10 ms
            while not stop.is_set() and not slow.stop:
                slow.pump(time.monotonic() + 0.01)
                time.sleep(0.01)
        t = threading.Thread(target=read_slowly, daemon=True)
        t.start()
        end.start_burst(1.0, 64 << 20)
        end.pump(time.monotonic() + 1.0, lambda: not end.sending())
        b = end.burst
        rate = b["acked_bytes"] / (time.monotonic() - b["start"])     # what arrived, per second
        # Unpaced, the sockets' buffers would hold megabytes (many seconds of this reader).
        assert b["sent"] - b["acked_bytes"] <= max(64 << 10, rate * 2.0), (b, rate)
        stop.set()
        t.join(5)
    finally:
        here.close()
        there.close()


def test_what_is_not_the_protocol_is_ignored(roscore: RosCore):
    here, _there, _ = _pair(roscore)
    end = LinkEnd(here)
    for text in ("k x y", "k 1", "d", "d 9 notanumber", "a big", "b 1", "s -", "L 99 short",
                 "q", "", "zz 1 2", "k 1 2 3 nan"):
        end.handle(text, len(text), time.monotonic())
    assert end.largest_in == 0 and not end.delivered and end.burst is None


def test_the_peer_program_runs_on_a_stdlib_python_from_the_agents_source(roscore: RosCore,
                                                                        tmp_path: Path):
    """What the ROS 1 agent loads (rosproto, then roslink's body on its names) runs under
    ``python3 -I -S``; with no other end it reports, by its connect bound, why not."""
    prog = tmp_path / "prog.py"
    prog.write_bytes(b"import sys\nns = {'__name__': 'rosnet_agent_ros'}\n"
                     b"exec(compile(open(sys.argv[1], 'rb').read(), 'ros', 'exec'), ns)\n"
                     b"ns = dict(ns)\nexec(compile(open(sys.argv[2], 'rb').read(), 'rlink', "
                     b"'exec'), ns)\nsys.exit(ns['run_link'](sys.argv[3:]))\n")
    (tmp_path / "ros.py").write_bytes(ROSPROTO_SOURCE)
    (tmp_path / "rlink.py").write_bytes(ROSLINK_SOURCE)
    base = f"{rosproto.PROBE_PREFIX}/link_{rosproto.new_probe_id()}"
    r = subprocess.run([sys.executable, "-I", "-S", str(prog), str(tmp_path / "ros.py"),
                        str(tmp_path / "rlink.py"), "link", "--master", roscore.uri, "--topic",
                        base, "--timeout", "3", "--connect", "0.8", "--bashrc", "/nonexistent"],
                       capture_output=True, text=True, timeout=30, env={"ROS_IP": "127.0.0.1"})
    lines = r.stdout.splitlines()
    assert rosproto.READY_KEY in lines[0], r.stderr
    rep = rosproto.parse_report_line(r.stdout)
    assert rep is not None and rep["ok"] is False, r.stdout + r.stderr
    assert "no publisher of" in rep["error"] and r.returncode == 1
    r = subprocess.run([sys.executable, "-I", "-S", str(prog), str(tmp_path / "ros.py"),
                        str(tmp_path / "rlink.py"), "link", "--timeout", "x"],
                       capture_output=True, text=True, timeout=30)
    assert r.returncode == 2 and "usage" in r.stderr and "Traceback" not in r.stderr


# --------------------------------------------------------------------------- the check
async def _link(ctx: CheckContext):
    checks_for(["ros"])
    return await run_check(REGISTRY["ros.link"], ctx)


async def test_the_check_measures_the_loopback_peer_both_ways(tmp_path: Path, roscore: RosCore,
                                                             ssh_client):
    ctx = make_ctx(tmp_path, loopback_settings(roscore.port, ssh_client),
                   env=loopback_env(roscore), ssh=ssh_client)
    r = await _link(ctx)
    print(f"{r.duration_s:.3f} s: {r.summary}", *r.evidence, sep="\n")
    assert r.status == Status.PASS, (r.summary, r.evidence)
    d = r.data["peers"]["localhost"]
    assert d["rtt_ms"] is not None and d["rtt_ms"] < 100, d
    assert d["out_bps"] > 10e6 and d["in_bps"] > 10e6, d
    assert d["largest_out"] == d["largest_in"] == 1 << 20, d
    assert "Mbit/s" in r.summary and " ms" in r.summary and "1 MB whole both ways" in r.summary
    assert r.duration_s <= r.timeout_s
    # Its probe nodes are gone from the master.
    state = rosproto.MasterClient(roscore.uri).get_system_state()
    assert not [n for n in state.nodes if "_link_" in n], state.nodes


async def test_a_need_above_the_rate_warns_with_the_figures_and_max_hz_is_not_counted(
        tmp_path: Path, roscore: RosCore, ssh_client):
    s = loopback_settings(roscore.port, ssh_client)
    s.link.topics = [LinkTopic("/points", 500_000_000, 10.0, max_hz=0.001)]    # 40 Gbit/s
    ctx = make_ctx(tmp_path, s, env=loopback_env(roscore), ssh=ssh_client)
    r = await _link(ctx)
    assert r.status == Status.WARN, (r.summary, r.evidence)
    assert r.data["need_bps"] == 40e9
    assert "needs 40000.0 Mbit/s up, measured " in r.summary, r.summary
    assert "needs 40000.0 Mbit/s down, measured " in r.summary, r.summary
    assert any("max_hz is for ROS 2" in e for e in r.evidence), r.evidence


async def test_master_down_is_said_within_the_rounds_timeout(tmp_path: Path, ssh_client):
    from tests.builders import free_port

    s = loopback_settings(free_port(), ssh_client)
    ctx = make_ctx(tmp_path, s, env={"ROS_IP": "127.0.0.1"}, ssh=ssh_client)
    r = await _link(ctx)
    assert r.status in (Status.FAIL, Status.SKIP) and "timed out" not in r.summary, r.summary
    assert "could not publish" in r.summary and "refused" in r.summary, r.summary
    assert r.duration_s <= ctx.timeout_s + 0.5


async def test_skips_under_ros2_and_without_peers(tmp_path: Path, roscore: RosCore):
    s = loopback_settings(roscore.port)
    r = await _link(make_ctx(tmp_path, s, env=loopback_env(roscore)))
    assert r.status == Status.SKIP and "no peer with an SSH user" in r.summary
    s.ros = RosSettings(version=2, master="127.0.0.1")
    r = await _link(make_ctx(tmp_path, s))
    assert r.status == Status.SKIP and "ROS 1" in r.summary, r.summary



# --------------------------------------------------------------------------- the advice
def _advice(s, data: dict) -> list:
    from rosnet_tui.core.advisor import advise
    from rosnet_tui.core.results import CheckResult

    return advise([CheckResult("ros.link", "ros", Status.WARN, "s", [], 1.0, 18.0, data)], s,
                  strict=True)


def _ros1_member():
    from tests.builders import laptop_settings

    return laptop_settings()


def test_the_link_rules_read_ros_link_under_ros1_with_ros1s_actions():
    s = _ros1_member()
    assert not s.ros2
    lost = {"peers": {"turtlebot": {"rtt_ms": 40.0, "out_bps": 2_000_000, "in_bps": 2_000_000,
                                    "largest_out": 1 << 20, "largest_in": 65536,
                                    "tried_out": 1 << 20, "tried_in": 1 << 20}}}
    f = _advice(s, lost)
    assert f[0].rule == "ros2.link.large_dropped", [x.rule for x in f]
    text = " ".join(f[0].actions)
    assert "ping -M do -s 1472" in text and "low_pass_filter" not in text, text
    assert f[0].evidence[0].startswith("ros.link: turtlebot: down, 1 MB tried"), f[0].evidence
    # A need of 10 x 50 kB (4.0 Mbit/s), its max_hz not counted: throttle, not downsampling.
    s.link.topics = [LinkTopic("/camera/image/compressed", 50_000, 10, max_hz=1.0)]
    thin = {"peers": {"turtlebot": {"rtt_ms": 40.0, "out_bps": 2_100_000, "in_bps": 9_000_000,
                                    "largest_out": 1 << 20, "largest_in": 1 << 20,
                                    "tried_out": 1 << 20, "tried_in": 1 << 20}}}
    f = [x for x in _advice(s, thin) if x.rule == "ros2.link.too_thin"]
    assert f and "need 4.0 Mbit/s" in f[0].meaning and "2.1 Mbit/s" in f[0].meaning, f
    text = " ".join(f[0].actions)
    assert "topic_tools throttle" in text and "downsampling" not in text, text


async def test_a_probe_the_peer_cannot_reach_is_named_not_timed_out(tmp_path: Path,
                                                                   roscore: RosCore, ssh_client):
    """Our node advertises an address the peer cannot reach (ROS_IP from TEST-NET-1): nothing
    is measured, the summary says which call failed, within the budget; the master forgets both
    probes."""
    env = {**loopback_env(roscore), "ROS_IP": "192.0.2.1"}
    ctx = make_ctx(tmp_path, loopback_settings(roscore.port, ssh_client), env=env,
                   ssh=ssh_client, timeout=1.0)
    r = await _link(ctx)
    print(f"{r.duration_s:.2f} s: {r.summary}", *r.evidence, sep="\n")
    assert r.status == Status.FAIL and "nothing measured" in r.summary, (r.summary, r.evidence)
    assert "192.0.2.1" in r.summary and "timed out" not in r.summary.split(":")[0], r.summary
    assert r.duration_s <= r.timeout_s
    state = rosproto.MasterClient(roscore.uri).get_system_state()
    assert not [n for n in state.nodes if "_link_" in n], state.nodes


async def test_a_peer_that_is_down_is_said_within_the_rounds_timeout(tmp_path: Path,
                                                                    roscore: RosCore,
                                                                    ssh_client):
    from tests.builders import free_port

    s = loopback_settings(roscore.port, ssh_client)
    s.peers[0].ssh_port = free_port()           # nothing listens there: the peer is down
    ctx = make_ctx(tmp_path, s, env=loopback_env(roscore), ssh=ssh_client)
    r = await _link(ctx)
    assert r.status == Status.SKIP and "SSH" in r.summary, r.summary
    assert r.duration_s <= ctx.timeout_s + 0.5
    state = rosproto.MasterClient(roscore.uri).get_system_state()
    assert not [n for n in state.nodes if "_link_" in n], state.nodes
