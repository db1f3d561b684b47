"""Regenerate screenshots/ from the real app: `python -m rosnet_tui.screenshots [--out DIR]`.

The scene is fixed (a telecom robot "turtlebot" that is the ROS master, and an operator laptop
"sami"), and so is what it shows, so the files only change when the app does. A test compares
the committed files with a fresh run.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import sys
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

from rosnet_tui.core.config.paths import Paths
from rosnet_tui.core.config.settings_model import Peer, Settings, ThisComponent
from rosnet_tui.core.net.netinfo import LocalNet
from rosnet_tui.core.results import CheckResult, Status
from rosnet_tui.core.wizard.steps import STEPS

if TYPE_CHECKING:
    from rosnet_tui.core.wizard.session import WizardSession

SIZES = ((80, 24), (120, 40))
DEFAULT_OUT = Path(__file__).resolve().parent.parent / "screenshots"


def demo_settings() -> Settings:
    s = Settings()
    s.this = ThisComponent(name="turtlebot", role="master", connection="telecom",
                           profile="remote", local_ip="10.10.10.1", interface="wlan0")
    s.peers = [Peer(name="sami", local_ip="192.168.1.10", public_ip="198.51.100.2",
                    ssh_user="ops")]
    s.ros.master = "turtlebot"
    return s


def demo_net() -> LocalNet:
    return LocalNet("wlan0", "10.10.10.1", "10.10.10.254", "02:00:00:00:0a:01", "255.255.255.0")


# What the router step shows after a round on a modem that does not forward: Table 1's
# "listener up, checker says Closed".
DEMO_RESULTS = [
    CheckResult("router.local_ip", "router", Status.PASS,
                "10.10.10.1 on wlan0, gateway 10.10.10.254: the address the modem forwards to",
                ["interface wlan0: 10.10.10.1/24", "default route via 10.10.10.254"], 0.01, 3.0,
                {"local_ip": "10.10.10.1", "interface": "wlan0", "gateway": "10.10.10.254",
                 "expected_ip": "10.10.10.1", "differs": False}),
    CheckResult("router.port_free", "router", Status.PASS, "port 12345 is free",
                ["no process listens on TCP 12345"], 0.02, 3.0,
                {"port": 12345, "in_use": False, "process": None, "pid": None}),
    CheckResult("router.listener", "router", Status.PASS, "our listener is up on port 12345",
                ["listening on 0.0.0.0:12345"], 0.01, 3.0, {"port": 12345, "listening": True}),
    CheckResult("router.port_open", "router", Status.FAIL,
                "203.0.113.2:12345 is Closed from outside while our listener runs",
                ["GET http://probe.example/port/12345 -> reachable: false",
                 "GET http://probe.example/port/40211 -> reachable: false"], 2.41, 9.0,
                {"ports": [{"port": 12345, "reachable": False, "listener": True, "via": "echoip"},
                           {"port": 40211, "reachable": False, "listener": True, "via": "echoip"}],
                 "test_port": 12345, "test_port_open": False, "public_ip": "203.0.113.2"}),
]


def _session(tmpdir: Path, settings: Settings) -> WizardSession:
    """A session of the demo component, its files in *tmpdir*."""
    from rosnet_tui.core.wizard.session import WizardSession

    return WizardSession(settings, Paths(config_path=tmpdir / "config.toml",
                                         state_dir=tmpdir / "state"), detect_net=demo_net)


async def _shoot(out: Path, width: int, height: int) -> list[Path]:
    from rosnet_tui.ui.app import RosnetApp

    written: list[Path] = []
    with tempfile.TemporaryDirectory() as tmp:
        tmpdir = Path(tmp)
        app = RosnetApp(_session(tmpdir, demo_settings()))
        async with app.run_test(size=(width, height)) as pilot:
            await pilot.pause()
            for step in STEPS:
                if step.id == "router":
                    for r in DEMO_RESULTS:
                        app.session.set_check_state(r.id, r.status.value, r)
                await pilot.press(str(step.number))
                await pilot.pause()
                if step.id == "router":
                    await pilot.press("end", "e")  # the failed check, and its evidence
                    await pilot.pause()
                path = out / f"step-{step.number}-{step.id}-{width}x{height}.svg"
                app.save_screenshot(filename=path.name, path=str(out))
                written.append(path)
            await pilot.press("a")  # the advisor on the router step's results
            await pilot.pause()
            path = out / f"advisor-{width}x{height}.svg"
            app.save_screenshot(filename=path.name, path=str(out))
            written.append(path)
            await pilot.press("escape")
            await pilot.pause()
            await pilot.press("s")
            await pilot.pause()
            path = out / f"setup-{width}x{height}.svg"
            app.save_screenshot(filename=path.name, path=str(out))
            written.append(path)
    return written


def demo_settings_ros2() -> Settings:
    """The same scene on ROS 2 over rmw_zenoh: the robot's router is the hub, TCP 7447."""
    s = demo_settings()
    s.ros.version = 2
    return s


