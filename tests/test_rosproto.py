"""rosproto against a real roscore on loopback: Master API, Slave API, TCPROS, hop verdicts.

The ROS 1 tools (roscore, rospy, rostopic) are the Debian packages and run under /usr/bin/python3;
every process started here is on 127.0.0.1 and is killed at the end.
"""

from __future__ import annotations

import json
import os
import socket
import struct
import subprocess
import threading
import time
import xmlrpc.client
from pathlib import Path
from xmlrpc.server import SimpleXMLRPCServer

import pytest

from rosnet_tui.core.peer import rosproto
from tests.builders import free_port
from tests.plugins.roscore import ROS_PYTHON, RosCore, kill_group

SOURCE = Path(rosproto.__file__).read_bytes()
LOOPBACK_ENV = {"ROS_IP": "127.0.0.1"}


TALKER = """
import sys, rospy
from std_msgs.msg import String
rospy.init_node("talker_test", anonymous=True, disable_signals=True)
pub = rospy.Publisher(sys.argv[1], String, queue_size=10)
rate = rospy.Rate(20)
end = rospy.Time.now() + rospy.Duration(float(sys.argv[2]))
while not rospy.is_shutdown() and rospy.Time.now() < end:
    pub.publish(String("hello from rospy"))
    rate.sleep()
"""


def ros_tool(core: RosCore, argv: list[str]) -> subprocess.Popen:
    return subprocess.Popen(argv, env=core.env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            stdin=subprocess.DEVNULL, text=True, start_new_session=True)


def unique_topic() -> str:
    return f"/rosnet_test/{rosproto.new_probe_id()}"


# --------------------------------------------------------------------------- pure parts
def test_connection_header_matches_the_documented_layout():
    # The wiki's example: rostopic publishing std_msgs/String "hello" on /chatter.
    fields = {"message_definition": "string data\n\n",
              "callerid": "/rostopic_4767_1316912741557", "latching": "1",
              "md5sum": rosproto.STRING_MD5, "topic": "/chatter", "type": "std_msgs/String"}
    wire = rosproto.encode_header(fields)
    assert wire[:4] == bytes.fromhex("b0000000")  # 176 bytes, little-endian
    assert wire[4:8] == bytes.fromhex("20000000") and wire[8:26] == b"message_definition"
    assert rosproto.decode_header(wire[4:]) == fields
    assert rosproto.encode_string("hello") == bytes.fromhex("0900000005000000") + b"hello"
    assert rosproto.decode_string(rosproto.encode_string("héllo")[4:]) == "héllo"
    with pytest.raises(ValueError):
        rosproto.decode_header(struct.pack("<I", 10) + b"abc")


def test_bashrc_parsing_last_effective_export_wins(tmp_path: Path):
    rc = tmp_path / "bashrc"
    rc.write_text(
        "# export ROS_MASTER_URI=http://commented:11311\n"
        "export ROS_MASTER_URI=http://first:11311\n"
        "  export ROS_MASTER_URI='http://turtlebot:11311'  # the robot\n"
        "#export ROS_IP=10.0.0.1\n"
        "ROS_HOSTNAME=sami; export ROS_HOSTNAME\n"
        "export ROS_IP=192.168.1.10\n"
        "unset ROS_IP\n"
        "source /opt/ros/noetic/setup.bash\n")
    found = rosproto.read_shell_exports(str(rc), ("ROS_MASTER_URI", "ROS_IP", "ROS_HOSTNAME"))
    assert found["ROS_MASTER_URI"] == ("http://turtlebot:11311", 3)
    assert found["ROS_HOSTNAME"] == ("sami", 5)
    assert found["ROS_IP"] == (None, 7)
    assert rosproto.read_shell_exports(str(tmp_path / "missing"), ("ROS_IP",)) == {}


def test_advertised_host_follows_rospy_rules(tmp_path: Path):
    rc = tmp_path / "bashrc"
    rc.write_text("export ROS_IP=10.1.2.3\n")
    assert rosproto.advertised_host({"ROS_HOSTNAME": "sami", "ROS_IP": "1.2.3.4"})[0] == "sami"
    assert rosproto.advertised_host({"ROS_IP": "127.0.0.1"}) == ("127.0.0.1",
                                                                 "ROS_IP (environment)")
    host, why = rosproto.advertised_host({}, str(rc))       # a new terminal would get it
    assert host == "10.1.2.3" and "bashrc line 1" in why
    assert rosproto.advertised_host({"ROS_IP": "127.0.0.9"}, str(rc))[0] == "127.0.0.9"
    host, why = rosproto.advertised_host({}, None)
    assert why.startswith(("the hostname", "a local address"))
    assert rosproto.bind_address("127.0.0.1") == "127.0.0.1"
    assert rosproto.bind_address("localhost") == "127.0.0.1"
    assert rosproto.bind_address("192.168.1.10") == "0.0.0.0"


