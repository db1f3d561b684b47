"""Router/modem checks on loopback: real listeners, psutil, the real probe server, a real sshd."""

from __future__ import annotations

import asyncio
import contextlib
import json
import shutil
import socket
import subprocess
import threading
import time
from contextlib import contextmanager
from xmlrpc.server import SimpleXMLRPCServer

import pytest

from rosnet_tui.core.checks import (
    REGISTRY,
    CheckContext,
    load_builtin_checks,
    run_check,
    run_checks,
)
from rosnet_tui.core.checks.router import PROBE_SCRIPT, port_probe_argv
from rosnet_tui.core.config.paths import Paths
from rosnet_tui.core.config.settings_model import (
    ProbeSettings,
    RosSettings,
    Settings,
    ThisComponent,
)
from rosnet_tui.core.net.listener import GREETING, ListenerPool
from rosnet_tui.core.net.netinfo import detect_local_net
from rosnet_tui.core.peer.commands import python_command
from rosnet_tui.core.results import Status
from rosnet_tui.core.ssh.options import SshOptions
from tests.builders import free_port

load_builtin_checks()


def ctx_for(tmp_path, *, port_check_url="http://127.0.0.1:9", peers=(), public_ip="127.0.0.1",
            urls=(), ros_port=None, local_ip=None, interface="", timeout=2.0, **kw) -> CheckContext:
    s = Settings(this=ThisComponent(name="turtlebot", local_ip=local_ip or "127.0.0.1",
                                    public_ip=public_ip, interface=interface),
                 peers=list(peers),
                 ros=RosSettings(master="turtlebot", port=ros_port or free_port()),
                 probe=ProbeSettings(port=free_port(), public_ip_urls=list(urls),
                                     port_check_url=port_check_url))
    kw.setdefault("upnp", False)
    kw.setdefault("ssh_options", SshOptions(ssh_agent=False))
    return CheckContext(settings=s, timeout_s=timeout, paths=Paths(state_dir=tmp_path / "state"),
                        **kw)


async def run(check_id: str, ctx: CheckContext):
    return await run_check(REGISTRY[check_id], ctx)


def can_bind(port: int) -> bool:
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("0.0.0.0", port))
            return True
        except OSError:
            return False


# --------------------------------------------------------------------------- router.local_ip
async def test_local_ip_matches_this_machine(tmp_path):
    net = detect_local_net()
    if not net.local_ip or not net.gateway:
        pytest.skip("this machine has no default route")
    r = await run("router.local_ip", ctx_for(tmp_path, local_ip=net.local_ip))
    assert r.status is Status.PASS, r.summary
    base = {k: r.data[k] for k in ("local_ip", "interface", "gateway", "expected_ip", "differs")}
    assert base == {"local_ip": net.local_ip, "interface": net.interface, "gateway": net.gateway,
                    "expected_ip": net.local_ip, "differs": False}
    # recorded, like the public IP: the first run has nothing before it
    assert r.data["previous_ip"] is None and r.data["changed"] is False
    assert [h["ip"] for h in r.data["history"]] == [net.local_ip]


async def test_local_ip_history_shows_a_new_dhcp_lease_without_local_ip_in_the_settings(tmp_path):
    """The documented settings have no local_ip: the history is what tells a new lease."""
    from rosnet_tui.core.saved.state import record_local_ip

    net = detect_local_net()
    if not net.local_ip or not net.gateway:
        pytest.skip("this machine has no default route")
    record_local_ip(tmp_path / "state", "10.99.99.98", when="2026-01-01T00:00:00+00:00")
    ctx = ctx_for(tmp_path, local_ip=net.local_ip)
    ctx.settings.this.local_ip = ""        # as with_detected leaves it when nothing is detected
    r = await run("router.local_ip", ctx)
    assert r.status is Status.WARN, r.summary
    assert r.data["changed"] is True and r.data["previous_ip"] == "10.99.99.98"
    assert r.data["differs"] is False
    assert "10.99.99.98 on the last run" in r.summary
    assert [h["ip"] for h in r.data["history"]] == ["10.99.99.98", net.local_ip]
    again = await run("router.local_ip", ctx)        # the next run: nothing new
    assert again.status is Status.PASS and again.data["changed"] is False


