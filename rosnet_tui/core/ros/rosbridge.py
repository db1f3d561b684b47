"""Web clients (Robot Web Tools): rosbridge, the WebSocket bridge a browser talks to. One home for
its facts: how it is started under each ROS version, what the modem must forward for it, and the
words the steps show about it.

A browser running roslibjs opens ``ws://<host>:<port>/`` (rosbridge_server, TCP 9090 by default)
and speaks the rosbridge v2 JSON protocol (``op``: ``advertise``, ``publish``, ``subscribe``,
``call_service``; the topic list is the ``/rosapi/topics`` service of the rosapi node that the
launch file starts beside the bridge). rosbridge has no authentication of its own: it takes any
client, unless ``rosauth`` is set up.
"""

from __future__ import annotations

from rosnet_tui.core.config.settings_model import (
    PORT_MAX,
    PORT_MIN,
    ROSBRIDGE_PORT_DEFAULT,
    Settings,
)

LAUNCH_ROS1 = "roslaunch rosbridge_server rosbridge_websocket.launch"
LAUNCH_ROS2 = "ros2 launch rosbridge_server rosbridge_websocket_launch.xml"
INSTALL = "sudo apt install ros-$ROS_DISTRO-rosbridge-suite"
TOPICS_SERVICE = "/rosapi/topics"
# The probe message's type, as each ROS version's rosbridge names it.
PROBE_TYPE = {1: "std_msgs/String", 2: "std_msgs/msg/String"}


def launch_command(settings: Settings, version: int | None = None) -> str:
    """The command that starts rosbridge (and rosapi) under *version* (default: the settings'
    ROS version), on the settings' port."""
    port = settings.rosbridge.port
    base = LAUNCH_ROS2 if (version or settings.ros.version) == 2 else LAUNCH_ROS1
    return base + (f" port:={port}" if port != ROSBRIDGE_PORT_DEFAULT else "")


def url(settings: Settings) -> str:
    """What a browser opens: ws://<host>:<port>/ (by name, as the hosts files agree)."""
    return f"ws://{settings.rosbridge_host or '<host>'}:{settings.rosbridge.port}/"


def in_ros1_range(port: int) -> bool:
    """Whether ROS 1's forwarded range (1024-65000) already covers *port*."""
    return PORT_MIN <= port <= PORT_MAX


def forward_needed(settings: Settings) -> bool:
    """Whether this component's modem needs a forward of its own for the bridge (on top of what
    its ROS version forwards anyway)."""
    if not settings.hosts_rosbridge or settings.this.profile != "remote":
        return False
    return settings.ros2 or not in_ros1_range(settings.rosbridge.port)


def ros_step_text(s: Settings) -> str:
    """The ROS step's paragraph about the bridge ('' when [rosbridge] is off)."""
    if not s.rosbridge.enabled:
        return ""
    host, port = s.rosbridge_host or "<host>", s.rosbridge.port
    start = (f"Start it on *{host}* (`{INSTALL}` installs it): under ROS 1 "
             f"`{launch_command(s, 1)}`, under ROS 2 `{launch_command(s, 2)}`; both start rosapi "
             "too (the topic list).")
    if s.ros2:
        fwd = (f"*{host}*'s modem forwards TCP **{port}** to it, besides the Zenoh port "
               f"{s.ros.zenoh_port}.")
    elif in_ros1_range(port):
        fwd = (f"*{host}*'s modem already forwards it (ROS 1 forwards {PORT_MIN}-{PORT_MAX}).")
    else:
        fwd = f"*{host}*'s modem forwards TCP **{port}** to it (outside ROS 1's range)."
    where = ("This component runs it: the check runs from the others, as a browser would."
             if s.hosts_rosbridge else
             f"The check opens `{url(s)}` from here, as a browser would: by name, through the "
             "forward, the WebSocket upgrade, the topic list, and a message published and "
             "received through the bridge.")
    return (f"**Web clients (rosbridge).** Browsers (Robot Web Tools, roslibjs) reach ROS "
            f"through rosbridge at `{url(s)}`. {start} {fwd} {where} rosbridge takes any client "
            "(no authentication unless rosauth is set up): it is exposed like the master.")


def router_text(s: Settings) -> str:
    """The Router step's paragraph about the bridge's forward ('' when none is needed here)."""
    if not forward_needed(s):
        return ""
    port = s.rosbridge.port
    also = ("" if not s.ros2 else f", besides the Zenoh port {s.ros.zenoh_port}"
            if s.is_master else "") if s.ros2 else " (outside ROS 1's range)"
    return (f"**rosbridge (web clients).** Forward **TCP {port}** to "
            f"**{s.this.local_ip or '<this component local IP>'}** too{also}: browsers "
            "connect to it from outside. It takes any client, like the ROS master.")
