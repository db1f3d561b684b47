"""Issue 34 at a lab host's gateway: a hostile modem of the tests' own
(tests/lab/modem_scripts/hostile_modem.py) in the robot modem's namespace answers SSDP and SOAP
badly; `router mappings --json` and `check --step router --json` on the robot end, print valid,
small JSON, never a traceback, and no control character reaches the terminal."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests.lab import ADDR
from tests.lab.ros2 import Ros2World

pytestmark = pytest.mark.lab

SCRIPT = Path(__file__).resolve().parent / "lab" / "modem_scripts" / "hostile_modem.py"
CONTROLS = [chr(c) for c in (*range(0, 9), *range(11, 32), *range(0x7f, 0xa0))]


class HostileModem:
    def __init__(self, lab, mode: str) -> None:
        self.lab, self.mode = lab, mode
        self.proc: subprocess.Popen | None = None

    def __enter__(self) -> HostileModem:
        self.proc = self.lab.spawn("robot_modem", [sys.executable, str(SCRIPT), self.mode,
                                                   ADDR.ROBOT_GW])
        assert self.lab.wait_listening("robot_modem", 5000, "tcp", timeout=10, proc=self.proc)
        assert self.lab.wait_listening("robot_modem", 1900, "udp", timeout=10, proc=self.proc)
        return self

    def __exit__(self, *exc) -> None:
        if self.proc is not None:
            self.lab.kill(self.proc, grace=0.5)


@pytest.fixture(scope="module")
def world(lab):
    with Ros2World(lab) as w:
        yield w


def rosnet(lab, w: Ros2World, *args: str, timeout: float = 60):
    return lab.rosnet("robot", *args, "--config", str(w.config_path("robot")), env=w.env("robot"),
                      timeout=timeout)


def assert_sound(p: subprocess.CompletedProcess, *, limit: int = 16_000, json_out: bool = True
                 ) -> dict:
    assert "Traceback" not in p.stderr, p.stderr[-2000:]
    assert not any(c in p.stdout + p.stderr for c in CONTROLS if c != "\n"), \
        repr((p.stdout + p.stderr)[-500:])
    assert len(p.stdout) < limit, len(p.stdout)
    assert len(p.stderr) < 8_000, len(p.stderr)
    return json.loads(p.stdout) if json_out else {}


@pytest.mark.parametrize("mode", ["chunk", "digits", "snowman", "c1", "flood"])
def test_router_mappings_and_the_router_checks_hold_against_a_hostile_modem(lab, world, mode):
    with HostileModem(lab, mode):
        p = rosnet(lab, world, "router", "mappings", "--json", timeout=30)
        assert p.returncode in (0, 1), (p.returncode, p.stderr[-2000:])
        assert_sound(p)
        p = rosnet(lab, world, "router", "mappings", timeout=30)    # as a person reads it
        assert p.returncode in (0, 1), (p.returncode, p.stderr[-2000:])
        assert_sound(p, json_out=False)
        p = rosnet(lab, world, "check", "--json", "--step", "router", timeout=60)
        checks = {c["id"]: c for c in assert_sound(p, limit=40_000)["checks"]}
        upnp = checks["router.upnp"]
        assert "unexpectedly" not in upnp["summary"], upnp
        assert len(json.dumps(upnp)) < 4_000, len(json.dumps(upnp))


@pytest.mark.parametrize("wan", ["0.0.0.0", "224.0.0.1", "127.0.0.1"])
def test_isp_cgnat_never_passes_on_a_modems_external_address_that_is_not_public(lab, world, wan):
    with HostileModem(lab, f"wan:{wan}"):
        p = rosnet(lab, world, "check", "--json", "--step", "isp", timeout=60)
        checks = {c["id"]: c for c in assert_sound(p, limit=40_000)["checks"]}
        cgnat = checks["isp.cgnat"]
        assert cgnat["status"] != "pass", cgnat
        assert "unexpectedly" not in cgnat["summary"], cgnat
