"""`rosnet-tui hosts|ros|undo` as a user runs them: diff, ask, --yes, exit codes, privilege."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from rosnet_tui.core.files import managed_file as mf
from rosnet_tui.core.files import undo_journal as uj
from rosnet_tui.core.saved.settings import load_settings
from tests.builders import ROBOT_CONFIG, ros2_master
from tests.prompts import run_answering

REPO = Path(__file__).resolve().parent.parent

HOSTS = b"127.0.0.1\tlocalhost\r\n::1 localhost ip6-localhost\n# end"
BASHRC = b"# bashrc\nexport ROS_IP=10.10.10.1\n"


@pytest.fixture
def box(tmp_path):
    """A home with settings, a hosts file and a .bashrc; env pointing everything there."""
    home = tmp_path / "home"
    home.mkdir()
    cfg = home / ".config" / "rosnet-tui" / "config.toml"
    cfg.parent.mkdir(parents=True)
    cfg.write_text(ROBOT_CONFIG)
    (tmp_path / "hosts").write_bytes(HOSTS)
    (home / ".bashrc").write_bytes(BASHRC)
    env = {k: v for k, v in os.environ.items() if not k.startswith(("ROS_", "XDG_"))}
    env.update(HOME=str(home), PYTHONPATH=str(REPO), PYTHONUNBUFFERED="1")

    class Box:
        pass

    b = Box()
    b.home, b.cfg, b.hosts, b.bashrc, b.env = home, cfg, tmp_path / "hosts", home / ".bashrc", env
    b.state = home / ".local" / "state" / "rosnet-tui"
    return b


def run(box, *args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "rosnet_tui", *args], capture_output=True,
                          text=True, timeout=60, stdin=subprocess.DEVNULL, cwd=REPO,
                          env=env or box.env)


def run_tty(box, args: list[str], answers: list[str], timeout: float = 30) -> tuple[int, str]:
    """Run on a pseudo-terminal; answer each '[y/N]' prompt in turn."""
    return run_answering([sys.executable, "-m", "rosnet_tui", *args], answers, env=box.env,
                         cwd=REPO, timeout=timeout)


def hosts_args(box, *extra: str) -> list[str]:
    return ["hosts", "apply", "--file", str(box.hosts), *extra]


# --------------------------------------------------------------------------- hosts
def test_without_terminal_and_without_yes_shows_the_diff_and_refuses(box):
    out = run(box, *hosts_args(box))
    assert out.returncode == 2
    assert "+10.10.10.1      turtlebot" in out.stdout and "--yes" in out.stderr
    assert box.hosts.read_bytes() == HOSTS


def test_dry_run_writes_nothing(box):
    out = run(box, *hosts_args(box, "--dry-run"))
    assert out.returncode == 0 and "Dry run" in out.stdout and "+# BEGIN rosnet-tui" in out.stdout
    assert box.hosts.read_bytes() == HOSTS


def test_yes_writes_then_nothing_more_to_do_then_undo(box):
    out = run(box, *hosts_args(box, "--yes"))
    assert out.returncode == 0, out.stderr
    assert "Wrote" in out.stdout and "Backup:" in out.stdout
    data = box.hosts.read_bytes()
    assert data.endswith(HOSTS) and b"198.51.100.2    sami" in data
    again = run(box, *hosts_args(box, "--yes"))
    assert again.returncode == 0 and "already up to date" in again.stdout
    assert box.hosts.read_bytes() == data
    undo = run(box, "undo", "--yes")
    assert undo.returncode == 0 and "Restored" in undo.stdout
    assert box.hosts.read_bytes() == HOSTS
    nothing = run(box, "undo", "--yes")
    assert nothing.returncode == 1 and "nothing to undo" in nothing.stdout


def test_use_switches_the_set_and_saves_the_profile_keeping_comments(box):
    out = run(box, "hosts", "use", "office", "--file", str(box.hosts), "--yes")
    assert out.returncode == 0, out.stderr
    assert "# Active set: office" in box.hosts.read_text()
    assert load_settings(box.cfg).this.profile == "office"
    assert box.cfg.read_text().startswith("# my robot")
    show = run(box, "hosts", "show", "--file", str(box.hosts))
    assert show.returncode == 0 and "172.16.0.6" in show.stdout
    assert "'office' set is active" in show.stdout and "exactly this set" in show.stdout


def test_dry_run_of_use_saves_nothing(box):
    out = run(box, "hosts", "use", "office", "--file", str(box.hosts), "--dry-run")
    assert out.returncode == 0
    assert load_settings(box.cfg).this.profile == "remote" and box.hosts.read_bytes() == HOSTS


def test_bad_settings_exit_2_and_write_nothing(box):
    box.cfg.write_text(ROBOT_CONFIG.replace('local_ip = "10.10.10.1"', 'local_ip = "10.10.10.256"'))
    out = run(box, *hosts_args(box, "--yes"))
    assert out.returncode == 2 and "this.local_ip" in out.stderr
    assert box.hosts.read_bytes() == HOSTS


def test_incomplete_settings_exit_2_and_say_what_is_missing(box):
    # (a blank local_ip is filled in from this machine, as `check` does: tests/
    # test_cli_example_settings.py; a missing name cannot be)
    box.cfg.write_text(ROBOT_CONFIG.replace('name = "turtlebot"\n', "")
                       .replace('master = "turtlebot"\n', ""))
    out = run(box, *hosts_args(box, "--yes"))
    assert out.returncode == 2 and "this.name" in out.stderr and "nothing was written" \
        in out.stderr
    assert box.hosts.read_bytes() == HOSTS


def test_no_settings_file_is_exit_2(box):
    box.cfg.unlink()
    out = run(box, *hosts_args(box, "--yes"))
    assert out.returncode == 2 and "no settings file" in out.stderr


def test_stale_expected_digest_is_refused(box):
    out = run(box, *hosts_args(box, "--yes", "--expect-digest", "0" * 64))
    assert out.returncode == 1 and "changed since the preview" in out.stderr
    assert box.hosts.read_bytes() == HOSTS


def test_terminal_answer_yes_writes_and_no_does_not(box):
    rc, out = run_tty(box, hosts_args(box), ["n"])
    assert rc == 1 and "Cancelled" in out and box.hosts.read_bytes() == HOSTS
    rc, out = run_tty(box, hosts_args(box), ["y"])
    assert rc == 0 and "Wrote" in out, out
    assert b"# END rosnet-tui" in box.hosts.read_bytes()


def test_terminal_asks_about_conflicting_lines(box):
    box.hosts.write_bytes(b"127.0.1.1\tturtlebot\n")
    rc, out = run_tty(box, hosts_args(box), ["y", "y"])
    assert rc == 0, out
    assert "conflict" in out and box.hosts.read_bytes().endswith(b"# rosnet-tui: 127.0.1.1\tturtlebot\n")


# --------------------------------------------------------------------------- ros
def test_ros_apply_comments_ros_ip_when_asked_or_told_yes(box):
    out = run(box, "ros", "apply", "--dry-run", "--file", str(box.bashrc))
    assert out.returncode == 0, out.stderr
    assert "--comment-ros-ip" in out.stdout and box.bashrc.read_bytes() == BASHRC
    out = run(box, "ros", "apply", "--yes", "--file", str(box.bashrc))
    assert out.returncode == 0, out.stderr
    text = box.bashrc.read_text()
    # --yes answers the question a terminal would be asked: comment the ROS_IP line out
    assert "# rosnet-tui: export ROS_IP=10.10.10.1\n" in text
    assert "export ROS_MASTER_URI=http://turtlebot:11311" in text
    assert "export ROS_MASTER_URI=http://turtlebot:11311" in out.stdout  # for this shell
    assert run(box, "undo", "--yes").returncode == 0
    assert box.bashrc.read_bytes() == BASHRC
    out = run(box, "ros", "apply", "--yes", "--comment-ros-ip")  # default file: ~/.bashrc
    assert out.returncode == 0, out.stderr
    assert "# rosnet-tui: export ROS_IP=10.10.10.1\n" in box.bashrc.read_text()
    assert run(box, "undo", "--yes").returncode == 0
    assert box.bashrc.read_bytes() == BASHRC


def test_ros_apply_on_a_terminal_asks_about_ros_ip(box):
    rc, out = run_tty(box, ["ros", "apply"], ["y", "y"])
    assert rc == 0, out
    assert "ROS_IP" in out and "# rosnet-tui: export ROS_IP" in box.bashrc.read_text()


def test_ros_export_prints_the_line_for_this_shell(box):
    env = dict(box.env, ROS_HOSTNAME="turtlebot")
    out = run(box, "ros", "export", env=env)
    assert out.stdout.splitlines() == ["export ROS_MASTER_URI=http://turtlebot:11311",
                                       "unset ROS_HOSTNAME"]


def test_ros_bad_settings_exit_2(box):
    box.cfg.write_text(ROBOT_CONFIG.replace('role = "master"', 'role = "member"')
                       .replace('master = "turtlebot"', 'master = "nobody"'))
    out = run(box, "ros", "apply", "--yes")
    assert out.returncode == 2 and box.bashrc.read_bytes() == BASHRC


# --------------------------------------------------------------------------- undo
def test_undo_without_terminal_and_without_yes_refuses(box):
    assert run(box, *hosts_args(box, "--yes")).returncode == 0
    out = run(box, "undo")
    assert out.returncode == 2 and "--yes" in out.stderr
    assert box.hosts.read_bytes() != HOSTS


def test_undo_refuses_to_lose_a_later_edit(box):
    assert run(box, *hosts_args(box, "--yes")).returncode == 0
    with open(box.hosts, "ab") as f:
        f.write(b"\n10.9.9.9 added-by-hand\n")
    out = run(box, "undo", "--yes")
    assert out.returncode == 1 and "--force" in out.stderr
    assert run(box, "undo", "--yes", "--force").returncode == 0
    assert box.hosts.read_bytes() == HOSTS


# --------------------------------------------------------------------------- privilege
def test_when_root_is_needed_the_exact_sudo_command_is_run(box, tmp_path, monkeypatch, capsys):
    """In process, as if this user could not write the file; a stand-in sudo on PATH runs the
    command for real (we are root already), so the whole path is exercised but the password."""
    from rosnet_tui.cli import main

    fake = tmp_path / "bin"
    fake.mkdir()
    (fake / "sudo").write_text('#!/bin/sh\necho "sudo $*" > "$(dirname "$0")/called"\n[ "$1" = "-n" ] && shift\nexec "$@"\n')
    os.chmod(fake / "sudo", 0o755)
    monkeypatch.setenv("PATH", f"{fake}{os.pathsep}{os.environ.get('PATH', '')}")
    monkeypatch.setenv("HOME", str(box.home))
    monkeypatch.setattr(mf, "can_write", lambda path: False)
    from rosnet_tui.core.files.hosts import preview_hosts
    seen = preview_hosts(load_settings(box.cfg), "remote", box.hosts)
    rc = main(["hosts", "apply", "--file", str(box.hosts), "--yes", "--no-checks"])
    out = capsys.readouterr().out
    assert rc == 0, out
    called = (fake / "called").read_text().split()
    called = [x for x in called if x != "-n"]  # no terminal here: sudo -n
    assert called[:4] == ["sudo", sys.executable, "-m", "rosnet_tui"]
    assert f"--expect-digest {seen.write_digest}" in " ".join(called)   # what was previewed
    assert "needs root; running:" in out
    assert b"198.51.100.2    sami" in box.hosts.read_bytes()
    assert [e.label for e in uj.journal_entries(box.state)] == ["hosts: remote set"]
    # and undo goes the same way
    rc = main(["undo", "--yes", "--no-checks"])
    assert rc == 0 and box.hosts.read_bytes() == HOSTS
    assert "undo --yes --expect-entry" in (fake / "called").read_text()


def test_without_sudo_the_command_is_shown_and_nothing_written(box, monkeypatch, capsys):
    from rosnet_tui.cli import main
    from rosnet_tui.core.files import privilege

    monkeypatch.setenv("HOME", str(box.home))
    monkeypatch.setattr(mf, "can_write", lambda path: False)
    monkeypatch.setattr(privilege, "sudo_available", lambda: False)
    rc = main(["hosts", "apply", "--file", str(box.hosts), "--yes"])
    err = capsys.readouterr().err
    assert rc == 1 and "sudo is not installed" in err and "--expect-digest" in err
    assert box.hosts.read_bytes() == HOSTS


def test_root_hands_the_users_journal_back_to_the_user(box):
    """What sudo runs writes into the user's state dir; the journal stays the user's."""
    if os.geteuid() != 0:
        pytest.skip("needs root")
    box.state.mkdir(parents=True)
    for p in (box.home / ".local", box.home / ".local" / "state", box.state):
        os.chown(p, 65534, 65534)
    out = run(box, "hosts", "apply", "--file", str(box.hosts), "--yes", "--state-dir",
              str(box.state))
    assert out.returncode == 0, out.stderr
    (entry,) = uj.journal_entries(box.state)
    for p in (box.state / "journal" / f"{entry.id}.json", box.state / "backups" / entry.id,
              box.state / "lock"):
        assert os.stat(p).st_uid == 65534, p


@pytest.mark.skipif(os.geteuid() != 0 or not shutil.which("setpriv")
                    or not Path("/usr/bin/python3").exists(),
                    reason="needs root, setpriv and /usr/bin/python3")
def test_can_write_as_a_normal_user():
    """The real permission logic, run as the user nobody."""
    with tempfile.TemporaryDirectory(prefix="rosnet-can-write-") as d:
        os.chmod(d, 0o755)
        _can_write_as_nobody(Path(d))


def _can_write_as_nobody(tmp_path: Path) -> None:
    root_file, own_file = tmp_path / "root-owned", tmp_path / "own"
    root_file.write_text("x")
    own_file.write_text("x")
    (tmp_path / "open").mkdir(mode=0o777)
    os.chmod(tmp_path / "open", 0o777)
    os.chown(own_file, 65534, 65534)
    nobody = [shutil.which("setpriv"), "--reuid=65534", "--regid=65534", "--clear-groups",
              "/usr/bin/python3"]
    # Only "nobody cannot run Python or read this checkout" is a reason to skip; the check
    # itself must run: a crash inside can_write (exit 1, a traceback) fails the test.
    pre = subprocess.run([*nobody, "-c", "import sys, os; os.listdir(sys.argv[1])",
                          str(REPO / "rosnet_tui" / "core" / "files")],
                         capture_output=True, text=True, timeout=30, cwd="/")
    if pre.returncode != 0:
        pytest.skip(f"cannot run Python as nobody here: {pre.stderr.strip()[-200:]}")
    code = ("import sys; sys.path.insert(0, sys.argv[1]);"
            "from rosnet_tui.core.files.managed_write import can_write;"
            "print(*[can_write(p) for p in sys.argv[2:]])")
    r = subprocess.run([*nobody, "-c", code, str(REPO),
                        str(root_file), str(own_file), str(tmp_path / "new-in-root-dir"),
                        str(tmp_path / "open" / "new")],
                       capture_output=True, text=True, timeout=30, cwd="/")
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["False", "True", "False", "True"]


# --------------------------------------------------------------------------- ros pair --remove
def _fleet_master(box):
    """The box as a ROS 2 master with two members (neither has an SSH user: re-pairing them
    needs no network) and its fleet CA made; the CA's key id."""
    from rosnet_tui.core.config.settings_model import Peer
    from rosnet_tui.core.ros import fleet_tls
    from rosnet_tui.core.saved.settings import render_settings

    s = ros2_master()
    s.peers = [Peer(name="sami", public_ip="198.51.100.2"),
               Peer(name="rover", public_ip="203.0.113.30")]
    box.cfg.write_text(render_settings(s))
    made = run(box, "ros", "pair")
    assert made.returncode == 0, made.stderr
    box.tls = fleet_tls.tls_paths(box.home / ".config" / "rosnet-tui")
    return fleet_tls.ca_key_id(box.tls.ca_crt)


