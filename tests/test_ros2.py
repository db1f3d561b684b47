"""ROS 2 over rmw_zenoh, without the lab: settings, the wire format, the written configuration,
the steps text, which checks a version runs, and address sync leaving the ROS 2 block alone."""

from __future__ import annotations

import json
import struct
from dataclasses import replace
from pathlib import Path

import pytest

from rosnet_tui.core.checks.runner import select
from rosnet_tui.core.config.paths import Paths
from rosnet_tui.core.config.settings_model import RosSettings, SettingsError
from rosnet_tui.core.exposure.forwarding import ports_to_forward, required_ports
from rosnet_tui.core.peer import zenohproto
from rosnet_tui.core.ros import ros2
from rosnet_tui.core.saved.settings import parse_settings, render_settings
from rosnet_tui.core.wizard.steps import STEP_BY_ID, step_for
from tests.builders import ros2_master as master
from tests.builders import ros2_member as member


# --------------------------------------------------------------------------- settings
def test_files_without_version_keep_working_and_take_the_environment(monkeypatch):
    text = ('[this]\nname = "sami"\nrole = "member"\n[[peer]]\nname = "turtlebot"\n'
            'public_ip = "203.0.113.2"\n[ros]\nmaster = "turtlebot"\nport = 11311\n')
    monkeypatch.delenv("ROS_VERSION", raising=False)
    assert parse_settings(text).ros.version == 1
    monkeypatch.setenv("ROS_VERSION", "2")
    s = parse_settings(text)
    assert s.ros.version == 2 and s.ros.zenoh_port == 7447 and s.ros.domain_id == 0
    assert parse_settings(render_settings(s)).ros == s.ros


@pytest.mark.parametrize("line, key", [("version = 3", "ros.version"),
                                       ("zenoh_port = 80", "ros.zenoh_port"),
                                       ("zenoh_port = 65001", "ros.zenoh_port"),
                                       ("domain_id = 233", "ros.domain_id"),
                                       ("domain_id = -1", "ros.domain_id"),
                                       ('domain_id = "0"', "ros.domain_id")])
def test_bad_ros2_keys_are_refused_with_the_key(line, key):
    with pytest.raises(SettingsError) as exc:
        parse_settings(f'[this]\nname = "a"\n[ros]\n{line}\n')
    assert exc.value.key == key and exc.value.line == 4


