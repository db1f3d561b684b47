"""The ros.* checks on loopback: a real roscore, a real sshd playing the peer, real rc files.

The peer is this machine itself, reached as ``localhost`` through an sshd of the test's own
(127.0.0.1, a free port, its own host key and authorized key, killed at the end); it runs the probe
from rosproto's source piped into ``python3 -`` exactly as on a real peer.
"""

from __future__ import annotations

import getpass
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from rosnet_tui.core.checks import REGISTRY, CheckContext, checks_for, run_check
from rosnet_tui.core.config.paths import Paths
from rosnet_tui.core.config.settings_model import Peer, RosSettings, Settings, ThisComponent
from rosnet_tui.core.peer import rosproto
from rosnet_tui.core.results import Status
from rosnet_tui.core.ssh.options import SshOptions
from tests.builders import free_port
from tests.plugins.roscore import RosCore
from tests.plugins.ssh import Client, ros_sshd

ROS_IDS = ["ros.env", "ros.master", "ros.node_uris", "ros.pubsub_out", "ros.pubsub_in"]


@pytest.fixture(scope="module")
def sshd(tmp_path_factory: pytest.TempPathFactory):
    """The ssh plugin's loopback sshd with ROS_IP=127.0.0.1 in its sessions."""
    yield from ros_sshd(tmp_path_factory)


def make_ctx(tmp_path: Path, settings: Settings, *, env: dict[str, str] | None = None,
             bashrc: str = "", timeout: float = 2.0, ssh: Client | None = None) -> CheckContext:
    rc = tmp_path / "bashrc"
    rc.write_text(bashrc)
    return CheckContext(settings=settings, timeout_s=timeout,
                        paths=Paths(bashrc_path=rc, state_dir=tmp_path / "state"), env=dict(env or {}),
                        ssh_options=SshOptions(
                            ssh_dir=ssh.dir if ssh else tmp_path / "no-ssh",
                            ssh_agent=False))


def loopback_settings(core_port: int, ssh: Client | None = None) -> Settings:
    peers = [Peer(name="localhost", local_ip="127.0.0.1", ssh_user=getpass.getuser(),
                  ssh_port=ssh.sshd.port)] if ssh else []
    return Settings(this=ThisComponent(name="127.0.0.1", role="master", local_ip="127.0.0.1"),
                    peers=peers, ros=RosSettings(master="127.0.0.1", port=core_port))


def loopback_env(core: RosCore) -> dict[str, str]:
    return {"ROS_IP": "127.0.0.1", "ROS_MASTER_URI": core.uri}


async def run(ctx: CheckContext, check_id: str):
    checks_for(["ros"])
    return await run_check(REGISTRY[check_id], ctx)


def test_ros_checks_are_registered():
    assert [c.id for c in checks_for(["ros"], Settings())] == [*ROS_IDS, "ros.link", "security.outsider"]


# --------------------------------------------------------------------------- ros.env
def robot() -> Settings:
    return Settings(this=ThisComponent(name="turtlebot", role="master", local_ip="10.10.10.1",
                                       public_ip="203.0.113.2"),
                    peers=[Peer(name="sami", public_ip="198.51.100.2", ssh_user="root")],
                    ros=RosSettings(master="turtlebot"))


def laptop(profile: str = "remote") -> Settings:
    return Settings(this=ThisComponent(name="sami", role="member", local_ip="192.168.1.10",
                                       profile=profile),
                    peers=[Peer(name="turtlebot", public_ip="203.0.113.2", ssh_user="root")],
                    ros=RosSettings(master="turtlebot"))


GOOD = "export ROS_MASTER_URI=http://turtlebot:11311\n"


async def test_env_master_and_member_pass(tmp_path: Path):
    for settings in (robot(), laptop()):
        ctx = make_ctx(tmp_path, settings, env={"ROS_MASTER_URI": "http://turtlebot:11311"},
                       bashrc=GOOD)
        r = await run(ctx, "ros.env")
        assert r.status == Status.PASS, r.summary
        assert r.data == {"env_uri": "http://turtlebot:11311", "bashrc_uri": "http://turtlebot:11311",
                          "expected_uri": "http://turtlebot:11311", "uri_ok": True, "ros_ip": None,
                          "ros_hostname": None}
    ctx = make_ctx(tmp_path, robot(), env={"ROS_MASTER_URI": "http://10.10.10.1:11311/"},
                   bashrc="export ROS_MASTER_URI=http://10.10.10.1:11311\n")
    assert (await run(ctx, "ros.env")).status == Status.PASS  # the master's own local IP


async def test_env_wrong_uri_fails(tmp_path: Path):
    ctx = make_ctx(tmp_path, laptop(), env={"ROS_MASTER_URI": "http://localhost:11311"},
                   bashrc=GOOD)
    r = await run(ctx, "ros.env")
    assert r.status == Status.FAIL and not r.data["uri_ok"]
    assert "localhost" in r.summary and r.data["expected_uri"] == "http://turtlebot:11311"

    ctx = make_ctx(tmp_path, laptop(), env={"ROS_MASTER_URI": "http://203.0.113.2:11311"},
                   bashrc="export ROS_MASTER_URI=http://turtlebot:11312\n")
    r = await run(ctx, "ros.env")
    assert r.status == Status.FAIL and "use its name" in r.summary and "port 11312" in r.summary

    ctx = make_ctx(tmp_path, robot(), env={"ROS_MASTER_URI": "http://203.0.113.2:11311"},
                   bashrc=GOOD)
    r = await run(ctx, "ros.env")
    assert r.status == Status.FAIL and "refuses to start" in r.summary