def test_ros_pair_remove_previews_and_refuses_without_terminal_or_yes(box):
    """Issue 29 (section 4, row 6): `ros pair --remove` rotated the fleet CA at once."""
    from rosnet_tui.core.ros import fleet_tls

    ca = _fleet_master(box)
    out = run(box, "ros", "pair", "--remove", "sami")
    assert out.returncode == 2, out.stdout + out.stderr
    assert "Taking sami out of the fleet" in out.stdout
    assert "a new fleet CA replaces" in out.stdout and "cannot bring it back" in out.stdout
    assert "every other member must pair again: rover" in out.stdout
    assert "no terminal" in out.stderr and "--yes" in out.stderr
    assert fleet_tls.ca_key_id(box.tls.ca_crt) == ca
    dry = run(box, "ros", "pair", "--remove", "sami", "--dry-run")
    assert dry.returncode == 0 and "Dry run: nothing was changed." in dry.stdout, dry.stderr
    assert "Taking sami out of the fleet" in dry.stdout
    assert fleet_tls.ca_key_id(box.tls.ca_crt) == ca
    bad = run(box, "ros", "pair", "--dry-run")
    assert bad.returncode == 2 and "--dry-run goes with --remove" in bad.stderr
    done = run(box, "ros", "pair", "--remove", "sami", "--yes")
    assert fleet_tls.ca_key_id(box.tls.ca_crt) != ca
    assert "rover: NOT re-paired: no SSH user" in done.stdout and done.returncode == 1