# --------------------------------------------------------------------------- Master API
def test_master_api_register_lookup_unregister(roscore: RosCore):
    m = rosproto.MasterClient(roscore.uri, "/rosnet_test_node", 2.0)
    topic = unique_topic()
    api = f"http://127.0.0.1:{free_port()}/"
    assert m.get_uri().rstrip("/").endswith(str(roscore.port))
    assert m.register_publisher(topic, rosproto.STRING_TYPE, api) == []
    state = m.get_system_state()
    assert state.publishers_of(topic) == ["/rosnet_test_node"]
    assert "/rosnet_test_node" in state.nodes and topic in state.topics
    assert m.lookup_node("/rosnet_test_node") == api
    assert (topic, rosproto.STRING_TYPE) in m.get_topic_types()
    sub = rosproto.MasterClient(roscore.uri, "/rosnet_test_sub", 2.0)
    sub_api = f"http://127.0.0.1:{free_port()}/"
    assert sub.register_subscriber(topic, rosproto.STRING_TYPE, sub_api) == [api]
    assert sub.unregister_subscriber(topic, sub_api) == 1
    assert m.unregister_publisher(topic, api) == 1
    assert topic not in m.get_system_state().topics
    with pytest.raises(rosproto.MasterCallError) as err:
        m.lookup_node("/no_such_node")
    assert rosproto.describe_error(err.value)[0] == "master"


def test_dead_master_is_refused_at_once():
    uri = f"http://127.0.0.1:{free_port()}"
    start = time.monotonic()
    with pytest.raises(OSError) as err:
        rosproto.MasterClient(uri, "/t", 10.0).get_system_state()
    assert rosproto.describe_error(err.value)[0] == "refused"
    assert time.monotonic() - start < 5.0       # at once: not after the (long) timeout
    rep = rosproto.run_subscriber(uri, unique_topic(), 2.0, env=LOOPBACK_ENV)
    assert rep.failed_hop == "registration" and rep.uri == uri and not rep.ok
    assert "refused" in rep.hops[-1].detail


def test_silent_master_times_out_within_its_timeout():
    # A port that accepts connections (the kernel's backlog) but never answers.
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen(8)
        uri = f"http://127.0.0.1:{s.getsockname()[1]}"
        start = time.monotonic()
        with pytest.raises(OSError) as err:
            rosproto.MasterClient(uri, "/t", 0.8).get_system_state()
        took = time.monotonic() - start
    assert rosproto.describe_error(err.value, 0.8) == ("timeout",
                                                       "no answer within 0.8 s (timed out)")
    assert 0.7 < took < 2 * 0.8  # one wait, never two (bench row 3 times it)


# --------------------------------------------------------------------------- pub/sub with real ROS
def test_our_subscriber_hears_a_rospy_talker(roscore: RosCore):
    topic = unique_topic()
    talker = ros_tool(roscore, [str(ROS_PYTHON), "-c", TALKER, topic, "15"])
    try:
        rep = rosproto.run_subscriber(roscore.uri, topic, 10.0, env=LOOPBACK_ENV)
    finally:
        kill_group(talker, 2)
    assert rep.ok, rep.evidence()
    assert rep.received == "hello from rospy"
    assert [h.hop for h in rep.hops if h.ok and h.hop != "info"] == list(rosproto.HOPS)
    assert rep.advertised_uri.startswith("http://127.0.0.1:")


def test_rostopic_echo_hears_our_publisher(roscore: RosCore):
    topic = unique_topic()
    pub = rosproto.ProbePublisher(roscore.uri, topic, env=LOOPBACK_ENV, call_timeout=2.0)
    assert pub.start(), pub.report.evidence()
    try:
        echo = ros_tool(roscore, ["/usr/bin/rostopic", "echo", "-n", "1", topic])
        try:
            out, err = echo.communicate(timeout=15)
        except subprocess.TimeoutExpired:
            kill_group(echo, 1)
            out, err = echo.communicate()
        assert pub.wait_served(3.0)
    finally:
        rep = pub.stop()
    assert "rosnet-tui probe" in out, err
    assert rep.ok and rep.served == 1 and rep.sent >= 1
    assert any(h.hop == "xmlrpc_callback" and h.ok and "rostopic" in h.detail for h in rep.hops)
    # Unregistered on stop: the topic has no publisher left.
    assert not rosproto.MasterClient(roscore.uri).get_system_state().publishers_of(topic)


