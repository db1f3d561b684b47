"""`rosnet-tui report`: from saved `check --json` results and live, in Markdown and JSON."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from rosnet_tui.core.results import Status
from rosnet_tui.core.saved.settings import render_settings
from rosnet_tui.core.wizard import report
from tests.advisor_support import chat, unreachable
from tests.builders import free_port, healthy_laptop, laptop_settings, put, t1

ROOT = Path(__file__).resolve().parents[1]


def rosnet(*args: str, env: dict | None = None, input: str | None = None,
           timeout: float = 60) -> subprocess.CompletedProcess:
    full_env = {k: v for k, v in os.environ.items() if not k.startswith("ROS_")}
    full_env.update(env or {})
    return subprocess.run([sys.executable, "-m", "rosnet_tui", *args], capture_output=True,
                          text=True, cwd=ROOT, timeout=timeout, env=full_env, input=input)


@pytest.fixture
def saved(tmp_path):
    """A `check --json` file (with data) of a broken network, and its settings file."""
    results, settings = unreachable()
    put(results, "ros.env", "warn", ros_ip="192.168.1.10")
    chk = tmp_path / "check.json"
    chk.write_text(json.dumps({"checks": [r.to_json() for r in results.values()]}))
    cfg = tmp_path / "config.toml"
    cfg.write_text(render_settings(settings))
    return chk, cfg


def test_markdown_from_json(saved):
    chk, cfg = saved
    p = rosnet("report", "--from-json", str(chk), "--config", str(cfg))
    assert p.returncode == 1, p.stderr          # some checks failed
    md = p.stdout
    assert md.startswith("# rosnet-tui report: sami\n")
    assert "ROS member, home connection, remote network profile" in md
    assert f"results saved in {chk}" in md
    assert "Verdict: 4 failed, 1 warned, 13 passed" in md
    # findings, failures first, with their actions and where to go
    assert md.index("[FAIL]") < md.index("[WARN]") < md.index("[SECURITY]") < md.index("[INFO]")
    assert "1. [FAIL] Nothing answers at 203.0.113.2, the address sami uses for turtlebot" in md
    assert "forwards TCP 22 and 1024-65000 to 10.10.10.1" in md
    assert "Unset ROS_IP on sami" in md
    assert "Go to: step 2 (Router/modem)" in md
    # every check, by step, with its evidence and a pointer to its findings
    for step in ("Step 1 (ISP)", "Step 2 (Router/modem)", "Step 3 (Linux)", "Step 4 (ROS)"):
        assert f"### {step}" in md
    assert "- FAIL linux.ssh:" in md and "evidence of linux.ssh" in md
    assert "-> see finding 1 (linux.peer.unreachable)" in md
    # settings as TOML, and no line wider than a terminal can show comfortably (evidence aside)
    assert '[[peer]]\nname = "turtlebot"' in md and 'ssh_user = "root"' in md
    # (the line naming the results file carries pytest's temporary path, longer under xdist)
    prose = [ln for ln in md.splitlines() if not ln.startswith("  evidence") and str(chk) not in ln]
    assert max(len(ln) for ln in prose) <= 100


def test_json_from_json_and_back(saved, tmp_path):
    chk, cfg = saved
    out = tmp_path / "report.json"
    p = rosnet("report", "--format", "json", "-o", str(out), "--from-json", str(chk),
               "--config", str(cfg))
    assert p.returncode == 1 and p.stdout == ""
    assert f"report written to {out}" in p.stderr
    doc = json.loads(out.read_text())
    assert set(doc) == {"report", "summary", "findings", "checks", "settings", "environment"}
    assert doc["report"]["component"] == "sami" and doc["report"]["version"]
    assert doc["summary"] == {"pass": 13, "warn": 1, "fail": 4, "skip": 0}
    assert doc["findings"][0]["rule"] == "linux.peer.unreachable"
    assert doc["findings"][0]["severity"] == "fail"
    by_id = {c["id"]: c for c in doc["checks"]}
    assert [a["rule"] for a in by_id["linux.ssh"]["advice"]] == ["linux.peer.unreachable"]
    assert set(by_id["linux.ssh"]["advice"][0]) == {"rule", "meaning", "actions", "goto_step"}
    assert by_id["isp.internet"]["advice"] == []
    assert doc["settings"]["peer"][0]["ssh_user"] == "root"
    # a JSON report is itself an input: same findings, same settings, no --config needed
    p2 = rosnet("report", "--format", "json", "--from-json", str(out),
                env={"XDG_CONFIG_HOME": str(tmp_path / "none")})
    doc2 = json.loads(p2.stdout)
    assert [f["rule"] for f in doc2["findings"]] == [f["rule"] for f in doc["findings"]]
    assert doc2["settings"] == doc["settings"]


def test_exit_0_when_nothing_failed(tmp_path):
    chk = tmp_path / "ok.json"
    chk.write_text(json.dumps({"checks": [r.to_json() for r in healthy_laptop().values()]}))
    cfg = tmp_path / "c.toml"
    cfg.write_text(render_settings(laptop_settings()))
    p = rosnet("report", "--from-json", str(chk), "--config", str(cfg))
    assert p.returncode == 0, p.stderr
    assert "### Causes of failures" not in p.stdout
    assert "[SECURITY]" in p.stdout and "PasswordAuthentication no" in p.stdout


def test_step_filter_and_stdin(saved):
    chk, cfg = saved
    p = rosnet("report", "--format", "json", "--step", "linux", "--config", str(cfg),
               "--from-json", "-", input=chk.read_text())
    doc = json.loads(p.stdout)
    assert {c["step"] for c in doc["checks"]} == {"linux"}
    assert doc["report"]["steps"] == ["linux"]
    assert "standard input" in doc["report"]["source"]


def test_check_json_without_data_still_reports(tmp_path):
    """Older or trimmed `check --json` output (no data keys): results, catch-all advice."""
    results, _ = chat(True, False)()
    entries = []
    for r in results.values():
        e = r.to_json()
        del e["data"]
        entries.append(e)
    chk = tmp_path / "c.json"
    chk.write_text(json.dumps({"checks": entries}))
    cfg = tmp_path / "c.toml"
    cfg.write_text(render_settings(laptop_settings()))
    p = rosnet("report", "--format", "json", "--from-json", str(chk), "--config", str(cfg))
    doc = json.loads(p.stdout)
    assert p.returncode == 1
    assert [f["rule"] for f in doc["findings"] if f["severity"] == "fail"] == \
        ["check.unexplained"]


@pytest.mark.parametrize("content, needle", [
    ("not json", "is not JSON"),
    ('{"results": []}', 'expected {"checks": [...]}'),
    ('{"checks": [{"id": "isp.internet", "status": "great"}]}', "unknown status 'great'"),
    ('{"checks": [{"status": "pass"}]}', "needs at least an \"id\""),
])
def test_bad_input_is_a_usage_error(tmp_path, content, needle):
    chk = tmp_path / "bad.json"
    chk.write_text(content)
    p = rosnet("report", "--from-json", str(chk), "--config", str(tmp_path / "none.toml"))
    assert p.returncode == 2
    assert needle in p.stderr and "Traceback" not in p.stderr


def test_missing_file_bad_settings_and_bad_arguments(tmp_path):
    p = rosnet("report", "--from-json", str(tmp_path / "nope.json"))
    assert p.returncode == 2 and "cannot read" in p.stderr
    bad = tmp_path / "bad.toml"
    bad.write_text("[this]\nname = 'has space'\n")
    p = rosnet("report", "--config", str(bad))
    assert p.returncode == 2 and "line 2" in p.stderr and "Traceback" not in p.stderr
    p = rosnet("report", "--config", str(tmp_path / "absent.toml"))
    assert p.returncode == 2 and "no settings file" in p.stderr
    p = rosnet("report", "--format", "pdf")
    assert p.returncode == 2
    p = rosnet("report", "--step", "moon")
    assert p.returncode == 2


def test_no_secrets_in_settings_or_environment():
    scrubbed = report._scrub({"sync": {"store": "dns", "tsig_key_file": "/etc/k.key",
                                       "password": "x", "zone": "robots.example."},
                              "this": {"name": "sami", "api_token": "t"}})
    assert scrubbed == {"sync": {"store": "dns", "zone": "robots.example."},
                        "this": {"name": "sami"}}
    env = report.ros_environment({"ROS_MASTER_URI": "http://turtlebot:11311", "HOME": "/root",
                                  "AWS_SECRET_ACCESS_KEY": "s", "ROS_IP": "192.168.1.10"})
    assert env == {"ROS_IP": "192.168.1.10", "ROS_MASTER_URI": "http://turtlebot:11311"}


def test_build_report_counts_and_findings():
    r = t1(True, False)
    doc = report.build_report(r.values(), laptop_settings(), source="test")
    assert doc["summary"]["fail"] == 1          # the listener passes, the port test fails
    assert doc["findings"][0]["rule"].startswith("table1.listener_up_closed.")
    assert [f["order"] for f in doc["findings"][:3]] == [0, 1, 2]
    md = report.render_markdown(doc)
    assert md.count("[FAIL]") == 3


def test_live_report_runs_the_checks(tmp_path):
    """Live: the Router step's checks against loopback only (probes point at a closed port)."""
    closed = free_port()
    test_port = free_port()
    s = laptop_settings(local_ip="127.0.0.1")
    s.peers[0].ssh_user = ""
    s.probe.port = test_port
    s.probe.public_ip_urls = [f"http://127.0.0.1:{closed}/ip"]
    s.probe.port_check_url = f"http://127.0.0.1:{closed}"
    s.checks.timeout_s = 1.0
    cfg = tmp_path / "c.toml"
    cfg.write_text(render_settings(s))
    p = rosnet("report", "--format", "json", "--step", "router", "--config", str(cfg),
               env={"ROS_MASTER_URI": "http://turtlebot:11311", "MY_SECRET": "hunter2",
                    "XDG_STATE_HOME": str(tmp_path / "state")}, timeout=120)
    assert p.returncode in (0, 1), p.stderr
    doc = json.loads(p.stdout)
    assert doc["report"]["source"] == "checks run live on this machine"
    ids = [c["id"] for c in doc["checks"]]
    assert ids == ["router.local_ip", "router.port_free", "router.listener", "router.port_open"]
    assert all(Status(c["status"]) for c in doc["checks"])
    assert doc["environment"] == {"ROS_MASTER_URI": "http://turtlebot:11311"}
    assert "hunter2" not in p.stdout
    # the port checker cannot be reached: the advisor says so instead of reading Table 1
    port_open = next(c for c in doc["checks"] if c["id"] == "router.port_open")
    if port_open["status"] == "fail":
        assert port_open["advice"], port_open


def test_live_report_refuses_incomplete_settings(tmp_path):
    cfg = tmp_path / "c.toml"
    cfg.write_text('[this]\nname = "sami"\nrole = "member"\n')   # a member without a master
    p = rosnet("report", "--config", str(cfg))
    assert p.returncode == 2
    assert "not complete" in p.stderr and "ros.master" in p.stderr
