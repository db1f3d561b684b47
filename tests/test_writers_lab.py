"""The writers on the network lab: from hosts files that know nothing of each other, `hosts apply`
and `ros apply` on robot and laptop make names resolve and the whole `check` pass; `undo` puts
every file back exactly. Inside the lab /etc/hosts is a bind mount (ip netns exec): the in-place path."""

from __future__ import annotations

import json

import pytest

from tests.lab import ADDR
from tests.lab.firewall import secured

pytestmark = pytest.mark.lab

COMPUTERS = ("robot", "laptop")
NAME = {"robot": ADDR.ROBOT_NAME, "laptop": ADDR.LAPTOP_NAME}
LOCAL = {"robot": ADDR.ROBOT_LOCAL, "laptop": ADDR.LAPTOP_LOCAL}
PUBLIC = {"robot": ADDR.ROBOT_PUBLIC, "laptop": ADDR.LAPTOP_PUBLIC}
OTHER = {"robot": "laptop", "laptop": "robot"}
# A stock hosts file: localhost only (CRLF and no final newline on purpose: they must survive).
STOCK_HOSTS = "127.0.0.1\tlocalhost\n::1\tlocalhost ip6-localhost ip6-loopback\r\n# stock"
STOCK_BASHRC = "# ~/.bashrc\ncase $- in *i*) ;; *) return;; esac\nalias ll='ls -l'\n"


def env(lab, host: str) -> dict[str, str]:
    """The host's environment, its state dir under its own HOME (no shared XDG dirs)."""
    return {k: v for k, v in lab.ros_env(host).items() if not k.startswith("XDG_")}


def rosnet(lab, host: str, *args: str):
    return lab.rosnet(host, *args, env=env(lab, host), timeout=90)


def resolve(lab, host: str, name: str) -> str:
    r = lab.run(host, ["getent", "ahostsv4", name], timeout=10)
    return r.stdout.split()[0] if r.returncode == 0 and r.stdout.split() else ""


@pytest.fixture
def stock(lab):
    """Both computers with stock files; the lab's own files come back afterwards."""
    lab.reset()
    files = {}
    for h in COMPUTERS:
        lab.write_hosts(h, STOCK_HOSTS)
        lab.bashrc_path(h).write_text(STOCK_BASHRC)
        files[h] = (lab.hosts_path(h).read_bytes(), lab.bashrc_path(h).read_bytes())
    try:
        yield files
    finally:
        lab.reset()


def test_apply_on_both_sides_makes_names_work_and_undo_restores_every_byte(lab, stock):
    for h in COMPUTERS:
        assert resolve(lab, h, NAME[OTHER[h]]) == ""  # nothing knows the peer yet

    for h in COMPUTERS:
        cfg = str(lab.config_path(h))
        r = rosnet(lab, h, "hosts", "apply", "--yes", "--config", cfg)
        assert r.returncode == 0, r.stdout + r.stderr
        assert "in place (the file is a mount point)" in r.stdout  # the bind-mount path
        r = rosnet(lab, h, "ros", "apply", "--yes", "--config", cfg,
                   "--file", str(lab.home(h) / ".bashrc"))
        assert r.returncode == 0, r.stdout + r.stderr

    for h in COMPUTERS:
        assert resolve(lab, h, NAME[h]) == LOCAL[h]                # own name -> local IP
        assert resolve(lab, h, NAME[OTHER[h]]) == PUBLIC[OTHER[h]]  # peer -> its public IP
        hosts = lab.hosts_path(h).read_bytes()
        assert hosts.endswith(stock[h][0])  # the stock lines, byte for byte
        sourced = lab.run(h, ["bash", "-ic", "echo $ROS_MASTER_URI"], timeout=10)
        assert sourced.stdout.strip().splitlines()[-1] == "http://turtlebot:11311"
        # a real connection by name, across both modems
        nc = lab.run(h, ["nc", "-z", "-w", "3", NAME[OTHER[h]], "22"], timeout=10)
        assert nc.returncode == 0, nc.stderr

    lab.start_roscore()  # the master on the robot, named as its own hosts file says
    try:
        with secured(lab):   # ROS 1 as the product sets it up: the peers-only firewall on
            _check_everything_from_both_sides(lab)
    finally:
        lab.stop_roscore()
    for h in COMPUTERS:
        for _ in range(2):  # ros apply, then hosts apply: one per call
            r = rosnet(lab, h, "undo", "--yes")
            assert r.returncode == 0, r.stdout + r.stderr
        assert lab.hosts_path(h).read_bytes() == stock[h][0]
        assert lab.bashrc_path(h).read_bytes() == stock[h][1]
        r = rosnet(lab, h, "undo", "--yes")
        assert r.returncode == 1 and "nothing to undo" in r.stdout
        assert resolve(lab, h, NAME[OTHER[h]]) == ""


