"""`rosnet-tui check` as a user runs it: a subprocess, loopback services, exit codes, JSON shape.

Only the isp and router steps run here (on loopback, UPnP off): the linux step resolves names
with the system resolver, which outside the lab could ask a real DNS server. The lab tests run
every step.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from rosnet_tui.core.checks import checks_for
from tests.builders import free_port, loopback_master_config
from tests.plugins.web import ProbeThread, WebServer

ROUTER_IDS = [s.id for s in checks_for(["router"]) if s.ros != 2]   # ROS 1 settings here


def run(tmp_path, *args: str) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if not k.lower().endswith("_proxy")}
    env.update(XDG_STATE_HOME=str(tmp_path / "state"), XDG_CONFIG_HOME=str(tmp_path / "cfg"),
               NO_COLOR="1", COLUMNS="200")
    return subprocess.run([sys.executable, "-m", "rosnet_tui", "check", *args],
                          capture_output=True, text=True, timeout=60, env=env,
                          stdin=subprocess.DEVNULL)


def write_config(tmp_path, probe_url: str, ip_url: str, **extra) -> str:
    return str(loopback_master_config(tmp_path, ip_url, probe_url,
                                      ros_port=extra.get("ros_port")))


@pytest.fixture(scope="module")
def services():
    probe, web = ProbeThread(), WebServer()
    web.routes["/ip"] = (200, "203.0.113.9\n")
    web.routes["/"] = (200, "203.0.113.9\n")
    yield probe, web
    probe.close()
    web.close()


def test_json_lists_the_checks_in_registry_order_with_the_contract_keys(services, tmp_path):
    probe, web = services
    cfg = write_config(tmp_path, probe.url, web.url("/ip"))
    out = run(tmp_path, "--step", "router", "--json", "--no-upnp", "--config", cfg)
    assert out.returncode == 0, (out.stdout, out.stderr)
    doc = json.loads(out.stdout)
    assert list(doc) == ["checks"]
    assert [c["id"] for c in doc["checks"]] == ROUTER_IDS
    for c in doc["checks"]:
        assert {"id", "step", "status", "summary", "evidence", "duration_s", "timeout_s",
                "advice"} <= set(c)
        assert c["status"] == "pass", c
        assert c["step"] == "router" and isinstance(c["advice"], list)
    assert doc["checks"][0]["timeout_s"] == 2.0
    assert next(c for c in doc["checks"] if c["id"] == "router.port_open")["timeout_s"] == 6.0
    # progress went to stderr, one line per check, as they landed
    lines = [ln for ln in out.stderr.splitlines() if ln.startswith("[")]
    assert len(lines) == len(ROUTER_IDS) and lines[-1].startswith(f"[{len(ROUTER_IDS)}/")


def test_table_output_and_exit_1_when_a_check_fails(services, tmp_path):
    probe, web = services
    dead = f"http://127.0.0.1:{free_port()}"
    cfg = write_config(tmp_path, dead, dead + "/ip")
    out = run(tmp_path, "--step", "isp", "--no-upnp", "-q", "--config", cfg, "--timeout", "1")
    assert out.returncode == 1, out.stdout
    assert "FAIL" in out.stdout and "isp.internet" in out.stdout and "isp.public_ip" in out.stdout
    assert "refused" in out.stdout  # evidence of failed rows is shown
    assert out.stderr == ""


def test_steps_repeat_and_timeout_override(services, tmp_path):
    probe, web = services
    cfg = write_config(tmp_path, probe.url, web.url("/ip"))
    out = run(tmp_path, "--step", "isp", "--step", "router", "--json", "--no-upnp", "-q",
              "--timeout", "1.5", "--config", cfg)
    doc = json.loads(out.stdout)
    ids = [c["id"] for c in doc["checks"]]
    assert ids == [s.id for s in checks_for(["isp", "router"]) if s.ros != 2]
    assert doc["checks"][0]["timeout_s"] == 1.5
    pub = next(c for c in doc["checks"] if c["id"] == "isp.public_ip")
    assert pub["status"] == "pass" and pub["data"]["public_ip"] == "203.0.113.9"
    assert (tmp_path / "state" / "rosnet-tui" / "public_ip.json").exists()


def test_missing_settings_file_is_exit_2(tmp_path):
    out = run(tmp_path, "--config", str(tmp_path / "nope.toml"))
    assert out.returncode == 2 and "no settings file" in out.stderr and "nope.toml" in out.stderr


def test_malformed_settings_name_the_line_and_key(tmp_path):
    cfg = tmp_path / "bad.toml"
    cfg.write_text('[this]\nname = "turtlebot"\nrole = "boss"\n')
    out = run(tmp_path, "--config", str(cfg))
    assert out.returncode == 2
    assert "line 3" in out.stderr and "this.role" in out.stderr and "Traceback" not in out.stderr


def test_incomplete_settings_name_the_key(tmp_path):
    cfg = tmp_path / "inc.toml"
    cfg.write_text('[this]\nrole = "member"\n')
    out = run(tmp_path, "--config", str(cfg))
    assert out.returncode == 2 and "this.name" in out.stderr and "ros.master" in out.stderr


@pytest.mark.parametrize("args", [["--step", "dns"], ["--timeout", "0"], ["--timeout", "x"]])
def test_usage_errors_are_exit_2(tmp_path, args):
    out = run(tmp_path, *args)
    assert out.returncode == 2 and "Traceback" not in out.stderr