def test_ros_pair_remove_asks_on_a_terminal(box):
    from rosnet_tui.core.ros import fleet_tls

    ca = _fleet_master(box)
    rc, out = run_tty(box, ["ros", "pair", "--remove", "sami"], ["n"])
    assert rc == 1 and "Rotate the fleet CA now? [y/N]" in out and "Cancelled" in out, out
    assert fleet_tls.ca_key_id(box.tls.ca_crt) == ca
    rc, out = run_tty(box, ["ros", "pair", "--remove", "sami"], ["y"])
    assert "sami is out of the fleet" in out, out
    assert fleet_tls.ca_key_id(box.tls.ca_crt) != ca


# --------------------------------------------------------------------------- what is printed
def test_the_printed_undo_command_finds_the_change(box, tmp_path):
    """Issue 29 (section 4, row 10): "Undo with: rosnet-tui undo" left out the --state-dir in use,
    so that command found nothing. It is printed exactly, shell-quoted, and it works as printed."""
    import shlex

    state = tmp_path / "my state"        # a space: the quoting matters
    out = run(box, *hosts_args(box, "--yes", "--state-dir", str(state), "--config",
                               str(box.cfg)))
    assert out.returncode == 0, out.stderr
    line = next(x for x in out.stdout.splitlines() if "Undo with: " in x)
    printed = line.split("Undo with: ", 1)[1]
    assert printed == shlex.join(["rosnet-tui", "undo", "--config", str(box.cfg),
                                  "--state-dir", str(state)])
    argv = shlex.split(printed)
    assert argv[:2] == ["rosnet-tui", "undo"]
    again = run(box, *argv[1:], "--yes", "--no-checks")
    assert again.returncode == 0, again.stdout + again.stderr
    assert box.hosts.read_bytes() == HOSTS
    plain = run(box, *hosts_args(box, "--yes", "--no-checks"))       # the everyday journal
    assert "Undo with: rosnet-tui undo\n" in plain.stdout + "\n", plain.stdout


