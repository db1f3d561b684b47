"""Issue 22 on the network lab, seen from the outsider (192.0.2.66: on the internet, no peer).

Today's plain setup (no [ros] security yet, or security = "none"): the defect is reproduced (the
outsider gets a Zenoh session and the graph on ROS 2, and getSystemState on ROS 1), and
security.outsider fails with its advice. The SSH audit works today: the lab's sshd offers
publickey only (passes); with PasswordAuthentication on, the finding names the fix.

The tests of the final default behaviour (mTLS from S1, the peers-only firewall from S3) are here
too; each skips, saying which part is missing, until that part is in this build.
"""

from __future__ import annotations

import importlib.util
import json
import sys
import time

import pytest

from tests.lab import outsider
from tests.lab.ros2 import Ros2World, explain
from tests.lab.topology import ADDR, ZENOH_PORT

pytestmark = pytest.mark.lab
TIMEOUT = 3.0

# Runs security.* in *host*'s namespace with [ros] security set (S1's setting: set by hand until
# this build has it), printing {id: result} as JSON.
_RUN = r"""
import json, sys
from dataclasses import replace
from rosnet_tui.core.checks import runner
from rosnet_tui.core.settings import load_settings
path, security, *ids = sys.argv[1:]
s = load_settings(__import__("pathlib").Path(path))
ros = replace(s.ros)
ros.security = security
s = replace(s, ros=ros)
out = {}
for r in runner.run_now(s, runner.select(ids=ids)):
    out[r.id] = {"id": r.id, "status": r.status.value, "summary": r.summary,
                 "evidence": r.evidence, "data": r.data, "duration_s": r.duration_s}
print("RESULTS " + json.dumps(out))
"""


def run_security(lab, host: str, config, security: str, *ids: str, env=None) -> dict:
    r = lab.run(host, [sys.executable, "-c", _RUN, str(config), security, *ids],
                env=env or lab.env(host), timeout=60)
    line = next((x for x in r.stdout.splitlines() if x.startswith("RESULTS ")), None)
    assert line, r.stderr[-3000:]
    return json.loads(line[len("RESULTS "):])


def has_mtls() -> bool:
    return any(importlib.util.find_spec(m) is not None
               for m in ("rosnet_tui.core.fleet_tls", "rosnet_tui.core.tls"))


def has_firewall() -> bool:
    return importlib.util.find_spec("rosnet_tui.core.firewall") is not None


def needs(present: bool, what: str) -> None:
    if not present:
        pytest.skip(f"{what} is not in this build yet (issue 22); this test is its acceptance")


# --------------------------------------------------------------------------- the outsider host
def test_the_outsider_is_on_the_internet_and_no_peer(lab):
    lab.reset()
    code, text = lab.http_get("outsider", f"{ADDR.PROBE_URL}/ip")
    assert code == 200 and text.strip() == ADDR.OUTSIDER_IP
    settings = lab.settings("robot")
    assert ADDR.OUTSIDER_IP not in {p.public_ip for p in settings.peers}
    # the robot's modem forwards 22 to the robot: the outsider reaches its sshd
    got = outsider.ssh_auth_none(lab, ADDR.ROBOT_PUBLIC)
    assert got.get("methods") == ["publickey"], got


# --------------------------------------------------------------------------- SSH audit
def _install_on_peers(lab) -> None:
    from tests.lab import readme_install

    for h in lab.COMPUTERS:
        readme_install.install(lab.home(h))


def test_ssh_audit_passes_when_sshd_offers_keys_only(lab):
    lab.reset()
    _install_on_peers(lab)
    t0 = time.monotonic()
    res = run_security(lab, "robot", lab.config_path("robot"), "firewall", "security.ssh_auth")
    took = time.monotonic() - t0
    c = res["security.ssh_auth"]
    print(f"security.ssh_auth on robot: {c['status']} in {c['duration_s']:.2f} s")
    assert c["status"] == "pass", c
    d = c["data"]
    assert d["from"] == ADDR.LAPTOP_NAME and d["target"] == ADDR.ROBOT_PUBLIC
    assert d["methods"] == ["publickey"] and d["root_methods"] == ["publickey"]
    assert not d["password"] and not d["root_password"]
    assert c["duration_s"] < 2 * TIMEOUT + 0.5, took


def test_ssh_audit_without_rosnet_tui_on_the_peer_says_so_and_never_uses_its_python3(lab):
    from tests.lab import readme_install

    lab.reset()
    _install_on_peers(lab)
    readme_install.uninstall(lab.home("laptop"))
    try:
        res = run_security(lab, "robot", lab.config_path("robot"), "firewall",
                           "security.ssh_auth")
        c = res["security.ssh_auth"]
        assert c["status"] == "warn", c
        assert "rosnet-tui is not installed on sami" in c["summary"], c
        assert c["duration_s"] < 2 * TIMEOUT + 0.5, c
    finally:
        readme_install.install(lab.home("laptop"))


