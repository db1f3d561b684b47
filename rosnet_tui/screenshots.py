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

from rosnet_tui.core.netinfo import LocalNet
from rosnet_tui.core.results import CheckResult, Status
from rosnet_tui.core.settings import Peer, Settings, ThisComponent
from rosnet_tui.core.steps import STEPS

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


async def _shoot(out: Path, width: int, height: int) -> list[Path]:
    from rosnet_tui.ui.app import AppDeps, RosnetApp

    written: list[Path] = []
    with tempfile.TemporaryDirectory() as tmp:
        tmpdir = Path(tmp)
        deps = AppDeps(config_path=tmpdir / "config.toml", settings=demo_settings(),
                       state_dir=tmpdir / "state", detect_net=demo_net)
        app = RosnetApp(deps)
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


def generate(out: Path = DEFAULT_OUT) -> list[Path]:
    """Write every screenshot into *out*; return the paths."""
    out.mkdir(parents=True, exist_ok=True)
    os.environ.pop("NO_COLOR", None)
    paths: list[Path] = []
    for width, height in SIZES:
        paths += asyncio.run(_shoot(out, width, height))
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