def test_help_says_what_undo_and_ros_cover_now(box):
    undo = run(box, "undo", "--help").stdout
    assert "(hosts or ros)" not in undo
    for what in ("/etc/hosts", "~/.bashrc", "Zenoh router's config", "firewall", "router map"):
        assert what in " ".join(undo.split()), what
    top = " ".join(run(box, "--help").stdout.split())
    assert "ros write the ROS environment for this component's role (ROS 1 or 2)" in top
    for args in (["ros", "--help"], ["ros", "apply", "--help"]):
        text = " ".join(run(box, *args).stdout.split())
        assert "ROS 1: ROS_MASTER_URI" in text or "ROS 1: the ROS_MASTER_URI" in text, text
        assert "RMW_IMPLEMENTATION" in text and "fleet CA" in text, text


def test_ros2_apply_dry_run_says_it_makes_the_ca_and_makes_nothing(box):
    """Issue 29 (section 4, row 10): on a ROS 2 master `ros apply --dry-run` did not say that the
    apply makes the fleet CA and keys; with the files already written it even made them."""
    from rosnet_tui.core.saved.settings import render_settings

    box.cfg.write_text(render_settings(ros2_master()))
    tls = box.home / ".config" / "rosnet-tui" / "tls"
    dry = run(box, "ros", "apply", "--dry-run")
    assert dry.returncode == 0, dry.stderr
    said = " ".join(dry.stdout.split())
    assert "this apply also makes the fleet CA" in said and "this router's certificate" in said
    assert "Dry run: nothing was written, and no key or certificate made." in said
    assert not tls.exists()
    done = run(box, "ros", "apply", "--yes", "--no-checks")
    assert done.returncode == 0 and (tls / "ca.key").exists(), done.stdout + done.stderr
    assert "Undo with: rosnet-tui undo" in done.stdout
    for f in tls.iterdir():
        f.unlink()
    again = run(box, "ros", "apply", "--dry-run")        # the files are up to date now
    assert again.returncode == 0 and "this apply also makes the fleet CA" in again.stdout
    assert list(tls.iterdir()) == [], again.stdout


