"""The advisor's ROS 1 rules: the environment, the master, node URIs, publish/subscribe."""

from __future__ import annotations

from rosnet_tui.core.advisor import first_failure
from tests.advisor_support import (
    fresh_names,
    ids,
    master_down,
    master_uri,
    master_uri_unset,
    node_uri,
    only,
    peer_cannot_register,
    pubsub,
    ros_ip,
    run,
    text,
)
from tests.builders import healthy_laptop, healthy_robot, laptop_settings, put, robot_settings


def test_master_uri_unset_is_titled_not_set_and_says_what_to_set():
    """Issue 29 (section 4, row 4): a fresh install has no ROS_MASTER_URI at all; the finding
    says it is not set (not "wrong for the role") and what to set."""
    fs = run(master_uri_unset()[0])
    f = only(fs, "ros.env.master_uri_unset")
    assert f.condition == "ROS_MASTER_URI not set" and f.severity == "fail"
    assert f.meaning.startswith("ROS_MASTER_URI is not set on sami, neither in this shell nor "
                                "in ~/.bashrc") and "Set it to http://turtlebot:11311" in f.meaning
    assert "`rosnet-tui ros apply`" in text(f)
    assert "export ROS_MASTER_URI=http://turtlebot:11311" in text(f)
    assert "ros.env.master_uri" not in ids(fs) and f.check_ids == ["ros.env"]
    r = healthy_robot()
    put(r, "ros.env", "fail", env_uri=None, bashrc_uri=None, uri_ok=False,
        expected_uri="http://turtlebot:11311")
    f = only(run(r, robot_settings()), "ros.env.master_uri_unset")
    assert "turtlebot is the master" in f.meaning
    # set, to a wrong value: the other rule, and its title
    f = only(run(master_uri()[0]), "ros.env.master_uri")
    assert f.condition == "ROS_MASTER_URI wrong for the role" and "not set" not in f.meaning


def test_a_master_name_that_does_not_resolve_is_the_first_cause():
    robot = healthy_robot()
    robot["linux.resolve"].data["names"]["turtlebot"]["resolved"] = None
    put(robot, "linux.resolve", "fail", wrong=["turtlebot"])
    for r, s, first in ((fresh_names(), laptop_settings(), "Does turtlebot lead to the master"),
                        (robot, robot_settings(), "Map turtlebot")):
        put(r, "ros.master", "fail", reachable=False, topics=[], nodes=[])
        f = only(run(r, s), "ros.master.unreachable")
        assert f.goto_step == "linux" and f.actions[0].startswith(first), f.actions
        assert "turtlebot does not resolve here" in f.meaning


def test_master_uri_wrong_for_member_and_master():
    f = only(run(master_uri()[0]), "ros.env.master_uri")
    assert "http://203.0.113.2:11311" in f.meaning and "member" in f.meaning
    assert "export ROS_MASTER_URI=http://turtlebot:11311" in text(f)
    r = healthy_robot()
    put(r, "ros.env", "fail", env_uri="http://203.0.113.2:11311", bashrc_uri=None,
        expected_uri="http://turtlebot:11311", uri_ok=False)
    f = only(run(r, robot_settings()), "ros.env.master_uri")
    assert "is the master" in f.meaning and "public IP" in f.meaning
    # ~/.bashrc right but the shell stale
    r = healthy_laptop()
    put(r, "ros.env", "warn", env_uri="http://sami:11311", uri_ok=False)
    f = only(run(r), "ros.env.master_uri")
    assert "opened before the change" in f.meaning


def test_ros_ip_warns_on_remote_and_becomes_the_cause_when_ros_fails():
    f = only(run(ros_ip()[0]), "ros.env.ros_ip")
    assert f.severity == "warn"
    assert "Unset ROS_IP on sami" in f.actions[0] and "`unset ROS_IP`" in f.actions[0]
    assert "~/.bashrc on sami" in f.actions[0]
    r, s = ros_ip()
    put(r, "ros.pubsub_out", "fail", ok=False, failed_hop="xmlrpc_callback",
        uri="http://192.168.1.10:40001/", node="/probe")
    fs = run(r, s)
    f = first_failure(fs)
    assert f.rule == "ros.env.ros_ip" and f.severity == "fail"
    assert "ros.pubsub_out" in f.check_ids
    # on a LAN profile it is fine (info only)
    r, _ = ros_ip()
    f = only(run(r, laptop_settings(profile="office")), "ros.env.ros_ip")
    assert f.severity == "info"
    # ROS_HOSTNAME set to the component's own network name is harmless
    r = healthy_laptop()
    put(r, "ros.env", "warn", ros_hostname="sami")
    assert only(run(r), "ros.env.ros_ip").severity == "info"


