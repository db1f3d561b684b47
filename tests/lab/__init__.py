"""The network lab: the procedure's remote ROS network in Linux network namespaces.

    from tests.lab import Lab   # in pytest: the module-scoped `lab` fixture (tests/lab/fixtures.py)

Robot ``turtlebot`` (10.10.10.1) behind its modem (public 203.0.113.2), laptop ``sami``
(192.168.1.10) behind its modem (public 198.51.100.2), an "internet" namespace joining them with
the what-is-my-IP/port-check service (the product's probe server, http://probe.lab.test =
192.0.2.10) and a resolver (192.0.2.53). Each computer has its own hostname, /etc/hosts,
resolv.conf, HOME (.bashrc, .ssh) and sshd; roscore runs on the robot on demand.

Main API (see Lab's docstrings): wrap, run, spawn, kill, output, wait_output, rosnet, http_get,
config_path, settings, hosts_path, write_hosts, bashrc_path, home, env, ros_env, talker,
listener, start_roscore, stop_roscore, master_answers, listening, wait_listening, call_in,
variant, reset, set_robot_wan, public_ip, log_path, destroy.

On top of it: ``tests/lab/ros2.py`` (Ros2World: the ROS 2 network over real Zenoh routers) and
``tests/lab/upnp.py`` (UpnpModem: Debian's real miniupnpd in the robot's modem, UPnP IGD, PCP and
NAT-PMP, with stund on the internet side and an optional second LAN host).

Beside it: ``tests/lab/fleet.py`` (Fleet, a Lab subclass: a master and up to eight members, each
behind its own modem; the ``fleet`` fixture) and ``tests/lab/fleet_ros2.py`` (FleetRos2: ROS 2 on
it, every member's router linked to the master's).
"""

from .lab import Lab, LabUnavailable, lab_available
from .topology import ADDR, HOSTS, VARIANTS

__all__ = ["ADDR", "HOSTS", "VARIANTS", "Lab", "LabUnavailable", "lab_available"]