def _check_everything_from_both_sides(lab) -> None:
    """The whole check, every step, from each side: nothing fails."""
    for h in COMPUTERS:  # the whole check, every step, from each side
        r = rosnet(lab, h, "check", "--json", "--config", str(lab.config_path(h)))
        results = {c["id"]: c for c in json.loads(r.stdout)["checks"]}
        bad = {cid: (c["status"], c["summary"]) for cid, c in results.items()
               if c["status"] not in ("pass", "warn")}
        assert r.returncode == 0 and not bad, (h, bad, r.stderr[-2000:])
        for cid in ("linux.hosts", "linux.resolve", "ros.env", "ros.master"):
            assert results[cid]["status"] == "pass", (h, cid, results[cid])


def test_stale_entry_outside_the_block_is_fixed_on_request(lab):
    """The lab's stale_hosts variant: the laptop maps turtlebot to an old public address."""
    with lab.variant("stale_hosts"):
        cfg = str(lab.config_path("laptop"))
        assert resolve(lab, "laptop", ADDR.ROBOT_NAME) == ADDR.STALE_ROBOT_PUBLIC
        before = lab.hosts_path("laptop").read_bytes()
        r = rosnet(lab, "laptop", "hosts", "apply", "--dry-run", "--config", cfg)
        assert r.returncode == 0 and "--comment-conflicts" in r.stdout
        # --yes answers the question a terminal would be asked: fix the conflicting line too
        r = rosnet(lab, "laptop", "hosts", "apply", "--yes", "--config", cfg)
        assert r.returncode == 0, r.stdout + r.stderr
        assert resolve(lab, "laptop", ADDR.ROBOT_NAME) == ADDR.ROBOT_PUBLIC
        assert f"# rosnet-tui: {ADDR.STALE_ROBOT_PUBLIC}".encode() in \
            lab.hosts_path("laptop").read_bytes()
        assert rosnet(lab, "laptop", "undo", "--yes").returncode == 0
        assert lab.hosts_path("laptop").read_bytes() == before
        r = rosnet(lab, "laptop", "hosts", "apply", "--yes", "--comment-conflicts",
                   "--config", cfg)
        assert r.returncode == 0, r.stdout + r.stderr
        assert rosnet(lab, "laptop", "undo", "--yes").returncode == 0
        assert lab.hosts_path("laptop").read_bytes() == before


def test_ros_ip_on_the_laptop_is_commented_out_with_consent(lab):
    with lab.variant("ros_ip_laptop"):
        rc = lab.bashrc_path("laptop")
        before = rc.read_bytes()
        r = rosnet(lab, "laptop", "ros", "apply", "--yes", "--comment-ros-ip",
                   "--config", str(lab.config_path("laptop")), "--file", str(rc))
        assert r.returncode == 0, r.stdout + r.stderr
        out = lab.run("laptop", ["bash", "-ic", 'echo "${ROS_IP-unset} $ROS_MASTER_URI"'],
                      timeout=10).stdout.strip().splitlines()[-1]
        assert out == "unset http://turtlebot:11311"
        assert rosnet(lab, "laptop", "undo", "--yes").returncode == 0
        assert rc.read_bytes() == before