def test_commands_hosts_prints_to_run_next_name_the_same_files(box):
    """A sibling of the printed undo command: `hosts show --file F --config C` said "To write
    this set: rosnet-tui hosts apply --profile remote", which would write /etc/hosts with the
    everyday settings."""
    import shlex

    out = run(box, "hosts", "show", "--profile", "remote", "--file", str(box.hosts),
              "--config", str(box.cfg))
    line = next(x for x in out.stdout.splitlines() if x.startswith("To write this set: "))
    argv = shlex.split(line.split(": ", 1)[1])
    assert argv[:4] == ["rosnet-tui", "hosts", "apply", "--profile"], argv
    assert argv[argv.index("--file") + 1] == str(box.hosts)
    assert argv[argv.index("--config") + 1] == str(box.cfg)
    done = run(box, *argv[1:], "--yes", "--no-checks")
    assert done.returncode == 0 and b"rosnet-tui" in box.hosts.read_bytes(), done.stderr


def _user_ssh_config_and_a_relay(box):
    """The user's own ~/.ssh/config (CRLF in it), and settings of a ROS 2 master whose peer sami
    is reached through a relay: (the config's path, its bytes, the settings)."""
    from rosnet_tui.core.config.settings_model import RelaySettings
    from rosnet_tui.core.saved.settings import render_settings

    mine = b"Host *\r\n    ServerAliveInterval 30\nIdentityFile ~/.ssh/other\n"
    cfg = box.home / ".ssh" / "config"
    cfg.parent.mkdir(mode=0o700)
    cfg.write_bytes(mine)
    s = ros2_master(security="mtls")
    s.relay = RelaySettings(host="relay", ssh_user="jump", tunnels={"sami": 2202})
    box.cfg.write_text(render_settings(s))
    return cfg, mine, s