_R2 = "the master's Zenoh router"
DEMO_RESULTS_ROS2 = [
    CheckResult("ros2.env", "ros", Status.PASS,
                "rmw_zenoh_cpp, domain 0, jazzy, a router on this component",
                ["RMW_IMPLEMENTATION: environment rmw_zenoh_cpp, ~/.bashrc rmw_zenoh_cpp",
                 "sami: ROS_DISTRO=jazzy, RMW_IMPLEMENTATION=rmw_zenoh_cpp"], 0.5, 3.0,
                {"rmw": "rmw_zenoh_cpp", "bashrc_rmw": "rmw_zenoh_cpp", "rmw_ok": True,
                 "dds": False, "domain_ok": True, "distro": "jazzy"}),
    CheckResult("ros2.router", "ros", Status.PASS,
                f"{_R2} (v1.10.2) answers at tcp/turtlebot:7447 (10.10.10.1)",
                ["TCP 7447 listened on here: 0.0.0.0"], 0.1, 3.0,
                {"role": "master", "endpoint": "tcp/turtlebot:7447", "reachable": True,
                 "router_version": "v1.10.2", "listening": ["0.0.0.0"]}),
    CheckResult("ros2.graph", "ros", Status.PASS,
                "3 node(s) on 2 component(s) seen; probe nodes seen both ways (from here and "
                "sami)", ["nodes seen from here: turtlebot: /camera, /base; sami: /teleop"],
                0.8, 6.0, {"missing": [], "mixed_hashes": False}),
    CheckResult("ros2.pubsub_out", "ros", Status.PASS,
                "here -> sami: a message in rmw_zenoh's format went through the routers",
                [], 0.7, 12.0, {"peer": "sami", "ok": True}),
    CheckResult("ros2.pubsub_in", "ros", Status.PASS,
                "sami -> here: a message in rmw_zenoh's format went through the routers",
                [], 0.7, 12.0, {"peer": "sami", "ok": True}),
    CheckResult("ros2.link", "ros", Status.PASS,
                "to sami: round trip 38 ms (spread 6 ms), up 4.1 Mbit/s, down 18.6 Mbit/s, "
                "1 MB whole both ways", [], 9.2, 18.0,
                {"peers": {"sami": {"rtt_ms": 38.0, "rtt_spread_ms": 6.0, "out_bps": 4_100_000,
                                    "in_bps": 18_600_000, "largest_out": 1 << 20,
                                    "largest_in": 1 << 20, "tried_out": 1 << 20,
                                    "tried_in": 1 << 20}}, "need_bps": 0}),
    CheckResult("router.upnp", "router", Status.WARN,
                "TCP 7447 is not forwarded; the modem offers forwarding (UPnP IGD): `rosnet-tui "
                "router map` asks it",
                ["the modem 10.10.10.254 (home gateway) speaks UPnP IGD and NAT-PMP; this machine "
                 "is 10.10.10.1 towards it", "the modem's external address: 203.0.113.2"],
                0.3, 4.5,
                {"protocol": "upnp", "protocols": ["upnp", "natpmp"], "gateway": "10.10.10.254",
                 "external_ip": "203.0.113.2", "wan": "public", "cgnat": False, "needed": [7447],
                 "present": [], "missing": [7447], "conflicts": [], "forwards": [],
                 "can_list": True, "range_needed": False, "tried": []}),
]


async def _shoot_ros2(out: Path, width: int, height: int) -> list[Path]:
    """The ROS 2 path: the router step (one port, the card) and the ROS step, checks passed,
    then the set-up."""
    from rosnet_tui.ui.app import RosnetApp

    written: list[Path] = []
    with tempfile.TemporaryDirectory() as tmp:
        tmpdir = Path(tmp)
        app = RosnetApp(_session(tmpdir, demo_settings_ros2()))
        async with app.run_test(size=(width, height)) as pilot:
            await pilot.pause()
            for r in DEMO_RESULTS_ROS2:
                app.session.set_check_state(r.id, r.status.value, r)
            for number, step in ((2, "router"), (4, "ros")):
                await pilot.press(str(number))
                await pilot.pause()
                path = out / f"ros2-step-{number}-{step}-{width}x{height}.svg"
                app.save_screenshot(filename=path.name, path=str(out))
                written.append(path)
            await pilot.press("s")  # the set-up: the ROS version and only its fields
            await pilot.pause()
            path = out / f"ros2-setup-{width}x{height}.svg"
            app.save_screenshot(filename=path.name, path=str(out))
            written.append(path)
    return written


def generate(out: Path = DEFAULT_OUT) -> list[Path]:
    """Write every screenshot into *out*; return the paths."""
    out.mkdir(parents=True, exist_ok=True)
    os.environ.pop("NO_COLOR", None)
    paths: list[Path] = []
    for width, height in SIZES:
        paths += asyncio.run(_shoot(out, width, height))
        paths += asyncio.run(_shoot_ros2(out, width, height))
    return paths


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m rosnet_tui.screenshots",
                                     description="Regenerate the SVG screenshots from the real app.")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="folder (default: %(default)s)")
    args = parser.parse_args(argv)
    for p in generate(args.out):
        print(p)
    return 0


if __name__ == "__main__":
    sys.exit(main())
