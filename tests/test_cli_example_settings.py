"""The example settings of docs/SETTINGS.md, without the optional local_ip, work with every
command that reads settings (issue 14), and `--yes` answers every question a command would ask.

Nothing leaves this machine: the example's web services are pointed at a closed port on
127.0.0.1, the hosts file and ~/.bashrc are files in a temporary folder.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from rosnet_tui.core.net.netinfo import detect_local_net
from rosnet_tui.core.saved.settings import load_settings

REPO = Path(__file__).resolve().parent.parent


def readme_example() -> str:
    """The settings example of docs/SETTINGS.md ("The settings file"), as documented."""
    text = (REPO / "docs" / "SETTINGS.md").read_text(encoding="utf-8")
    section = text.split("# The settings file", 1)[1]
    return re.search(r"```toml\n(.*?)```", section, re.S).group(1)


@pytest.fixture
def home(tmp_path):
    net = detect_local_net()
    if not net.local_ip:
        pytest.skip("this machine has no LAN address to fill in")
    cfg_text = readme_example()
    assert 'local_ip = "10.10.10.1"' in cfg_text
    cfg_text = re.sub(r'(?m)^local_ip = "10\.10\.10\.1".*\n', "", cfg_text, count=1)
    cfg_text = cfg_text.replace("https://ifconfig.co/ip", "http://127.0.0.1:9/ip")
    cfg_text = cfg_text.replace('"https://ifconfig.co"', '"http://127.0.0.1:9"')
    cfg_text = cfg_text.replace("/home/ops/Sync/rosnet", str(tmp_path / "sync"))
    assert "ifconfig.co" not in cfg_text
    h = tmp_path / "home"
    (h / ".config" / "rosnet-tui").mkdir(parents=True)
    cfg = h / ".config" / "rosnet-tui" / "config.toml"
    cfg.write_text(cfg_text)
    assert load_settings(cfg).this.local_ip == ""       # the documented file, local_ip left out
    (tmp_path / "hosts").write_text("127.0.0.1\tlocalhost\n")
    (h / ".bashrc").write_text("# bashrc\nexport ROS_IP=10.10.10.1\n")
    env = {k: v for k, v in os.environ.items() if not k.startswith(("ROS_", "XDG_"))}
    env.update(HOME=str(h), PYTHONPATH=str(REPO), PYTHONUNBUFFERED="1")

    class Home:
        pass

    b = Home()
    b.dir, b.cfg, b.env, b.ip = h, cfg, env, net.local_ip
    b.hosts, b.bashrc, b.state = tmp_path / "hosts", h / ".bashrc", tmp_path / "state"
    return b


def run(home, *args: str, input: str | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "rosnet_tui", *args], capture_output=True,
                          text=True, timeout=60, cwd=REPO, env=home.env, input=input,
                          stdin=None if input is not None else subprocess.DEVNULL)


def test_hosts_commands_fill_the_local_ip_from_this_machine(home):
    out = run(home, "hosts", "show", "--file", str(home.hosts))
    assert out.returncode == 0, out.stderr
    assert f"{home.ip:<15} turtlebot" in out.stdout
    out = run(home, "hosts", "apply", "--dry-run", "--file", str(home.hosts))
    assert out.returncode == 0, out.stderr
    assert "Dry run" in out.stdout and home.hosts.read_text() == "127.0.0.1\tlocalhost\n"
    out = run(home, "hosts", "apply", "--yes", "--no-checks", "--file", str(home.hosts),
              "--state-dir", str(home.state))
    assert out.returncode == 0, out.stdout + out.stderr
    written = home.hosts.read_text()
    assert re.search(rf"(?m)^{re.escape(home.ip)}\s+turtlebot\b", written), written
    assert re.search(r"(?m)^198\.51\.100\.2\s+sami\b", written), written
    # switching the profile saves it, and only it: the detected address stays out of the file
    out = run(home, "hosts", "use", "office", "--yes", "--no-checks", "--file", str(home.hosts),
              "--state-dir", str(home.state))
    assert out.returncode == 0, out.stdout + out.stderr
    saved = load_settings(home.cfg)
    assert saved.this.profile == "office" and saved.this.local_ip == ""
    assert re.search(r"(?m)^192\.168\.1\.10\s+sami\b", home.hosts.read_text())
    for _ in range(2):
        assert run(home, "undo", "--yes", "--no-checks", "--state-dir",
                   str(home.state)).returncode == 0
    assert home.hosts.read_text() == "127.0.0.1\tlocalhost\n"


def test_ros_commands_and_yes_comments_out_ros_ip(home):
    out = run(home, "ros", "apply", "--yes", "--no-checks", "--file", str(home.bashrc),
              "--state-dir", str(home.state))
    assert out.returncode == 0, out.stdout + out.stderr
    text = home.bashrc.read_text()
    assert "export ROS_MASTER_URI=http://turtlebot:11311" in text
    # --yes is yes to the question the command asks on a terminal: the ROS_IP line goes
    assert "# rosnet-tui: export ROS_IP=10.10.10.1" in text
    assert not re.search(r"(?m)^export ROS_IP=", text)
    out = run(home, "ros", "export")
    assert out.returncode == 0 and "export ROS_MASTER_URI=http://turtlebot:11311" in out.stdout
    assert run(home, "undo", "--yes", "--no-checks", "--state-dir",
               str(home.state)).returncode == 0
    assert home.bashrc.read_text() == "# bashrc\nexport ROS_IP=10.10.10.1\n"


def test_check_and_report_accept_the_example(home):
    out = run(home, "check", "--step", "isp", "--json", "-q", "--no-upnp", "--timeout", "1")
    assert out.returncode == 1, out.stderr         # checks fail (nothing answers), not refused
    checks = json.loads(out.stdout)["checks"]
    assert {c["id"] for c in checks} == {"isp.internet", "isp.public_ip", "isp.cgnat"}
    rep = run(home, "report", "--format", "json", "--from-json", "-", input=out.stdout)
    assert rep.returncode == 1, rep.stderr
    assert json.loads(rep.stdout)["settings"]["this"]["name"] == "turtlebot"


def test_hosts_apply_yes_also_fixes_conflicting_lines(home):
    home.hosts.write_text("127.0.0.1\tlocalhost\n127.0.1.1\tturtlebot\n")
    out = run(home, "hosts", "apply", "--yes", "--no-checks", "--file", str(home.hosts),
              "--state-dir", str(home.state))
    assert out.returncode == 0, out.stdout + out.stderr
    assert "# rosnet-tui: 127.0.1.1\tturtlebot" in home.hosts.read_text()
    # the exact replay of a preview (the privileged re-run) follows its flags, not --yes
    home.hosts.write_text("127.0.0.1\tlocalhost\n127.0.1.1\tturtlebot\n")
    out = run(home, "hosts", "apply", "--yes", "--no-checks", "--file", str(home.hosts),
              "--state-dir", str(home.state), "--expect-digest", "0" * 64)
    assert out.returncode == 1 and "changed since the preview" in out.stderr
    assert home.hosts.read_text() == "127.0.0.1\tlocalhost\n127.0.1.1\tturtlebot\n"
