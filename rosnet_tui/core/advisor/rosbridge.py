"""Step 4, both ROS versions: the rules that read ros.rosbridge (a browser's path to rosbridge),
one per hop, and what an open bridge exposes.

The check names the hop where the exchange broke (name, forward, upgrade, bridge, rosapi,
round_trip); each rule below explains one hop and sends the user to the step where it is fixed.
"""

from __future__ import annotations

from rosnet_tui.core.advisor.engine import Hit, rule
from rosnet_tui.core.advisor.evidence import Evidence, join_and
from rosnet_tui.core.ros import rosbridge

CHECK = "ros.rosbridge"


def _failed(ev: Evidence, *hops: str) -> bool:
    if not ev.s.rosbridge.enabled or not ev.is_fail(CHECK):
        return False
    return ev.data("ros.rosbridge").get("failed_hop") in hops


def _host(ev: Evidence) -> str:
    return ev.s.rosbridge_host or "the bridge's host"


def _seen(ev: Evidence) -> list[str]:
    d = ev.data("ros.rosbridge")
    return [f"{CHECK}: {d.get('url')}: {d.get('failed_hop')} hop: {d.get('detail')}"]


def _launch(ev: Evidence) -> str:
    return rosbridge.launch_command(ev.s)


@rule("rosbridge.name", "ros", (CHECK,),
      "the bridge's host name does not resolve here",
      "A browser opens ws://<host>:<port>/ by name; here the name has no address, so no web "
      "client on this component reaches the bridge.",
      "Add the host to /etc/hosts (the Linux step's hosts set; `rosnet-tui hosts apply`).",
      "linux", "fail")
def _name(ev: Evidence) -> list[Hit]:
    if not _failed(ev, "name"):
        return []
    host = _host(ev)
    return [Hit(f"The name {host} does not resolve on {ev.me}, so a browser here cannot open "
                f"{rosbridge.url(ev.s)}: the same names the ROS nodes use must work for it.",
                [f"On {ev.me}: `rosnet-tui hosts apply` writes {host}'s public address into "
                 "/etc/hosts (Linux step), then re-run the ROS step."],
                evidence=_seen(ev))]


@rule("rosbridge.forward", "ros", (CHECK,),
      "TCP to the bridge's port is dropped or unreachable through the forward",
      "The bridge's host has a modem in front of it; a connection to its port that gets no "
      "answer (or an ICMP error) means the modem does not forward it, or forwards it to a "
      "machine that is not there.",
      "Forward TCP <port> to the host's local IP on its modem (under ROS 2 besides the Zenoh "
      "port; under ROS 1 the 1024-65000 range covers 9090).",
      "router", "fail")
def _forward(ev: Evidence) -> list[Hit]:
    if not _failed(ev, "forward"):
        return []
    host, port = _host(ev), ev.s.rosbridge.port
    d = ev.data("ros.rosbridge")
    how = ("an ICMP error came back (no machine where the modem forwards to)"
           if d.get("tcp") == "unreachable" else "nothing answered (the packets were dropped)")
    return [Hit(f"TCP {port} on {host} ({d.get('address')}) did not connect from {ev.me}: {how}. "
                f"{host}'s modem does not forward TCP {port}, or forwards it to the wrong local "
                "address.",
                [f"On {host}'s modem: forward TCP {port} to {host}'s local IP"
                 + (f", besides the Zenoh port {ev.s.ros.zenoh_port}" if ev.s.ros2 else "")
                 + "; reserve that IP for it by DHCP (Router step on the host).",
                 "Then re-run the ROS step here."],
                evidence=_seen(ev))]


@rule("rosbridge.not_running", "ros", (CHECK,),
      "the bridge's host refuses its port, or the WebSocket opens and rosbridge never answers",
      "The forward reaches the host, but rosbridge is not running there (nothing takes the "
      "port), or it is hung.",
      "Start rosbridge on its host (roslaunch rosbridge_server rosbridge_websocket.launch; "
      "ROS 2: ros2 launch rosbridge_server rosbridge_websocket_launch.xml).",
      "ros", "fail")
def _not_running(ev: Evidence) -> list[Hit]:
    if not _failed(ev, "bridge"):
        return []
    host, port = _host(ev), ev.s.rosbridge.port
    d = ev.data("ros.rosbridge")
    if d.get("tcp") == "refused":
        meaning = (f"{host} answers on its public address but refuses TCP {port}: rosbridge is "
                   "not running there, or listens on another port. (A modem that refuses "
                   "ports it does not forward answers the same way; the Router step's port test "
                   "tells the two apart.)")
    else:
        meaning = (f"The WebSocket to {rosbridge.url(ev.s)} opened, but rosbridge did not "
                   "answer the protocol: the bridge is hung or is not rosbridge.")
    return [Hit(meaning,
                [f"On {host}: `{_launch(ev)}` (it starts rosapi too); keep it running (a "
                 "systemd service or the robot's launch file).",
                 "Then re-run the ROS step."],
                evidence=_seen(ev))]