def test_probe_publisher_and_subscriber_either_order(roscore: RosCore):
    # Subscriber first: it learns of the publisher later (publisherUpdate or asking again).
    topic = unique_topic()
    result: dict = {}
    t = threading.Thread(target=lambda: result.update(
        rep=rosproto.run_subscriber(roscore.uri, topic, 6.0, env=LOOPBACK_ENV)))
    t.start()
    master, end = rosproto.MasterClient(roscore.uri), time.monotonic() + 6.0
    while time.monotonic() < end and not any(   # the subscriber is registered: it was first
            name == topic for name, _ in master.get_system_state().subscribers):
        time.sleep(0.02)
    pub_rep = rosproto.run_publisher(roscore.uri, topic, 6.0, env=LOOPBACK_ENV)
    t.join(8)
    assert result["rep"].ok, result["rep"].evidence()
    assert any("learned of publisher" in h.detail for h in result["rep"].hops)
    assert pub_rep.ok and pub_rep.served == 1


def test_unreachable_node_uri_fails_the_callback_hop_and_is_named(roscore: RosCore):
    """A publisher whose advertised address accepts nothing: the shape of a wrong ROS_IP."""
    topic = unique_topic()
    dead = f"http://127.0.0.1:{free_port()}/"
    fake = rosproto.MasterClient(roscore.uri, "/fake_talker_with_bad_uri", 2.0)
    fake.register_publisher(topic, rosproto.STRING_TYPE, dead)
    try:
        start = time.monotonic()
        rep = rosproto.run_subscriber(roscore.uri, topic, 4.0, env=LOOPBACK_ENV)
        assert time.monotonic() - start < 4.5
        assert rep.failed_hop == "xmlrpc_callback"
        assert rep.node == "/fake_talker_with_bad_uri" and rep.uri == dead
        assert any("refused" in line for line in rep.evidence())

        nodes = rosproto.check_node_uris(roscore.uri, 3.0)
        bad = [n for n in nodes["nodes"] if n["node"] == "/fake_talker_with_bad_uri"]
        assert not nodes["ok"] and bad and bad[0]["uri"] == dead
        assert "refused" in bad[0]["reason"] and not bad[0]["reachable"]
    finally:
        fake.unregister_publisher(topic, dead)


def test_tcpros_hop_failure_is_named(roscore: RosCore):
    """requestTopic answers, but the TCPROS port it names accepts nothing."""
    topic = unique_topic()
    server = SimpleXMLRPCServer(("127.0.0.1", 0), logRequests=False, allow_none=True)
    closed = free_port()
    server.register_function(lambda c, t, p: [1, "ready", ["TCPROS", "127.0.0.1", closed]],
                             "requestTopic")
    threading.Thread(target=server.serve_forever, args=(0.1,), daemon=True).start()
    api = f"http://127.0.0.1:{server.server_address[1]}/"
    fake = rosproto.MasterClient(roscore.uri, "/fake_talker_tcpros", 2.0)
    fake.register_publisher(topic, rosproto.STRING_TYPE, api)
    try:
        rep = rosproto.run_subscriber(roscore.uri, topic, 4.0, env=LOOPBACK_ENV)
    finally:
        fake.unregister_publisher(topic, api)
        server.shutdown()
        server.server_close()
    assert rep.failed_hop == "tcpros" and rep.node == "/fake_talker_tcpros" and rep.uri == api
    assert any(h.hop == "xmlrpc_callback" and h.ok for h in rep.hops)
    assert f"127.0.0.1:{closed}" in rep.hops[-1].detail or any(
        f"127.0.0.1:{closed}" in h.detail for h in rep.hops if not h.ok)


def test_silent_publisher_gives_no_message(roscore: RosCore):
    topic = unique_topic()
    pub = rosproto.ProbePublisher(roscore.uri, topic, env=LOOPBACK_ENV, call_timeout=1.0,
                                  period=60.0, prompt=False)
    assert pub.start()
    try:
        rep = rosproto.run_subscriber(roscore.uri, topic, 1.5, env=LOOPBACK_ENV)
    finally:
        pub.stop()
    assert rep.failed_hop == "no_message" and rep.node == pub.caller_id
    assert [h.hop for h in rep.hops if h.ok and h.hop != "info"] == [
        "registration", "xmlrpc_callback", "tcpros"]


# --------------------------------------------------------------------------- script mode
def run_script(args: list[str], env: dict[str, str], timeout: float = 20.0
               ) -> subprocess.CompletedProcess:
    """The module as the peer runs it: its source piped into `python3 -` (Debian's python)."""
    return subprocess.run([str(ROS_PYTHON), "-", *args], input=SOURCE, capture_output=True,
                          env=env, timeout=timeout)