def test_a_bad_key_exits_2_with_one_line(tmp_path):
    import subprocess
    import sys
    cfg = tmp_path / "c.toml"
    cfg.write_text('[this]\nname = "a"\n[ros]\nversion = 7\n')
    r = subprocess.run([sys.executable, "-m", "rosnet_tui", "check", "--config", str(cfg)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "ros.version" in r.stderr and "Traceback" not in r.stderr


# --------------------------------------------------------------------------- which checks
def test_the_ros_step_lists_the_checks_of_the_version():
    one = [c.id for c in select(["ros"], settings=replace(member(), ros=RosSettings(
        master="turtlebot")))]
    two = [c.id for c in select(["ros"], settings=member())]
    assert one == ["ros.env", "ros.master", "ros.node_uris", "ros.pubsub_out", "ros.pubsub_in",
                   "ros.link", "security.outsider"]
    assert two == ["ros2.env", "ros2.router", "ros2.graph", "ros2.pubsub_out", "ros2.pubsub_in",
                   "ros2.link", "security.outsider"]
    assert step_for("ros", member()).check_ids == tuple(two)
    assert STEP_BY_ID["ros"].check_ids == tuple(one)


def test_forwarding_per_version_and_role():
    assert [p.ports for p in required_ports(master())] == ["7447"]
    assert required_ports(member()) == []
    assert [p.ports for p in required_ports(master(zenoh_port=17447))] == ["17447"]
    one = replace(master(), ros=RosSettings(master="turtlebot"))
    assert [(p.protocol, p.ports) for p in required_ports(one)] == [("TCP", "1024-65000")]
    assert all(not p.required for p in ports_to_forward(member()))


# --------------------------------------------------------------------------- wire format
@pytest.mark.parametrize("wire,ros", [
    ("std_msgs::msg::dds_::String_", "std_msgs/msg/String"),
    ("geometry_msgs::msg::dds_::TwistStamped_", "geometry_msgs/msg/TwistStamped"),
    ("my_pkg::msg::dds_::My_Type__", "my_pkg/msg/My_Type_"),   # one "_" is the DDS suffix
    ("example_interfaces::srv::dds_::AddTwoInts_", "example_interfaces/srv/AddTwoInts"),
    ("std_msgs::msg::String", "std_msgs/msg/String"),           # without the dds_ part
    ("std_msgs::msg::dds_::String", "std_msgs/msg/String"),     # without the trailing _
    ("std_msgs/msg/String", "std_msgs/msg/String"),             # already the ROS form
    ("String_", "String_"), ("", ""), ("::", "::"), ("dds_::", "dds_::"), ("a::::b", "a/b"),
])
def test_a_type_is_named_as_ros_2_users_write_it(wire, ros):
    """Issue 29 (section 4, row 9): ros2.graph said /chatter [std_msgs::msg::dds_::String_]."""
    assert zenohproto.ros_type(wire) == ros
    if not wire:
        return                      # no type chunk on the wire: no token to read
    tok = zenohproto.parse_token(zenohproto.endpoint_token(0, "abc", "7", "8", "MS", "listener",
                                                           "/chatter", type_name=wire))
    assert tok is not None and tok["type"] == ros


def test_keys_tokens_payloads_and_attachments_have_rmw_zenohs_layout():
    assert zenohproto.topic_key(0, "/chatter") == (
        "0/chatter/std_msgs::msg::dds_::String_/RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db"
        "1288021743503259e948f6b1a18")
    node = zenohproto.node_token(3, "abc", "7", "talker", "/robot1")
    assert node == "@ros2_lv/3/abc/7/7/NN/%/%robot1/talker"
    pub = zenohproto.endpoint_token(0, "abc", "7", "8", "MP", "talker", "/chatter")
    assert pub.startswith("@ros2_lv/0/abc/7/8/MP/%/%/talker/%chatter/std_msgs::msg::dds_::String_/")
    tok = zenohproto.parse_token(pub)
    assert (tok["kind"], tok["topic"], tok["name"], tok["namespace"]) == ("MP", "/chatter",
                                                                         "talker", "/")
    assert tok["type"] == "std_msgs/msg/String"     # as `ros2 topic list -t` says it
    assert zenohproto.parse_token("@ros2_lv/0/a") is None
    payload = zenohproto.encode_string("hi")
    assert payload == b"\x00\x01\x00\x00\x03\x00\x00\x00hi\x00"
    assert zenohproto.decode_string(payload) == "hi"
    att = zenohproto.encode_attachment(5, 123, bytes(range(16)))
    assert len(att) == 33 and att[16] == 16 and struct.unpack_from("<qq", att) == (5, 123)
    assert zenohproto.decode_attachment(att) == (5, 123, bytes(range(16)))
    assert zenohproto.decode_attachment(att[:32]) is None


def test_the_peer_program_says_when_zenoh_is_missing(tmp_path):
    import subprocess
    import sys
    src = Path(zenohproto.__file__).read_text()
    shadow = tmp_path / "zenoh.py"
    shadow.write_text("raise ImportError('no zenoh here')\n")
    r = subprocess.run([sys.executable, "-", "sub", "--timeout", "1"], input=src,
                       capture_output=True, text=True, timeout=30, cwd=tmp_path,
                       env={"PYTHONPATH": str(tmp_path), "HOME": str(tmp_path),
                            "PATH": "/usr/bin:/bin"})
    rep = zenohproto.parse_report(r.stdout)
    assert r.returncode == zenohproto.NO_ZENOH_EXIT and rep["error"] == "no_zenoh", r.stderr


# --------------------------------------------------------------------------- configuration
def test_router_configs_per_role():
    m, s = ros2.router_config(master(security="none")), ros2.router_config(member(security="none"))
    assert m["listen"]["endpoints"] == ["tcp/0.0.0.0:7447"] and m["connect"]["endpoints"] == []
    assert s["connect"]["endpoints"] == ["tcp/turtlebot:7447"]
    other = ros2.router_config(master(zenoh_port=17447, security="none"))["listen"]["endpoints"]
    assert other == ["tcp/0.0.0.0:17447", "tcp/127.0.0.1:7447"]
    text = ros2.render_router_config(member(security="none"))
    assert text.startswith(ros2.MANAGED_HEADER) and ros2.loads_json5(text) == s
    assert ros2.router_config_problems(member(security="none"), ["tcp/[::]:7447"], [], True)
    assert "no IPv6" in ros2.router_config_problems(master(security="none"), ["tcp/[::]:7447"], [], False)[0]
    assert "loopback" in ros2.router_config_problems(master(security="none"), ["tcp/127.0.0.1:7447"], [], True)[0]
    assert ros2.router_config_problems(master(security="none"), ["tcp/0.0.0.0:7447"], [], False) == []


def test_override_parsing_and_the_lone_node_rules():
    values, bad = ros2.parse_override(ros2.client_override(member(security="none")))
    assert bad == [] and values == {"mode": "client", "connect/endpoints": ["tcp/turtlebot:7447"]}
    assert ros2.override_problems(member(security="none"), values) == []
    peer, _ = ros2.parse_override('mode="peer";connect/endpoints=["tcp/turtlebot:7447"]')
    assert "peers connected straight" in ros2.override_problems(member(security="none"), peer)[0]
    assert ros2.parse_override("mode")[1]


def test_ros_apply_writes_both_files_and_refuses_a_foreign_config(tmp_path):
    from rosnet_tui.core.files import managed_file as mf
    from rosnet_tui.core.files import managed_text as mt

    rc, bashrc = tmp_path / "router.json5", tmp_path / "bashrc"
    bashrc.write_text("# mine\n")
    ps = ros2.previews(member(security="none"), bashrc, router_config_path=rc, distro="jazzy")
    mf.apply_previews(ps, state_dir=tmp_path / "state")
    text = bashrc.read_text()
    assert text.startswith("# mine\n# BEGIN rosnet-tui") and f"ZENOH_ROUTER_CONFIG_URI={rc}" in text
    assert json.loads(rc.read_text().split("\n", 4)[4])["connect"]["endpoints"] == [
        "tcp/turtlebot:7447"]
    client = ros2.previews(member(security="none"), bashrc, client=True, router_config_path=rc, distro="jazzy")
    assert len(client) == 1 and "ZENOH_CONFIG_OVERRIDE='mode=\"client\"" in client[0].new.decode()
    humble = ros2.previews(member(security="none"), bashrc, client=True, distro="humble",
                           session_config_path=tmp_path / "s.json5")
    assert "ZENOH_SESSION_CONFIG_URI" in humble[0].new.decode() and len(humble) == 2
    mf.undo_last(tmp_path / "state")
    assert bashrc.read_text() == "# mine\n" and not rc.exists()
    rc.write_text("{ mode: 'router' }  // my own\n")
    with pytest.raises(mt.ManagedFileError, match="not written by rosnet-tui"):
        ros2.previews(member(security="none"), bashrc, router_config_path=rc)


def test_steps_text_per_role():
    assert "Nothing to forward" in STEP_BY_ID["router"].configure(member())
    assert "TCP 7447" in STEP_BY_ID["router"].configure(master())
    assert "carrier-grade NAT included" in STEP_BY_ID["isp"].configure(member())
    assert "VPS" in STEP_BY_ID["isp"].configure(master())
    ros = STEP_BY_ID["ros"].configure(member())
    assert "tls/turtlebot:7447" in ros and "client mode" in ros and "Humble" in ros
    assert "ros pair" in ros                                       # mutual TLS, the default
    assert "Only the fleet gets in" in STEP_BY_ID["router"].configure(master())
    open_master = master(security="none")
    assert "tcp/0.0.0.0:7447" in STEP_BY_ID["ros"].configure(open_master)
    assert "Exposure" in STEP_BY_ID["router"].configure(open_master)
    assert "tcp/turtlebot:7447" in STEP_BY_ID["ros"].configure(member(security="none"))


# --------------------------------------------------------------------------- address sync
def test_address_sync_leaves_the_ros2_block_alone(tmp_path):
    """Sync rewrites the master's hosts line; under ROS 2 that is all (the router dials the
    master by name), and it must not put a ROS 1 ROS_MASTER_URI block over the ROS 2 one."""
    from rosnet_tui.core.files import managed_file as mf
    from rosnet_tui.core.sync.service import SyncService
    from rosnet_tui.core.sync.watcher import LocalAddress, PublicLookup

    s = replace(member(), sync=replace(member().sync, folder=str(tmp_path / "shared")))
    (tmp_path / "shared").mkdir()
    cfg = tmp_path / "config.toml"
    cfg.write_text(render_settings(s))
    bashrc, hosts = tmp_path / "bashrc", tmp_path / "hosts"
    hosts.write_text("127.0.0.1\tlocalhost\n")
    bashrc.write_text("# mine\n")
    mf.apply_previews(ros2.previews(s, bashrc, router_config_path=tmp_path / "r.json5",
                                    distro="jazzy"), state_dir=tmp_path / "st")
    before = bashrc.read_text()
    svc = SyncService(Paths(config_path=cfg, state_dir=tmp_path / "state", hosts_path=hosts,
                            bashrc_path=bashrc), write_bashrc=True,
                      local_source=lambda _s: LocalAddress("eth0", "192.168.1.10", "192.168.1.1"),
                      public_source=lambda _s: PublicLookup("198.51.100.2", "test"),
                      netlink=False, run_checks=False)
    svc.publisher.next_fetch = svc.publisher.next_publish = svc.applier.next_apply = 0.0
    res = svc.round()
    assert res.ok and res.applied
    assert "203.0.113.2\tturtlebot" in hosts.read_text().replace(" ", "\t") or \
        "turtlebot" in hosts.read_text()
    assert bashrc.read_text() == before, bashrc.read_text()


def test_the_zenoh_peer_program_runs_with_the_peers_site_packages(tmp_path):
    """The ROS 1 probes run ``python3 -S`` (stdlib only, a faster start: issue 14), but the Zenoh
    peer program imports eclipse-zenoh from the site-packages of the rosnet-tui installed on the
    peer (issue 21; tests/test_peer_install.py): its interpreter runs it with site."""
    import subprocess
    import sys

    from rosnet_tui.core.peer.commands import python_stdin_command, zenoh_peer_command

    cmd = zenoh_peer_command("graph", "--timeout", "1")
    assert cmd.startswith("sh -c ") and 'exec "$py" - "$@"' in cmd
    assert python_stdin_command("nodes").startswith("python3 -I -S - ")
    src = Path(zenohproto.__file__).read_text()
    path = f"{Path(sys.executable).parent}:/usr/bin:/bin"   # where this rosnet-tui's launcher is
    r = subprocess.run(["sh", "-c", cmd], input=src, capture_output=True, text=True, timeout=30,
                       cwd=tmp_path, env={"HOME": str(tmp_path), "PATH": path})
    rep = zenohproto.parse_report(r.stdout)
    assert rep is not None and rep.get("error") != "no_zenoh", (r.stdout, r.stderr)


@pytest.mark.parametrize("value", ["\u00b9", "\u0663", "7x", ""])
def test_a_domain_id_that_is_no_ascii_number_falls_back_to_the_settings(tmp_path, value):
    """ROS_DOMAIN_ID from the environment: '¹' and Arabic-Indic digits are digits to Python,
    which int() then refuses; the nodes' domain is the settings' (ros2.env names the
    mismatch), never a crash of the checks that read it."""
    from rosnet_tui.core.checks import CheckContext
    from rosnet_tui.core.checks.probes.ros2 import node_domain

    ctx = CheckContext(settings=member(domain_id=5), paths=Paths(bashrc_path=tmp_path / "rc"),
                       env={"ROS_DOMAIN_ID": value})
    assert node_domain(ctx) == (0 if value == "" else 5)