@rule("rosbridge.upgrade", "ros", (CHECK,),
      "TCP connects but the HTTP upgrade to WebSocket is refused",
      "Something that is not rosbridge's WebSocket server answers on the port (a web server, "
      "another program), or a proxy in between does not pass the upgrade.",
      "Free the port for rosbridge, or run it on another port ([rosbridge] port and the forward).",
      "ros", "fail")
def _upgrade(ev: Evidence) -> list[Hit]:
    if not _failed(ev, "upgrade"):
        return []
    host, port = _host(ev), ev.s.rosbridge.port
    return [Hit(f"TCP {port} on {host} accepts connections, but the HTTP upgrade to WebSocket "
                "fails: another program holds the port (or the modem forwards it to another "
                "machine).",
                [f"On {host}: `sudo ss -ltnp 'sport = :{port}'` names the program; stop it, or "
                 "give rosbridge another port (`port:=N`, [rosbridge] port, and the forward).",
                 "Then re-run the ROS step."],
                evidence=_seen(ev))]


@rule("rosbridge.rosapi", "ros", (CHECK,),
      "rosbridge answers, but /rosapi/topics does not exist or fails",
      "rosbridge relays service calls to ROS; the topic list a web page shows comes from the "
      "rosapi node, which is not running.",
      "Start rosapi (the rosbridge launch file does; or rosrun rosapi rosapi_node / ros2 run "
      "rosapi rosapi_node).",
      "ros", "fail")
def _rosapi(ev: Evidence) -> list[Hit]:
    if not _failed(ev, "rosapi"):
        return []
    host = _host(ev)
    node = "ros2 run rosapi rosapi_node" if ev.s.ros2 else "rosrun rosapi rosapi_node"
    return [Hit(f"rosbridge on {host} answers, but {rosbridge.TOPICS_SERVICE} does not: the "
                "rosapi node is not running, so web pages get no topic list (and no other "
                "rosapi service).",
                [f"On {host}: start the bridge with its launch file (`{_launch(ev)}`), which "
                 f"starts rosapi too, or start it alone: `{node}`.",
                 "Then re-run the ROS step."],
                evidence=_seen(ev))]


@rule("rosbridge.round_trip", "ros", (CHECK,),
      "the bridge answers, but a message published through it is not received through it",
      "rosbridge and rosapi work, but the bridge's own publisher and subscriber do not meet in "
      "ROS: the bridge cannot reach the master or its nodes, or the type is unknown there.",
      "Check the bridge's ROS environment on its host (ROS_MASTER_URI, the hosts file) and its "
      "log.",
      "ros", "fail")
def _round_trip(ev: Evidence) -> list[Hit]:
    if not _failed(ev, "round_trip"):
        return []
    host = _host(ev)
    return [Hit(f"rosbridge on {host} lists the topics, but a message published through it did "
                "not come back through it: inside ROS, the bridge's publisher and subscriber "
                "did not connect (the bridge's own ROS environment, or std_msgs missing there).",
                [f"On {host}: start rosbridge from a shell that sourced ~/.bashrc (the same ROS "
                 "environment as the other nodes), and read its log for errors.",
                 "Then re-run the ROS step."],
                evidence=_seen(ev))]


@rule("security.rosbridge_exposed", "router", (CHECK,),
      "rosbridge is reachable from the internet",
      "rosbridge takes any client: whoever reaches its port can list topics, publish (drive the "
      "robot) and call services, exactly like the ROS master - there is no authentication "
      "unless rosauth is set up.",
      "Restrict its port to the peers' addresses, like the ROS ports; or use rosauth, or reach "
      "it through an SSH tunnel instead of a forward.",
      "router", "security")
def _exposed(ev: Evidence) -> list[Hit]:
    b = ev.s.rosbridge
    if not b.enabled or ev.data("ros.rosbridge").get("upgraded") is not True:
        return []
    host, port = _host(ev), b.port
    peers = [f"{p.name} {p.public_ip}" for p in ev.s.peers if p.public_ip]
    return [Hit(f"rosbridge on {host} (TCP {port}) takes any client that reaches it: topics, "
                "publishing (so driving the robot) and service calls, like the ROS master. It "
                "has no authentication of its own.",
                ["Any restriction to the peers' addresses (on the modem, where it can, or a "
                 f"firewall on {host}) must cover TCP {port} as well as the ROS ports"
                 + (f" (peers: {join_and(peers)})" if peers else "") + ".",
                 "Or switch on rosbridge's rosauth (`authenticate:=true`), or do not forward the "
                 f"port and reach it through SSH: `ssh -L {port}:localhost:{port} {host}`, then "
                 f"ws://localhost:{port}/."],
                evidence=[f"{CHECK}: a WebSocket to {rosbridge.url(ev.s)} opened from {ev.me}"])]