async def test_env_last_export_wins_and_comments_are_ignored(tmp_path: Path):
    rc = ("export ROS_MASTER_URI=http://localhost:11311\n"
          "# export ROS_MASTER_URI=http://wrong:11311\n"
          "export ROS_MASTER_URI=http://turtlebot:11311   # the robot\n"
          "#export ROS_IP=192.168.1.10\n")
    ctx = make_ctx(tmp_path, laptop(), env={"ROS_MASTER_URI": "http://turtlebot:11311"}, bashrc=rc)
    r = await run(ctx, "ros.env")
    assert r.status == Status.PASS, r.summary
    assert r.data["bashrc_uri"] == "http://turtlebot:11311" and r.data["ros_ip"] is None


async def test_env_missing_somewhere(tmp_path: Path):
    r = await run(make_ctx(tmp_path, laptop(), env={}, bashrc=""), "ros.env")
    assert r.status == Status.FAIL and not r.data["uri_ok"]
    assert "export ROS_MASTER_URI=http://turtlebot:11311" in r.summary
    r = await run(make_ctx(tmp_path, laptop(), env={"ROS_MASTER_URI": "http://turtlebot:11311"},
                           bashrc=""), "ros.env")
    assert r.status == Status.WARN and "new terminals" in r.summary and r.data["uri_ok"]
    r = await run(make_ctx(tmp_path, laptop(), env={}, bashrc=GOOD), "ros.env")
    assert r.status == Status.WARN and "source" in r.summary


async def test_env_ros_ip_or_hostname_warns_on_remote(tmp_path: Path):
    ctx = make_ctx(tmp_path, laptop(), env={"ROS_MASTER_URI": "http://turtlebot:11311"},
                   bashrc=GOOD + "export ROS_IP=192.168.1.10\n")
    r = await run(ctx, "ros.env")
    assert r.status == Status.WARN and r.data["ros_ip"] == "192.168.1.10"
    assert "ROS_IP=192.168.1.10" in r.summary and "cannot subscribe" in r.summary
    ctx = make_ctx(tmp_path, laptop(), env={"ROS_MASTER_URI": "http://turtlebot:11311",
                                            "ROS_HOSTNAME": "sami.local"}, bashrc=GOOD)
    r = await run(ctx, "ros.env")
    assert r.status == Status.WARN and r.data["ros_hostname"] == "sami.local"
    # On a LAN profile they are fine (the procedure says so); loopback never is.
    ctx = make_ctx(tmp_path, laptop("office"), env={"ROS_MASTER_URI": "http://turtlebot:11311",
                                                    "ROS_IP": "192.168.1.10"}, bashrc=GOOD)
    assert (await run(ctx, "ros.env")).status == Status.PASS
    ctx = make_ctx(tmp_path, laptop("office"), env={"ROS_MASTER_URI": "http://turtlebot:11311",
                                                    "ROS_IP": "127.0.0.1"}, bashrc=GOOD)
    assert (await run(ctx, "ros.env")).status == Status.WARN


async def test_no_master_configured_skips_every_ros_check(tmp_path: Path):
    s = laptop()
    s.ros.master = ""
    ctx = make_ctx(tmp_path, s, env={"ROS_MASTER_URI": "http://turtlebot:11311"}, bashrc=GOOD)
    for cid in ROS_IDS:
        r = await run(ctx, cid)
        assert r.status == Status.SKIP and "master" in r.summary, (cid, r.summary)


# --------------------------------------------------------------------------- ros.master
async def test_master_answers(tmp_path: Path, roscore: RosCore):
    ctx = make_ctx(tmp_path, loopback_settings(roscore.port), env=loopback_env(roscore))
    r = await run(ctx, "ros.master")
    assert r.status == Status.PASS, r.summary
    assert r.data["reachable"] and r.data["uri"] == roscore.uri
    assert isinstance(r.data["topics"], list) and isinstance(r.data["nodes"], list)
    assert any(line.startswith("nodes (") for line in r.evidence)


async def test_dead_master_fails_within_its_timeout(tmp_path: Path):
    port = free_port()
    ctx = make_ctx(tmp_path, loopback_settings(port), timeout=10.0)
    r = await run(ctx, "ros.master")
    # refused: at once, not after the timeout (a long one: a loaded machine stays far below)
    assert r.status == Status.FAIL and "refused" in r.summary and r.duration_s < 5.0
    assert r.data["reachable"] is False
    with socket.socket() as silent:  # accepts connections, never answers
        silent.bind(("127.0.0.1", 0))
        silent.listen(8)
        ctx = make_ctx(tmp_path, loopback_settings(silent.getsockname()[1]), timeout=1.0)
        start = time.monotonic()
        r = await run(ctx, "ros.master")
        assert time.monotonic() - start < 2 * 1.0  # one wait, never two (bench row 3 times it)
    assert r.status == Status.FAIL and "timed out" in r.summary, r.summary