def test_master_unreachable_member_and_master():
    f = only(run(master_down()[0]), "ros.master.unreachable")
    t = text(f)
    assert "roscore" in t and "turtlebot's modem" in t and "10.10.10.1" in t
    assert "getent hosts turtlebot" in t and "203.0.113.2" in t
    r = healthy_robot()
    put(r, "ros.master", "fail", reachable=False)
    f = only(run(r, robot_settings()), "ros.master.unreachable")
    assert "`roscore`" in text(f) and "on turtlebot" in text(f)


def test_node_uri_local_ip_names_the_component_to_fix():
    fs = run(*node_uri("192.168.1.10")())
    f = first_failure(fs)
    assert f.rule == "ros.node_uri.local_ip"
    assert "/talker on sami" in f.meaning
    assert f.actions[0].startswith("Unset ROS_IP on sami")
    # from the robot's seat the laptop's local address maps to sami too
    fs = run(*node_uri("192.168.1.10", robot_settings)())
    f = only(fs, "ros.node_uri.local_ip")
    assert "Unset ROS_IP on sami" in f.actions[0]
    # on a LAN profile a local address is the right one: not this rule
    r, _ = node_uri("192.168.1.10")()
    assert "ros.node_uri.local_ip" not in ids(run(r, laptop_settings(profile="office")))


def test_node_uri_unreachable_names_the_component_and_its_forwarding():
    f = only(run(*node_uri("turtlebot")()), "ros.node_uri.unreachable")
    assert "turtlebot's modem" in text(f) and "10.10.10.1" in text(f)
    assert "41234" in text(f)
    f = only(run(*node_uri("203.0.113.2")()), "ros.node_uri.unreachable")
    assert "turtlebot" in f.meaning


def test_node_uri_unknown_host_and_loopback():
    f = only(run(*node_uri("ubuntu-laptop")()), "ros.node_uri.unknown_host")
    assert "hostnamectl set-hostname" in text(f)
    f = only(run(*node_uri("192.0.2.99")()), "ros.node_uri.unknown_host")
    assert "unset ROS_IP" in text(f)
    f = only(run(*node_uri("127.0.1.1")()), "ros.node_uri.loopback")
    assert "127.0.1.1" in text(f)


def test_pubsub_one_way_uses_the_failed_hop_and_uri():
    fs = run(*pubsub(False, True, uri="http://192.168.1.10:40001/", node="/probe")())
    f = only(fs, "ros.pubsub.out_fails")
    assert "Unset ROS_IP on sami" in text(f)
    assert "ros.node_uri.local_ip" in ids(fs)      # the same evidence, by component
    f = only(run(*pubsub(True, False, hop="tcpros", uri="http://turtlebot:40002/")()),
             "ros.pubsub.in_fails")
    assert "turtlebot's modem" in text(f)
    f = only(run(*pubsub(True, False, hop="registration")()), "ros.pubsub.in_fails")
    assert "ROS_MASTER_URI" in text(f)


def test_pubsub_both_fail_is_superseded_by_a_dead_master():
    r, s = pubsub(False, False, hop="registration")()
    put(r, "ros.master", "fail", reachable=False)
    fs = run(r, s)
    assert "ros.pubsub.both_fail" not in ids(fs)
    assert "ros.master.unreachable" in ids(fs)


def test_dead_master_explains_the_ros_checks_that_follow_from_it():
    r, s = master_down()
    put(r, "ros.node_uris", "fail", unreachable=[], checked=0)
    put(r, "ros.pubsub_out", "fail", ok=False, failed_hop="registration",
        uri="http://turtlebot:11311")
    fs = run(r, s)
    assert [f.rule for f in fs if f.severity == "fail"] == ["ros.master.unreachable"]
    assert only(fs, "ros.master.unreachable").check_ids == ["ros.master", "ros.node_uris",
                                                            "ros.pubsub_out"]


def test_master_seat_peer_cannot_register():
    fs = run(*peer_cannot_register())
    f = first_failure(fs)
    assert f.rule == "ros.master.peer_cannot_register"
    assert "sami's nodes cannot register" in f.meaning
    assert "10.10.10.1" in text(f) and "getent hosts turtlebot" in text(f)
    assert set(f.check_ids) == {"ros.pubsub_out", "ros.pubsub_in", "ros.node_uris"}
    assert not {"ros.pubsub.both_fail", "check.unexplained"} & set(ids(fs))