async def test_local_ip_warns_after_a_dhcp_change(tmp_path):
    if not detect_local_net().local_ip:
        pytest.skip("this machine has no LAN address")
    r = await run("router.local_ip", ctx_for(tmp_path, local_ip="10.99.99.99"))
    assert r.status is Status.WARN and r.data["differs"] and r.data["expected_ip"] == "10.99.99.99"
    assert "10.99.99.99" in r.summary


async def test_local_ip_fails_for_a_missing_interface(tmp_path):
    r = await run("router.local_ip", ctx_for(tmp_path, interface="nosuch0"))
    assert r.status is Status.FAIL and "does not exist" in r.summary


# --------------------------------------------------------------------------- router.port_free
async def test_port_free_passes_and_leaves_the_port_free(tmp_path):
    ctx = ctx_for(tmp_path)
    r = await run("router.port_free", ctx)
    assert r.status is Status.PASS and r.data == {"port": ctx.settings.probe.port, "in_use": False,
                                                  "process": None, "pid": None}
    assert can_bind(ctx.settings.probe.port)


@pytest.mark.skipif(shutil.which("nc") is None, reason="needs nc")
async def test_port_free_names_the_process_that_holds_the_port(tmp_path):
    ctx = ctx_for(tmp_path)
    port = ctx.settings.probe.port
    nc = subprocess.Popen(["nc", "-l", str(port)], stdin=subprocess.DEVNULL,
                          stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 5
        while can_bind(port) and time.monotonic() < deadline:
            time.sleep(0.05)
        r = await run("router.port_free", ctx)
    finally:
        nc.kill()
        nc.wait(5)
    assert r.status is Status.FAIL and r.data["in_use"] is True
    assert r.data["pid"] == nc.pid and "nc" in r.data["process"]
    assert f"pid {nc.pid}" in r.summary


# --------------------------------------------------------------------------- router.listener
async def test_listener_answers_and_is_closed_after_the_check(tmp_path):
    ctx = ctx_for(tmp_path)
    port = ctx.settings.probe.port
    r = await run("router.listener", ctx)
    assert r.status is Status.PASS and r.data == {"port": port, "listening": True}
    assert any(GREETING in e for e in r.evidence)
    assert can_bind(port) and not ctx.listeners.holds(port)


async def test_listener_tests_the_address_this_machine_has_not_a_stale_one(tmp_path):
    """After a new DHCP lease the settings still name the old local IP: our listener is up
    all the same (Table 1 must read "listener up"), and the evidence says what was skipped."""
    net = detect_local_net()
    if not net.local_ip:
        pytest.skip("this machine has no LAN address")
    ctx = ctx_for(tmp_path, local_ip="10.99.99.99")
    r = await run("router.listener", ctx)
    assert r.status is Status.PASS and r.data["listening"] is True, r.evidence
    assert net.local_ip in r.summary and "10.99.99.99" not in r.summary
    assert any("10.99.99.99 is not an address of this machine now" in e for e in r.evidence)


async def test_listener_fails_when_the_port_is_taken(tmp_path):
    ctx = ctx_for(tmp_path)
    with socket.socket() as s:
        s.bind(("0.0.0.0", ctx.settings.probe.port))
        s.listen(1)
        r = await run("router.listener", ctx)
    assert r.status is Status.FAIL and r.data["listening"] is False


async def test_the_pool_shares_one_listener_and_records_chat_lines():
    pool = ListenerPool()
    port = free_port()
    async with pool.hold(port) as a, pool.hold(port) as b:
        assert a is b and pool.holds(port)
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        hello = await reader.readline()
        assert hello.decode().startswith(f"{GREETING} {pool.token} {port}")
        writer.write(b"ROSNET-TUI CHAT abc\n")
        echo = await reader.readline()
        writer.close()
        assert b"ECHO ROSNET-TUI CHAT abc" in echo
        seen = await a.wait_for_line("abc", 2)
        assert seen is not None and seen.address == "127.0.0.1"
    assert not pool.holds(port) and can_bind(port)


# --------------------------------------------------------------------------- router.port_open
async def test_port_open_via_the_probe_server(probe_server, tmp_path):
    ros_port = free_port()
    ctx = ctx_for(tmp_path, port_check_url=probe_server.url, ros_port=ros_port)
    with socket.socket() as roscore_stand_in:  # a "service" listening there: probed too
        roscore_stand_in.bind(("0.0.0.0", ros_port))
        roscore_stand_in.listen(8)
        r = await run("router.port_open", ctx)
    assert r.status is Status.PASS, (r.summary, r.evidence)
    ports = [p["port"] for p in r.data["ports"]]
    test_port = ctx.settings.probe.port
    assert ports[0] == test_port and ros_port in ports and len(ports) == 4
    assert all(p["reachable"] and p["listener"] and p["via"] == "echoip" for p in r.data["ports"])
    assert r.data["test_port_open"] is True
    assert {p for _, p in probe_server.server.recent_connect_backs} >= set(ports)
    assert all(1024 <= p <= 65000 for p in ports[1:3])
    assert all(can_bind(p) for p in ports[:3])  # our listeners are gone


async def test_port_open_closed_while_listening_is_table1_row3(web, tmp_path):
    web.fallback = lambda path: (200, json.dumps({"ip": "127.0.0.1", "reachable": False,
                                                  "port": int(path.rsplit("/", 1)[-1])}))
    ctx = ctx_for(tmp_path, port_check_url=web.url(""))
    r = await run("router.port_open", ctx)
    assert r.status is Status.FAIL and r.data["test_port_open"] is False
    assert "while our listener runs" in r.summary
    assert r.data["ports"][0]["listener"] is True


async def test_port_open_without_a_checker_cannot_tell(tmp_path):
    r = await run("router.port_open", ctx_for(tmp_path, port_check_url=f"http://127.0.0.1:{free_port()}"))
    assert r.status is Status.FAIL and r.data["test_port_open"] is None
    assert "could not test" in r.summary


async def test_port_open_from_the_peer_over_ssh(ssh_client, web, tmp_path):
    web.routes["/ip"] = (200, "127.0.0.1\n")
    ctx = ctx_for(tmp_path, peers=[ssh_client.peer()], urls=[web.url("/ip")],
                  ssh_options=SshOptions(ssh_dir=ssh_client.dir,
                                         known_hosts_files=(ssh_client.dir / "known_hosts",)),
                  timeout=3.0)
    r = await run("router.port_open", ctx)
    assert r.status is Status.PASS, (r.summary, r.evidence)
    assert all(p["via"] == "peer:localhost" and p["reachable"] for p in r.data["ports"])
    assert r.data["public_ip"] == "127.0.0.1"
    assert any(ctx.listeners.token in e for e in r.evidence)  # the peer read OUR listener
    # the evidence the advisor ranks by: our token read on every port, the address pings
    assert all(p["answer"] == "token" for p in r.data["ports"]), r.data["ports"]
    assert r.data["public_ip_ping"] is True


async def test_port_open_falls_back_to_the_checker_when_ssh_fails(ssh_client, probe_server,
                                                                  web, tmp_path):
    web.routes["/ip"] = (200, "127.0.0.1\n")
    peer = ssh_client.peer(ssh_port=free_port())
    ctx = ctx_for(tmp_path, peers=[peer], urls=[web.url("/ip")], port_check_url=probe_server.url,
                  ssh_options=SshOptions(ssh_dir=ssh_client.dir,
                                         known_hosts_files=(ssh_client.dir / "known_hosts",)))
    r = await run("router.port_open", ctx)
    assert r.status is Status.PASS and r.data["ports"][0]["via"] == "echoip"
    assert "asking the port checker instead" in r.evidence[0]


async def test_router_step_runs_concurrently_without_fighting_over_the_port(probe_server,
                                                                            tmp_path):
    ctx = ctx_for(tmp_path, port_check_url=probe_server.url)
    specs = [REGISTRY[i] for i in ("router.port_free", "router.listener", "router.port_open")]
    got = {r.id: r async for r in run_checks(specs, ctx)}
    assert all(r.status is Status.PASS for r in got.values()), {i: r.summary for i, r in got.items()}
    assert can_bind(ctx.settings.probe.port) and not ctx.listeners.holds(ctx.settings.probe.port)


# --------------------------------------------------------------------------- what answers where
@contextmanager
def ros_master_stand_in(port: int):
    """An XML-RPC server answering getPid on 0.0.0.0:*port*, as the ROS master does (rosmaster's
    server is the standard library's SimpleXMLRPCServer): it never speaks first."""
    srv = SimpleXMLRPCServer(("0.0.0.0", port), logRequests=False, allow_none=True)
    srv.register_function(lambda caller_id: [1, "", 4242], "getPid")
    th = threading.Thread(target=srv.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)
    th.start()
    try:
        yield srv
    finally:
        srv.shutdown()
        srv.server_close()
        th.join(2)


@contextmanager
def silent_listener():
    """A port that accepts connections and never says a word (a Zenoh router, to a probe)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen(8)
        yield s.getsockname()[1]


@contextmanager
def dropping_port():
    """A port whose connections get no answer at all, as behind a modem that drops them: a
    listener whose accept queue is full (Linux then drops further SYNs)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen(0)
        port = s.getsockname()[1]
        fillers = []
        try:
            for _ in range(3):
                c = socket.socket()
                c.setblocking(False)
                with contextlib.suppress(BlockingIOError):
                    c.connect(("127.0.0.1", port))
                fillers.append(c)
            time.sleep(0.05)
            yield port
        finally:
            for c in fillers:
                c.close()


def run_probe(ports: dict, t: float = 3.0) -> tuple[dict, float]:
    cmd = python_command(PROBE_SCRIPT, *port_probe_argv("127.0.0.1", t, ports))
    t0 = time.monotonic()
    r = subprocess.run(["sh", "-c", cmd], capture_output=True, text=True, timeout=t + 5)
    took = time.monotonic() - t0
    line = next(ln for ln in r.stdout.splitlines() if ln.startswith("RESULT "))
    return {int(k): v for k, v in json.loads(line[7:]).items()}, took


async def test_the_port_probe_knows_what_answers_where():
    """A silent open port is open at once; the ROS master answers a harmless getPid; a server
    that speaks first (our listener) is read. None of them waits for a banner that never comes."""
    pool = ListenerPool()
    ros_port = free_port()
    with silent_listener() as quiet, ros_master_stand_in(ros_port):
        async with pool.hold(free_port()) as lst:
            got, took = await asyncio.to_thread(
                run_probe, {lst.port: "line", quiet: "accept", ros_port: "xmlrpc"}, 10.0)
    assert got[quiet] == ["open", ""]
    assert got[ros_port][0] == "open" and got[ros_port][1].startswith("HTTP/1."), got
    assert got[lst.port][0] == "open" and lst.token in got[lst.port][1]
    # not the 10 s timeout: a loaded machine stays far below the bound
    assert took < 5.0, f"the probe took {took:.2f} s: it waited for a silent port"


async def test_port_open_from_the_peer_with_a_ros_master_running_here(ssh_client, web,
                                                                      tmp_path):
    """The master's seat: a ROS master listens on its port, so the peer tests that port too; it
    must not wait for a greeting that an XML-RPC server never sends (issue 25)."""
    web.routes["/ip"] = (200, "127.0.0.1\n")
    ros_port = free_port()
    ctx = ctx_for(tmp_path, peers=[ssh_client.peer()], urls=[web.url("/ip")], ros_port=ros_port,
                  ssh_options=SshOptions(ssh_dir=ssh_client.dir,
                                         known_hosts_files=(ssh_client.dir / "known_hosts",)),
                  timeout=10.0)
    with ros_master_stand_in(ros_port):
        ctx.ssh_pool = None
        warm = await run("router.port_open", ctx)          # the SSH login, once
        assert warm.status is Status.PASS, (warm.summary, warm.evidence)
        t0 = time.monotonic()
        r = await run("router.port_open", ctx)
        took = time.monotonic() - t0
    assert r.status is Status.PASS, (r.summary, r.evidence)
    row = next(p for p in r.data["ports"] if p["port"] == ros_port)
    assert row["reachable"] is True and row["answer"] == "token" and row["via"] == "peer:localhost"
    assert any(f":{ros_port}: open, getPid over XML-RPC answered 'HTTP/1." in e
               for e in r.evidence), r.evidence
    # no wait for a greeting (the 10 s timeout): a loaded machine stays far below the bound
    assert took < 5.0, f"router.port_open took {took:.2f} s"


async def test_a_port_the_verdict_does_not_need_is_not_waited_for():
    """Under ROS 2 only zenoh_port decides; the test port (not forwarded on a ROS 2 modem) is
    given as long again as the needed port took (at least 0.25 s), then reported pending."""
    with silent_listener() as needed, dropping_port() as dropped:
        got, took = await asyncio.to_thread(run_probe, {needed: "accept", dropped: "accept?"},
                                            10.0)
        assert got[needed] == ["open", ""] and got[dropped][0] == "pending", got
        # not the 10 s timeout: a loaded machine stays far below it
        assert took < 5.0, f"the probe took {took:.2f} s"
        got, took = await asyncio.to_thread(run_probe, {dropped: "accept"}, 1.0)
    assert got[dropped][0] == "timeout" and took >= 1.0     # a needed port gets its whole time


# --------------------------------------------------------------------------- ros2.router
async def test_a_master_whose_router_is_down_is_told_so_while_our_stand_in_holds_its_port(
        tmp_path):
    """router.port_open holds a stand-in listener on the Zenoh port while the router is down (to
    test the forward): ros2.router, in the same round, took that listener for the router and the
    advice for a stopped router never came (seen on the lab's fresh master)."""
    from tests.builders import ros2_master

    zport = free_port()
    s = ros2_master(zenoh_port=zport, security="none")
    s.ros.master = "localhost"                  # no name lookup leaves this machine
    ctx = CheckContext(settings=s, timeout_s=2.0, paths=Paths(state_dir=tmp_path / "state"),
                       upnp=False, ssh_options=SshOptions(ssh_agent=False))
    async with ctx.listeners.hold(zport):
        r = await run("ros2.router", ctx)
    assert r.data["listen_problem"] == "not_running", (r.summary, r.evidence)
    assert r.data["listening"] == [], r.evidence
    assert r.status is Status.FAIL, r.summary


async def test_a_stand_in_that_opens_while_ros2_router_looks_is_not_taken_for_the_router(
        tmp_path, monkeypatch):
    """Fresh-clone CI saw it once (test_ros2_fresh_install[robot]): ros2.router asked whether
    rosnet-tui had the Zenoh port (not yet), router.port_open's stand-in opened, and the look at
    the port's listeners then found it: the stopped router counted as running. Here the stand-in
    opens exactly during the look."""
    import psutil

    from tests.builders import ros2_master

    zport = free_port()
    s = ros2_master(zenoh_port=zport, security="none")
    s.ros.master = "localhost"
    ctx = CheckContext(settings=s, timeout_s=2.0, paths=Paths(state_dir=tmp_path / "state"),
                       upnp=False, ssh_options=SshOptions(ssh_agent=False))
    loop = asyncio.get_running_loop()
    stand_in = contextlib.AsyncExitStack()
    real = psutil.net_connections

    def looking(kind: str = "inet"):        # in the check's thread, as psutil is called
        if not ctx.listeners.holds(zport):
            asyncio.run_coroutine_threadsafe(
                stand_in.enter_async_context(ctx.listeners.hold(zport)), loop).result(5)
        return real(kind)

    monkeypatch.setattr(psutil, "net_connections", looking)
    try:
        r = await run("ros2.router", ctx)
    finally:
        await stand_in.aclose()
    assert ctx.listeners.holds(zport) is False
    assert r.data["listen_problem"] == "not_running", (r.summary, r.evidence)
    assert r.data["listening"] == [], r.evidence
    assert "own test listener" in " ".join(r.evidence), r.evidence