# --------------------------------------------------------------------------- ros.node_uris
async def test_node_with_unreachable_uri_is_named(tmp_path: Path, roscore: RosCore):
    topic = f"/rosnet_test/{rosproto.new_probe_id()}"
    dead = f"http://127.0.0.1:{free_port()}/"
    fake = rosproto.MasterClient(roscore.uri, "/teleop_with_bad_uri", 2.0)
    fake.register_publisher(topic, rosproto.STRING_TYPE, dead)
    try:
        ctx = make_ctx(tmp_path, loopback_settings(roscore.port), env=loopback_env(roscore))
        r = await run(ctx, "ros.node_uris")
    finally:
        fake.unregister_publisher(topic, dead)
    assert r.status == Status.FAIL
    assert "/teleop_with_bad_uri" in r.summary and dead in r.summary
    bad = [u for u in r.data["unreachable"] if u["node"] == "/teleop_with_bad_uri"]
    assert bad == [{"node": "/teleop_with_bad_uri", "uri": dead, "host": "127.0.0.1",
                    "reason": bad[0]["reason"], "from": "here"}]
    assert "refused" in bad[0]["reason"] and r.data["checked"] >= 1


# --------------------------------------------------------------------------- with the peer over SSH
async def test_healthy_loopback_passes_in_both_directions(tmp_path: Path, roscore: RosCore,
                                                          ssh_client: Client):
    ctx = make_ctx(tmp_path, loopback_settings(roscore.port, ssh_client),
                   env=loopback_env(roscore), ssh=ssh_client)
    for cid in ("ros.node_uris", "ros.pubsub_out", "ros.pubsub_in"):
        r = await run(ctx, cid)
        assert r.status == Status.PASS, (cid, r.summary, r.evidence)
        assert r.duration_s < r.timeout_s
    out = await run(ctx, "ros.pubsub_out")
    assert out.data["peer"] == "localhost" and out.data["ok"] and out.data["failed_hop"] is None
    # Hop evidence from both seats: our publisher and the peer's subscriber.
    assert any(e.startswith("localhost (subscriber) no_message: ok") for e in out.evidence)
    assert any(e.startswith("here (publisher) registration: ok") for e in out.evidence)
    nodes = await run(ctx, "ros.node_uris")
    assert nodes.data["from"] == ["here", "localhost"]


async def test_pubsub_skips_without_ssh_peer_or_trusted_key(tmp_path: Path,
                                                            roscore: RosCore):
    ctx = make_ctx(tmp_path, loopback_settings(roscore.port), env=loopback_env(roscore))
    for cid in ("ros.pubsub_out", "ros.pubsub_in"):
        r = await run(ctx, cid)
        assert r.status == Status.SKIP and "SSH" in r.summary
    # A peer whose host key we do not know: never trusted silently, so the exchange is skipped.
    s = loopback_settings(roscore.port)
    with socket.socket() as nothing:
        nothing.bind(("127.0.0.1", 0))
        port = nothing.getsockname()[1]
    s.peers = [Peer(name="localhost", local_ip="127.0.0.1", ssh_user="root", ssh_port=port)]
    r = await run(make_ctx(tmp_path, s, env=loopback_env(roscore)), "ros.pubsub_out")
    assert r.status == Status.SKIP and "SSH to localhost failed" in r.summary


async def test_pubsub_with_dead_master_fails_at_registration(tmp_path: Path,
                                                              ssh_client: Client):
    port = free_port()
    ctx = make_ctx(tmp_path, loopback_settings(port, ssh_client), ssh=ssh_client, timeout=1.0,
                   env={"ROS_IP": "127.0.0.1"})
    r = await run(ctx, "ros.pubsub_out")
    assert r.status == Status.FAIL and r.data["failed_hop"] == "registration"
    assert r.data["uri"] == f"http://127.0.0.1:{port}"
    assert r.data["node"].startswith("/rosnet_probe")
    r = await run(ctx, "ros.pubsub_in")
    assert r.status == Status.FAIL and r.data["failed_hop"] == "registration", r.summary
    assert r.duration_s < r.timeout_s


def test_the_order_of_the_checks_does_not_follow_what_was_imported_first():
    """A module importing a check module for a constant (ros_link's PUBSUB) registered its
    checks first, and the ROS step listed ros.link before ros.env."""
    def order(first: str) -> list[str]:
        code = (first + "from rosnet_tui.core.checks import checks_for\n"
                "from rosnet_tui.core.config.settings_model import Settings\n"
                "print(' '.join(c.id for c in checks_for(None, Settings())))")
        return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                              timeout=60, check=True).stdout.split()

    plain = order("")
    assert plain.index("ros.env") < plain.index("ros.link") < plain.index("security.outsider")
    assert order("import rosnet_tui.core.checks.ros_link, rosnet_tui.core.checks.security\n"
                 "import rosnet_tui.core.checks.router_upnp\n") == plain
