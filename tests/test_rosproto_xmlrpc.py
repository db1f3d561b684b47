"""rosproto's own XML-RPC (client and server on a plain socket, issue 25) against Python's
xmlrpc library on real loopback sockets, both ways; and its small command-line parser. The wire
against roscore and rospy is in tests/test_rosproto.py."""

from __future__ import annotations

import http.client
import socket
import subprocess
import sys
import threading
import xmlrpc.client
from pathlib import Path
from xmlrpc.server import SimpleXMLRPCServer

import pytest

from rosnet_tui.core.peer import rosproto

SOURCE = Path(rosproto.__file__).read_bytes()


@pytest.fixture
def stdlib_server():
    server = SimpleXMLRPCServer(("127.0.0.1", 0), logRequests=False, allow_none=True)
    server.register_function(lambda *a: [1, "echo", list(a)], "echo")
    server.register_function(lambda: 1 / 0, "boom")
    threading.Thread(target=server.serve_forever, args=(0.05,), daemon=True).start()
    yield f"http://127.0.0.1:{server.server_address[1]}/"
    server.shutdown()
    server.server_close()


VALUES = ["plain", "a <b> & 'c' \"d\" é ☃", "", 0, -7, 2**31 - 1, True, False, 1.5, None,
          [], [1, ["x", [2.25]]], {"k": [1, {"n": None}]}, {}]


def test_our_client_round_trips_every_value_through_the_stdlib_server(stdlib_server):
    answer = rosproto.xmlrpc_call(stdlib_server, "echo", *VALUES, timeout=3)
    assert answer == [1, "echo", VALUES]


def test_a_fault_and_an_unknown_method_come_back_as_faults(stdlib_server):
    for method in ("boom", "nosuch"):
        with pytest.raises(rosproto.XmlRpcFault) as exc:
            rosproto.xmlrpc_call(stdlib_server, method, timeout=3)
        assert rosproto.describe_error(exc.value)[0] == "fault"


def test_an_http_error_and_a_non_xml_answer_are_named():
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(4)
    answers = [b"HTTP/1.0 404 Not Found\r\nContent-Length: 0\r\n\r\n",
               b"HTTP/1.0 200 OK\r\nContent-Length: 9\r\n\r\nnot xml!!",
               b"SSH-2.0-OpenSSH_9.6\r\n"]

    def serve():
        for a in answers:
            c, _ = srv.accept()
            c.recv(65536)
            c.sendall(a)
            c.close()

    t = threading.Thread(target=serve, daemon=True)
    t.start()
    uri = f"http://127.0.0.1:{srv.getsockname()[1]}/"
    kinds = []
    for _ in answers:
        with pytest.raises(Exception) as exc:
            rosproto.xmlrpc_call(uri, "getPid", "/x", timeout=2)
        kinds.append(rosproto.describe_error(exc.value)[0])
    t.join(2)
    srv.close()
    assert kinds == ["http", "protocol", "protocol"]


def test_a_silent_server_times_out():
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)
    try:
        with pytest.raises((TimeoutError, socket.timeout)):
            rosproto.xmlrpc_call(f"http://127.0.0.1:{srv.getsockname()[1]}/", "getPid", "/x",
                                 timeout=0.3)
    finally:
        srv.close()


def test_our_server_answers_the_stdlib_client():
    node = rosproto.ProbeNode("http://127.0.0.1:9/", "/t", "sub", env={"ROS_IP": "127.0.0.1"})
    node.start_server()
    try:
        proxy = xmlrpc.client.ServerProxy(node.uri, allow_none=True)
        assert proxy.getMasterUri("/c") == [1, "", "http://127.0.0.1:9/"]
        assert proxy.publisherUpdate("/c", "/t", ["http://a:1/"]) == [1, "", 0]
        assert proxy.paramUpdate("/c", "/p", {"x": [1.5, None]}) == [1, "", 0]
        assert node.updates.is_set() and "publisherUpdate for /t by /c from 127.0.0.1" in \
            node.callbacks[0]
        with pytest.raises(xmlrpc.client.Fault):
            proxy.noSuchMethod("/c")
        port = int(node.uri.rstrip("/").rsplit(":", 1)[1])
        conn = http.client.HTTPConnection("127.0.0.1", port, timeout=3)
        conn.request("GET", "/")
        assert conn.getresponse().status == 501   # only POST, as SimpleXMLRPCServer
        conn.close()
    finally:
        node.stop_server()


def test_parse_uri_matches_urllib():
    from urllib.parse import urlparse
    for uri in ("http://Host.Example:11311/", "http://10.0.0.2:45100", "rosrpc://h:1",
                "http://[::1]:8080/x", "http://u@h/", "http://h:/"):
        p = urlparse(uri)
        assert rosproto.parse_uri(uri)[:3] == (p.scheme, p.hostname or "", p.port), uri
    for bad in ("http://h:99999/", "http://h:x1/"):
        with pytest.raises(ValueError):
            rosproto.split_uri(bad)


@pytest.mark.parametrize("argv", [[], ["bogus"], ["sub", "--master", "http://h:1/"],
                                  ["pub", "--topic"], ["nodes", "--topic", "/t"],
                                  ["sub", "--topic", "/t", "--timeout", "soon"],
                                  ["whoami", "--linger"]])
def test_bad_command_lines_are_refused_with_exit_2(argv):
    res = subprocess.run([sys.executable, "-S", "-", *argv], input=SOURCE, capture_output=True,
                         timeout=20)
    assert res.returncode == 2 and b"Traceback" not in res.stderr
    assert b"usage: rosproto" in res.stderr


def test_the_command_line_forms():
    a = rosproto.parse_args(["nodes", "--master=http://h:1/", "--timeout", "2.5",
                              "--include", "/a", "--include=/b", "--bashrc", ""])
    assert (a.cmd, a.master, a.timeout, a.include, a.bashrc) == \
        ("nodes", "http://h:1/", 2.5, ["/a", "/b"], "")
    a = rosproto.parse_args(["pub", "--topic", "/t", "--linger"])
    assert a.linger and a.topic == "/t" and a.timeout == 5.0 and a.bashrc == "~/.bashrc"