def test_script_sub_and_pub_over_stdin(roscore: RosCore, tmp_path: Path):
    env = {"PATH": "/usr/bin:/bin", "HOME": str(tmp_path), "ROS_IP": "127.0.0.1"}
    topic = unique_topic()
    pub = rosproto.ProbePublisher(roscore.uri, topic, env=LOOPBACK_ENV, call_timeout=2.0)
    assert pub.start()
    try:
        out = run_script(["sub", "--master", roscore.uri, "--topic", topic, "--timeout", "5"], env)
    finally:
        pub.stop()
    rep = rosproto.parse_report_line(out.stdout.decode())
    assert out.returncode == 0 and rep and rep["ok"], out.stderr.decode()
    assert rep["received"].startswith("rosnet-tui probe")

    # pub: announces itself once registered, ends once its subscriber got a message and left.
    topic = unique_topic()
    proc = subprocess.Popen([str(ROS_PYTHON), "-", "pub", "--master", roscore.uri, "--topic",
                             topic, "--timeout", "60"], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    try:
        proc.stdin.write(SOURCE)
        proc.stdin.close()
        ready = json.loads(proc.stdout.readline())
        assert ready[rosproto.READY_KEY] == 1 and ready["topic"] == topic
        sub = rosproto.run_subscriber(roscore.uri, topic, 5.0, env=LOOPBACK_ENV)
        assert sub.ok, sub.evidence()
        start = time.monotonic()
        out_text = proc.stdout.read().decode()
        proc.wait(30)
        # it ended when its subscriber left, not at its own 60 s (far from a loaded machine's)
        assert time.monotonic() - start < 20
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    final = rosproto.parse_report_line(out_text)
    assert final["ok"] and final["served"] == 1 and proc.returncode == 0


def test_script_nodes_and_bad_master(roscore: RosCore, tmp_path: Path):
    env = {"PATH": "/usr/bin:/bin", "HOME": str(tmp_path)}
    out = run_script(["nodes", "--master", roscore.uri, "--timeout", "3"], env)
    rep = rosproto.parse_report_line(out.stdout.decode())
    assert rep and rep["error"] is None and isinstance(rep["nodes"], list), out.stderr.decode()
    dead = f"http://127.0.0.1:{free_port()}"
    start = time.monotonic()
    out = run_script(["sub", "--master", dead, "--topic", "/x", "--timeout", "2"], env)
    rep = rosproto.parse_report_line(out.stdout.decode())
    assert out.returncode == 1 and rep["failed_hop"] == "registration"
    assert time.monotonic() - start < 5
    assert run_script([], env).returncode == 2


def test_slave_api_of_the_probe(roscore: RosCore):
    topic = unique_topic()
    pub = rosproto.ProbePublisher(roscore.uri, topic, env=LOOPBACK_ENV, call_timeout=2.0)
    assert pub.start()
    try:
        proxy = xmlrpc.client.ServerProxy(pub.uri)
        assert proxy.getPid("/x") == [1, "", os.getpid()]
        assert proxy.getPublications("/x") == [1, "", [[topic, rosproto.STRING_TYPE]]]
        assert proxy.requestTopic("/x", "/other", [["TCPROS"]])[0] == -1
        assert proxy.requestTopic("/x", topic, [["UDPROS"]])[0] == 0
        code, _, params = proxy.requestTopic("/x", topic, [["TCPROS"]])
        assert code == 1 and params[0] == "TCPROS" and params[1] == "127.0.0.1"
        # A subscriber asking with the wrong type is told why.
        with socket.create_connection(("127.0.0.1", params[2]), timeout=2) as s:
            hdr = rosproto.subscriber_header("/x", topic)
            hdr["md5sum"] = "0" * 32
            s.sendall(rosproto.encode_header(hdr))
            assert "md5sum" in rosproto.read_header(s)["error"]
        assert proxy.shutdown("/x", "test") == [1, "shutdown", 0]
        assert pub.stopping.is_set()
    finally:
        pub.stop()


def test_a_message_counts_as_sent_before_it_leaves():
    """A subscriber may read the first message and hang up before the sending thread runs again:
    the publish loop, seeing the hang-up, must find the message counted, or the probe waits for
    another subscriber to its timeout (bench row 8: ros.pubsub_in took 8.6 s of its 11.5)."""
    pub = rosproto.ProbePublisher("http://127.0.0.1:9/", "/rosnet_probe/count", env=LOOPBACK_ENV)
    counted: list[int] = []

    class Watched(socket.socket):       # a real socket that notes the count as a frame leaves
        def sendall(self, data, flags=0):
            counted.append(pub.report.sent)
            return super().sendall(data, flags)

    a, b = socket.socketpair()
    w = Watched(a.family, a.type, fileno=a.detach())
    try:
        pub._send(w, "/rosnet_probe_sub")
        assert counted == [1] and pub.report.sent == 1
        assert rosproto.decode_string(rosproto.read_frame(b)).startswith("rosnet-tui probe 1 ")
        b.close()                         # the other end is gone: a failed send is not counted
        with pytest.raises(OSError):
            for _ in range(50):
                pub._send(w, "/rosnet_probe_sub")
        assert pub.report.sent == len(counted) - 1
    finally:
        w.close()
        b.close()