def test_ros_apply_takes_out_the_relay_block_once_the_relay_is_gone(box):
    """[relay] (or the peers' tunnels) removed from the settings: `ros apply` took the old
    ~/.ssh/config block out of nothing, so `ssh sami` kept jumping through a relay no longer
    there. Now the preview shows it going, the user's lines stay byte for byte, and undo puts
    it back."""
    from rosnet_tui.core.config.settings_model import RelaySettings
    from rosnet_tui.core.saved.settings import render_settings

    cfg, mine, s = _user_ssh_config_and_a_relay(box)
    done = run(box, "ros", "apply", "--yes", "--no-checks")
    assert done.returncode == 0, done.stdout + done.stderr
    assert cfg.read_bytes().startswith(b"# BEGIN rosnet-tui") and cfg.read_bytes().endswith(mine)
    for gone in (RelaySettings(host="relay", ssh_user="jump"), RelaySettings()):
        s.relay = gone
        box.cfg.write_text(render_settings(s))
        dry = run(box, "ros", "apply", "--dry-run")
        assert dry.returncode == 0, dry.stderr
        assert "-Host sami" in dry.stdout and "-    ProxyJump jump@relay" in dry.stdout, dry.stdout
        assert cfg.read_bytes() != mine                     # a dry run writes nothing
    done = run(box, "ros", "apply", "--yes", "--no-checks")
    assert done.returncode == 0, done.stdout + done.stderr
    assert cfg.read_bytes() == mine
    again = run(box, "ros", "apply", "--dry-run")             # nothing left to take out
    assert "Host sami" not in again.stdout
    undone = run(box, "undo", "--yes")
    assert undone.returncode == 0, undone.stdout + undone.stderr
    assert b"Host sami" in cfg.read_bytes() and cfg.read_bytes().endswith(mine)