def test_ssh_audit_names_password_login_with_the_fix(lab):
    lab.reset()
    _install_on_peers(lab)
    conf = lab._hostdir("robot") / "etc" / "sshd_config"
    before = conf.read_text()
    try:
        conf.write_text(before.replace("PasswordAuthentication no", "PasswordAuthentication yes"))
        lab._restart_sshd("robot", 22)
        assert outsider.ssh_auth_none(lab, ADDR.ROBOT_PUBLIC)["methods"] == ["publickey",
                                                                             "password"]
        res = run_security(lab, "robot", lab.config_path("robot"), "firewall",
                           "security.ssh_auth")
        c = res["security.ssh_auth"]
        assert c["status"] == "fail", c
        assert c["data"]["password"] and c["data"]["root_password"], c
        text = "\n".join(c["evidence"])
        for fix in ("ssh-copy-id", "PasswordAuthentication no", "KbdInteractiveAuthentication no",
                    "systemctl reload ssh"):
            assert fix in text, text
    finally:
        conf.write_text(before)
        lab._restart_sshd("robot", 22)


# --------------------------------------------------------------------------- ROS 1
def test_ros1_today_the_outsider_gets_the_graph_and_the_check_says_so(lab):
    lab.reset()
    _install_on_peers(lab)
    lab.start_roscore()
    try:
        got = outsider.get_system_state(lab, ADDR.ROBOT_PUBLIC)
        assert got["ok"], got                      # the defect: anyone reads the master
        for host in ("robot", "laptop"):            # every seat judges its own ports
            res = run_security(lab, host, lab.config_path(host), "none", "security.outsider")
            c = res["security.outsider"]
            print(f"security.outsider (ROS 1) on {host}: {c['status']} in "
                  f"{c['duration_s']:.2f} s")
            assert c["status"] == "fail", c
            assert c["data"]["cause"] == "security_off", c
            reach = c["data"]["outsider_reachable"]  # the master's port (master), a range port
            assert len(reach) == (2 if host == "robot" else 1) and all(reach.values()), c
            assert host != "robot" or reach["11311"] is True
            assert all(c["data"]["insider_reachable"].values()), c
            assert c["duration_s"] < 3 * TIMEOUT + 0.5
    finally:
        lab.stop_roscore()


def test_ros1_default_refuses_the_outsider_and_lets_the_peer_in(lab):
    needs(has_firewall(), "the peers-only firewall (S3: rosnet_tui.core.firewall)")
    lab.reset()
    _install_on_peers(lab)
    lab.start_roscore()
    try:
        r = lab.rosnet("robot", "firewall", "apply", "--yes", "--config",
                       str(lab.config_path("robot")), timeout=60)
        assert r.returncode == 0, r.stderr
        assert not outsider.get_system_state(lab, ADDR.ROBOT_PUBLIC, timeout=2)["ok"]
        res = run_security(lab, "robot", lab.config_path("robot"), "firewall",
                           "security.outsider")
        assert res["security.outsider"]["status"] == "pass", res
    finally:
        lab.rosnet("robot", "firewall", "undo", "--yes", "--config",
                   str(lab.config_path("robot")), timeout=60)
        lab.stop_roscore()


# --------------------------------------------------------------------------- ROS 2
@pytest.fixture(scope="module")
def world(lab):
    with Ros2World(lab) as w:
        yield w


def test_ros2_today_the_outsider_gets_a_session_and_the_check_says_so(world):
    lab = world.lab
    world.node("robot", "talker", name="talker")
    got = outsider.zenoh_session(lab, ADDR.ROBOT_PUBLIC, ZENOH_PORT)
    assert got["session"] and got["tokens"], got   # the defect: a stranger reads the graph
    assert got["published"] == 3
    for host in ("robot", "laptop"):                   # the master over SSH; a member itself
        res = run_security(lab, host, world.config_path(host), "none", "security.outsider",
                           env=world.env(host))
        c = res["security.outsider"]
        print(f"security.outsider (ROS 2) on {host}: {c['status']} in {c['duration_s']:.2f} s")
        assert c["status"] == "fail", explain(res)
        assert c["data"]["cause"] == "security_off", explain(res)
        assert c["data"]["attempts"]["plain"]["result"] == "accepted", explain(res)
        assert c["duration_s"] < 3 * TIMEOUT + 0.5, explain(res)


def test_ros2_default_mtls_refuses_the_outsider(world):
    needs(has_mtls(), "mutual TLS for ROS 2 (S1: rosnet_tui.core.fleet_tls)")
    lab = world.lab
    for host in ("robot", "laptop"):
        r = lab.rosnet(host, "ros", "apply", "--yes", "--config", str(world.config_path(host)),
                       env=world.env(host), timeout=60)
        assert r.returncode == 0, r.stderr
    world.start_router("robot")
    world.start_router("laptop")
    for tls in (False, True):
        got = outsider.zenoh_session(lab, ADDR.ROBOT_PUBLIC, ZENOH_PORT, tls=tls)
        assert not got["session"], got
    for host in ("robot", "laptop"):
        res = run_security(lab, host, world.config_path(host), "mtls", "security.outsider",
                           env=world.env(host))
        assert res["security.outsider"]["status"] == "pass", explain(res)


def test_the_fleet_has_the_outsider_too(fleet):
    """tests/lab/fleet.py inherits the outsider: on the internet, no peer, every site in reach."""
    code, text = fleet.http_get("outsider", f"{ADDR.PROBE_URL}/ip")
    assert code == 200 and text.strip() == ADDR.OUTSIDER_IP
    assert ADDR.OUTSIDER_IP not in {fleet.public_ip(h) for h in fleet.COMPUTERS}
    for host in fleet.COMPUTERS:
        got = outsider.ssh_auth_none(fleet, fleet.public_ip(host))
        assert got.get("methods") == ["publickey"], (host, got)