def test_ros1_apply_takes_out_a_stale_relay_block_too(box, monkeypatch):
    """A machine moved from ROS 2 with a relay to ROS 1 (which refuses [relay]): ROS 1's `ros
    apply` wrote its ~/.bashrc block and left the ~/.ssh/config block, so `ssh sami` kept
    jumping through a relay the network no longer uses. Now it is taken out as ROS 2's apply
    does: previewed, the user's lines kept byte for byte, one undo with the .bashrc block."""
    cfg, mine, _s = _user_ssh_config_and_a_relay(box)
    assert run(box, "ros", "apply", "--yes", "--no-checks").returncode == 0
    relayed = cfg.read_bytes()
    assert relayed.startswith(b"# BEGIN rosnet-tui") and relayed.endswith(mine)
    box.cfg.write_text(ROBOT_CONFIG)                      # ROS 1 now, no [relay]
    # The wizard's ROS step writes the same: the block goes with its .bashrc write.
    from rosnet_tui.core.config.paths import Paths
    from rosnet_tui.core.wizard.write_plans import write_plan

    monkeypatch.setenv("HOME", str(box.home))
    plan = write_plan("ros", load_settings(box.cfg), Paths(state_dir=box.state,
                                                           bashrc_path=box.bashrc))
    assert [(p.path, p.new) for p in plan.companions(False)] == [(cfg, mine)]
    dry = run(box, "ros", "apply", "--dry-run")
    assert dry.returncode == 0, dry.stdout + dry.stderr
    assert "-Host sami" in dry.stdout and "-    ProxyJump jump@relay" in dry.stdout, dry.stdout
    assert cfg.read_bytes() == relayed                       # a dry run writes nothing
    done = run(box, "ros", "apply", "--yes", "--no-checks")
    assert done.returncode == 0, done.stdout + done.stderr
    assert cfg.read_bytes() == mine and b"ROS_MASTER_URI" in box.bashrc.read_bytes()
    again = run(box, "ros", "apply", "--dry-run")
    assert "Host sami" not in again.stdout
    undone = run(box, "undo", "--yes")
    assert undone.returncode == 0, undone.stdout + undone.stderr
    assert cfg.read_bytes() == relayed and b"ROS_MASTER_URI" not in box.bashrc.read_bytes()
