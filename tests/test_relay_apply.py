"""`rosnet-tui relay apply` on the master against a real sshd on 127.0.0.1 standing for the relay:
its sessions get a home with rosnet-tui installed the README's way (pipx layout,
tests/lab/readme_install.py) and a PATH without the development interpreter, so the relay's side
runs on the relay's own install. The master's side is the CLI with a home of its own (its ~/.ssh
trusting the relay's host key, its fleet CA)."""

from __future__ import annotations

import getpass
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from rosnet_tui.core.config import paths as config_paths
from rosnet_tui.core.peer import relayproto
from rosnet_tui.core.ros import fleet_tls, pairing, relay, relay_apply
from rosnet_tui.core.saved.settings import load_settings
from tests.builders import free_port
from tests.lab import readme_install
from tests.lab.topology import SSH_SESSION_PATH
from tests.plugins.ssh import SSHD, Sshd, keygen

pytestmark = [pytest.mark.lab,       # root: the README's install is cached under /var/cache
              pytest.mark.skipif(not os.path.exists(SSHD) or os.geteuid() != 0,
                                 reason="needs OpenSSH's sshd, and root")]

SETTINGS = """\
[this]
name = "turtlebot"
role = "master"
[[peer]]
name = "sami"
local_ip = "192.168.1.10"
[ros]
version = {version}
master = "turtlebot"
{relay}"""
RELAY = """\
[relay]
host = "relay"
ssh_user = "{user}"
ssh_port = {port}
zenoh_port = {zport}
"""


@pytest.fixture(scope="module")
def relay_sshd(tmp_path_factory):
    root = tmp_path_factory.mktemp("relay")
    home = root / "home"
    home.mkdir()
    readme_install.install(home)
    d = Sshd(root / "sshd", extra_config=f"SetEnv HOME={home} PATH={SSH_SESSION_PATH}\n")
    d.home = home
    d.start()
    yield d
    d.stop()


class Master:
    """The master's seat: a home (~/.ssh, the config folder with the fleet CA), its settings."""

    def __init__(self, tmp: Path, relay_sshd: Sshd, *, ca: bool = True, trust: bool = True,
                 version: int = 2, role: str = "master", port: int | None = None) -> None:
        self.home = tmp / "master"
        ssh = self.home / ".ssh"
        ssh.mkdir(parents=True, mode=0o700)
        relay_sshd.authorized.write_text(keygen(ssh / "id_ed25519") + "\n")
        (ssh / "known_hosts").write_text(
            f"[relay]:{relay_sshd.port} {relay_sshd.host_pub.rsplit(' ', 1)[0]}\n"
            if trust else "")
        self.zport = free_port()
        self.config = tmp / "config.toml"
        text = SETTINGS.format(version=version, relay=RELAY.format(
            user=getpass.getuser(), port=port or relay_sshd.port, zport=self.zport))
        if role != "master":
            text = text.replace('role = "master"', f'role = "{role}"').replace(
                'master = "turtlebot"', 'master = "sami"')
        self.config.write_text(text)
        self.tls = fleet_tls.tls_paths(self.home / ".config" / "rosnet-tui")
        if ca:
            pairing.prepare_master(load_settings(self.config), self.tls)
        self.state = tmp / "state"
        self.unit_dir = tmp / "units"       # the relay's unit folder (the same machine here)

    def env(self) -> dict[str, str]:
        env = {k: v for k, v in os.environ.items() if not k.startswith("XDG_")}
        env.update(HOME=str(self.home), SSH_AUTH_SOCK="")
        return env

    def run(self, *args: str, timeout: float = 120) -> subprocess.CompletedProcess:
        # 'relay' is 127.0.0.1 for this process alone: its own /etc/hosts, bound over the real
        # one in a mount namespace of its own.
        hosts = self.home / "etc_hosts"
        hosts.write_text("127.0.0.1\tlocalhost\n127.0.0.1\trelay\n")
        own_hosts = ["unshare", "-m", "sh", "-c", 'mount --bind "$0" /etc/hosts && exec "$@"',
                     str(hosts)]
        return subprocess.run([*own_hosts, sys.executable, "-m", "rosnet_tui", *args, "--config",
                               str(self.config), "--state-dir", str(self.state)],
                              capture_output=True, text=True, timeout=timeout,
                              stdin=subprocess.DEVNULL, env=self.env())

    def apply(self, *args: str) -> subprocess.CompletedProcess:
        return self.run("relay", "apply", "--unit-dir", str(self.unit_dir), *args)


def relay_files(home: Path) -> dict[str, Path]:
    cfg = home / ".config" / "rosnet-tui"
    return {"config": cfg / relay.CONFIG_NAME, "key": cfg / "tls" / "node.key",
            "crt": cfg / "tls" / "node.crt", "ca": cfg / "tls" / "ca.crt"}


@pytest.fixture
def clean_relay(relay_sshd):
    def wipe() -> None:
        for p in relay_files(relay_sshd.home).values():
            p.unlink(missing_ok=True)
    wipe()
    yield relay_sshd
    wipe()


def test_relay_apply_sets_the_relay_up_and_undo_puts_its_files_back(clean_relay, tmp_path):
    m = Master(tmp_path, clean_relay)
    files = relay_files(clean_relay.home)
    unit = m.unit_dir / "rosnet-tui-relay.service"

    dry = m.apply("--dry-run")
    assert dry.returncode == 0, dry.stdout + dry.stderr
    assert "Dry run: nothing was done on the relay." in dry.stdout
    assert "the relay makes its own key there" in dry.stdout
    assert str(files["config"]) in dry.stdout and str(unit) in dry.stdout
    assert not any(p.exists() for p in files.values()) and not unit.exists()

    no_tty = m.apply()                 # no --yes and no terminal: nothing done, exit 2
    assert no_tty.returncode == 2 and "--yes" in no_tty.stderr
    assert not files["key"].exists()

    out = m.apply("--yes")
    assert out.returncode == 0, out.stdout + out.stderr
    # The relay's key was made there and never left it: 0600, and nowhere in the master's home.
    key = files["key"].read_bytes()
    assert files["key"].stat().st_mode & 0o777 == 0o600
    assert not any(key in p.read_bytes() for p in m.home.rglob("*") if p.is_file())
    summ = fleet_tls.cert_summary(files["crt"])
    assert summ["cn"] == "relay" and summ["sans"] == ["relay"]
    assert summ["issuer_key_id"] == fleet_tls.ca_key_id(m.tls.ca_crt)
    assert files["ca"].read_bytes() == m.tls.ca_crt.read_bytes()
    assert not (files["ca"].parent / "ca.key").exists()          # the CA stays on the master
    # The router config names the relay's own TLS files and its port; relay serve accepts it.
    cfg = relay.read_relay_config(files["config"])
    assert relay.listen_endpoints(files["config"]) == [f"tls/0.0.0.0:{m.zport}"]
    assert set(relay.tls_files(cfg).values()) == {str(files["ca"]), str(files["key"]),
                                                   str(files["crt"])}
    start = next(x for x in unit.read_text().splitlines() if x.startswith("ExecStart="))
    venv_python = clean_relay.home / readme_install.VENV / "bin" / "python"
    assert start == (f"ExecStart={venv_python} -m rosnet_tui relay serve --router-config "
                     f"{files['config']}")              # the relay's install, not the master's
    assert f"User={getpass.getuser()}" in unit.read_text()
    assert "RestartPreventExitStatus=2" in unit.read_text().splitlines()  # refused: no loop
    assert "Undo (the config and unit, not the key) with: rosnet-tui undo" in out.stdout

    # The unit's command starts the relay's router from what was written (its own install).
    serve = subprocess.Popen([str(venv_python), "-m", "rosnet_tui", "relay", "serve",
                              "--router-config", str(files["config"])],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             env={"HOME": str(clean_relay.home), "PATH": SSH_SESSION_PATH},
                             cwd="/")
    try:
        line = serve.stdout.readline()
        assert "listening on tls/0.0.0.0:" in line, line + serve.stderr.read()
    finally:
        serve.terminate()
        serve.wait(10)

    again = m.apply("--yes")           # nothing changes: no new key, no new undo entry
    assert again.returncode == 0, again.stderr
    assert "the relay's certificate is good: kept" in again.stdout
    assert "already set up: nothing to change" in again.stdout
    assert files["key"].read_bytes() == key
    assert len(list((m.state / "journal").glob("*.json"))) == 1

    undo = m.run("undo", "--yes")
    assert undo.returncode == 0, undo.stdout + undo.stderr
    assert "on the relay relay" in undo.stdout
    assert not files["config"].exists() and not unit.exists()
    assert files["key"].read_bytes() == key     # the key and certificate stay, as ros apply's


# systemd does not run here: the relay's sshd gets /run/systemd/system (what relayproto looks
# for) in a mount namespace of its own, and a stand-in `systemctl` first on its PATH that speaks
# systemctl's interface as far as `relay apply` uses it (its arguments; exit 0, or the status
# and message of a failed unit) and records each call.
STANDIN = """#!/bin/sh
printf '%s\\n' "$*" >> "$(dirname "$0")/calls"
if [ -e "$(dirname "$0")/fail" ]; then echo "Failed to enable unit: Access denied" >&2; exit 1; fi
exit 0
"""
SYSTEMD_NS = ("unshare", "-m", "sh", "-c", "mount -t tmpfs -o mode=755 none /run/systemd && "
              'mkdir /run/systemd/system && exec "$@"', "sh")


@pytest.fixture(scope="module")
def systemd_relay(tmp_path_factory):
    root = tmp_path_factory.mktemp("systemd_relay")
    home, bin_dir = root / "home", root / "bin"
    home.mkdir()
    bin_dir.mkdir()
    (bin_dir / "systemctl").write_text(STANDIN)
    (bin_dir / "systemctl").chmod(0o755)
    readme_install.install(home)
    d = Sshd(root / "sshd", wrap=SYSTEMD_NS,
             extra_config=f"SetEnv HOME={home} PATH={bin_dir}:{SSH_SESSION_PATH}\n")
    d.home, d.bin = home, bin_dir
    d.start()
    yield d
    d.stop()


def test_a_yes_enables_and_starts_the_unit_on_the_relay(systemd_relay, tmp_path):
    """`relay apply` printed the systemctl line for the user to run on the relay after a yes
    to setting it up; now that yes runs it there over SSH (root here), and --dry-run, or a
    rerun without --yes, still only says it."""
    m = Master(tmp_path, systemd_relay)
    calls = systemd_relay.bin / "calls"
    unit = m.unit_dir / "rosnet-tui-relay.service"      # outside systemd's folder: by its path
    started = [["daemon-reload"], ["enable", str(unit)], ["start", "rosnet-tui-relay.service"]]

    def seen() -> list[list[str]]:
        return [x.split() for x in calls.read_text().splitlines()] if calls.exists() else []

    dry = m.apply("--dry-run")
    assert dry.returncode == 0, dry.stdout + dry.stderr
    line = f"systemctl daemon-reload && systemctl enable {unit} && systemctl start "
    assert f"the apply runs: {line}" in dry.stdout, dry.stdout
    assert seen() == []
    out = m.apply("--yes")
    assert out.returncode == 0, out.stdout + out.stderr
    assert seen() == started, out.stdout
    assert "its router runs as rosnet-tui-relay.service" in out.stdout
    calls.unlink()
    idle = m.apply()            # nothing to change and no yes: the line is said, not run
    assert idle.returncode == 0 and seen() == [], idle.stdout + idle.stderr
    assert f"on the relay: {line}" in idle.stdout
    again = m.apply("--yes")    # nothing changed: started (a running unit stays as it is)
    assert again.returncode == 0 and seen() == started, again.stdout + again.stderr
    calls.unlink()
    relay_files(systemd_relay.home)["config"].write_text("// changed by hand\n")
    fixed = m.apply("--yes")    # the running router must read its config again
    assert fixed.returncode == 0, fixed.stdout + fixed.stderr
    assert seen() == [*started[:2], ["restart", "rosnet-tui-relay.service"]]
    calls.unlink()
    (systemd_relay.bin / "fail").touch()
    try:
        bad = m.apply("--yes")
    finally:
        (systemd_relay.bin / "fail").unlink()
    assert bad.returncode == 1 and "Traceback" not in bad.stderr
    assert "systemctl failed (exit status 1: Failed to enable unit: Access denied)" in bad.stderr
    assert f"run on the relay: {line}" in bad.stderr, bad.stderr


def test_undo_stops_and_disables_the_unit_before_it_takes_it_away(systemd_relay, tmp_path):
    """Undo of a `relay apply` took the unit's file away and left its router running (and
    linked for the next boot). Now it stops and disables the unit first, while its file is there,
    then puts the files back and has systemd read them again. Where systemctl fails, the undo
    changes nothing on the relay, says what to run there, and exits 1."""
    for p in relay_files(systemd_relay.home).values():
        p.unlink(missing_ok=True)
    m = Master(tmp_path, systemd_relay)
    calls = systemd_relay.bin / "calls"
    unit = m.unit_dir / "rosnet-tui-relay.service"
    out = m.apply("--yes")
    assert out.returncode == 0 and unit.exists(), out.stdout + out.stderr
    calls.unlink()
    (systemd_relay.bin / "fail").touch()
    try:
        refused = m.run("undo", "--yes")
    finally:
        (systemd_relay.bin / "fail").unlink()
    assert refused.returncode == 1 and "Traceback" not in refused.stderr, refused.stderr
    said = refused.stdout + refused.stderr
    assert "run on the relay `systemctl disable --now rosnet-tui-relay.service`" in said, said
    assert "nothing was changed on the relay" in said, said
    assert unit.exists() and relay_files(systemd_relay.home)["config"].exists()
    calls.unlink()
    undo = m.run("undo", "--yes")
    assert undo.returncode == 0, undo.stdout + undo.stderr
    assert [x.split() for x in calls.read_text().splitlines()] == [
        ["disable", "--now", "rosnet-tui-relay.service"], ["daemon-reload"]], undo.stdout
    assert not unit.exists() and not relay_files(systemd_relay.home)["config"].exists()
    assert "ran `systemctl disable --now rosnet-tui-relay.service`" in undo.stdout, undo.stdout


def test_undo_steps_stop_a_unit_it_made_and_restart_one_put_back():
    unit = {"path": "/etc/systemd/system/rosnet-tui-relay.service", "before": None}
    config = {"path": "/home/r/.config/rosnet-tui/relay.json5", "before": "{}"}
    assert relay_apply.undo_steps([config, unit]) == (["systemctl disable --now rosnet-tui-relay.service"],
                                          ["systemctl daemon-reload"])
    assert relay_apply.undo_steps([config, dict(unit, before="[Unit]\n")]) == (
        [], ["systemctl daemon-reload", "systemctl try-restart rosnet-tui-relay.service"])
    assert relay_apply.undo_steps([config]) == (
        [], ["systemctl daemon-reload", "systemctl try-restart rosnet-tui-relay.service"])


def test_the_systemctl_line_names_the_unit_as_systemd_knows_it():
    """In systemd's own folder the unit is enabled and started by name (restarted when the
    apply changed what it reads); a login that is not root is told to use sudo."""
    look = relay_apply.RelayLook("c", "r", "ca", "k", "crt", "py", "", "root", True, True, {}, {})
    plan = relay_apply.RelayPlan("relay", look, None)
    start_line = relay_apply.start_line
    unit = relay_apply.UNIT_DIR / relay_apply.UNIT_NAME
    assert start_line(plan, unit) == ("systemctl daemon-reload && systemctl enable --now "
                                      "rosnet-tui-relay.service")
    plan.cert_why = "it has none yet"               # a first set-up: nothing runs yet
    assert start_line(plan, unit).endswith("systemctl enable --now rosnet-tui-relay.service")
    plan.files = [relay_apply.RemoteFile(str(unit), "[Unit]\n", "[Unit]\n")]   # a renewal
    assert start_line(plan, unit) == ("systemctl daemon-reload && systemctl enable "
                                      "rosnet-tui-relay.service && systemctl restart "
                                      "rosnet-tui-relay.service")
    plan.look = relay_apply.RelayLook("c", "r", "ca", "k", "crt", "py", "", "ops", True, True, {}, {})
    assert start_line(plan, unit).startswith("sudo systemctl daemon-reload && sudo systemctl")


def test_a_config_changed_on_the_relay_is_previewed_as_a_diff_and_undo_puts_it_back(
        clean_relay, tmp_path):
    m = Master(tmp_path, clean_relay)
    files = relay_files(clean_relay.home)
    files["config"].parent.mkdir(parents=True, exist_ok=True)
    files["config"].write_text("// an old config of mine\n")
    out = m.apply("--yes")
    assert out.returncode == 0, out.stdout + out.stderr
    assert "-// an old config of mine" in out.stdout          # a diff against what is there
    assert files["config"].read_text() != "// an old config of mine\n"
    undo = m.run("undo", "--yes")
    assert undo.returncode == 0, undo.stdout + undo.stderr
    assert files["config"].read_text() == "// an old config of mine\n"


def test_an_unknown_relay_host_key_stops_before_anything_naming_the_hop(clean_relay, tmp_path):
    m = Master(tmp_path, clean_relay, trust=False)
    out = m.apply("--yes")
    assert out.returncode == 1 and "Traceback" not in out.stderr
    assert "SSH from turtlebot to the relay relay" in out.stderr, out.stderr
    assert "host_key_unknown" in out.stderr and clean_relay.fingerprint in out.stderr
    assert not relay_files(clean_relay.home)["key"].exists()


def test_no_sshd_at_the_relay_names_the_hop_and_exits_1(clean_relay, tmp_path):
    m = Master(tmp_path, clean_relay, port=free_port())
    out = m.apply("--yes")
    assert out.returncode == 1 and "Traceback" not in out.stderr
    assert re.search(r"SSH from turtlebot to the relay relay \(\S+@relay:\d+\) failed",
                     out.stderr), out.stderr


def test_a_relay_without_rosnet_tui_installed_is_told_how_to_install_it(tmp_path):
    home = tmp_path / "bare_home"
    home.mkdir()
    bare = Sshd(tmp_path / "bare", extra_config=f"SetEnv HOME={home} PATH={SSH_SESSION_PATH}\n")
    bare.start()
    try:
        m = Master(tmp_path, bare)
        out = m.apply("--yes")
        assert out.returncode == 1 and "Traceback" not in out.stderr
        assert "the relay relay has no rosnet-tui installed" in out.stderr, out.stderr
        assert "README" in out.stderr
        assert not (home / ".config").exists()          # nothing made there
    finally:
        bare.stop()


@pytest.mark.parametrize("case, words", [
    ("no relay", "no relay in the settings"),
    ("member", "turtlebot is not the master"),
    ("no CA", "run `rosnet-tui ros apply` first"),
    ("ROS 1", "ROS 2 only"),
])
def test_refusals_exit_2_with_one_clear_line(relay_sshd, tmp_path, case, words):
    m = Master(tmp_path, relay_sshd, ca=case == "no relay", version=1 if case == "ROS 1" else 2,
               role="member" if case == "member" else "master")
    if case == "no relay":
        m.config.write_text(m.config.read_text().split("[relay]")[0])
    out = m.apply("--yes")
    assert out.returncode == 2, out.stdout + out.stderr
    assert words in out.stderr and "Traceback" not in out.stderr


def test_the_relay_program_finds_the_config_folder_as_rosnet_tui_does(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg"))
    assert relayproto.config_dir() == config_paths.default_config_dir()
    monkeypatch.delenv("XDG_CONFIG_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert relayproto.config_dir() == config_paths.default_config_dir()


def test_write_refuses_a_file_changed_since_the_preview(tmp_path):
    p = tmp_path / "f"
    p.write_text("theirs\n")
    rep = relayproto.write({"files": [{"path": str(p), "content": "ours\n", "mode": 0o644,
                                       "expect": relayproto.digest("before\n")}]})
    assert "changed on the relay since the preview" in rep["error"]
    assert p.read_text() == "theirs\n"
    assert json.dumps(rep)
    t0 = time.monotonic()
    os.mkfifo(tmp_path / "fifo")                      # read without waiting on a writer
    with pytest.raises(OSError):
        relayproto.read(tmp_path / "fifo")
    assert time.monotonic() - t0 < 5


async def test_undo_from_a_running_event_loop_says_why_and_does_not_crash():
    """The wizard undoes from its event loop: the relay's handler must not call asyncio.run
    there. A relay that does not answer: a refusal naming it (ManagedFileError), not a crash."""
    from rosnet_tui.core.files.managed_text import ManagedFileError
    from rosnet_tui.core.ros import relay_apply

    change = {"kind": relay_apply.KIND, "state": "made", "host": "localhost", "user": "root",
              "port": free_port(), "files": [{"path": "/nonexistent/x", "before": None,
                                               "after": "0" * 64}]}
    with pytest.raises(ManagedFileError, match="to the relay localhost"):
        relay_apply.undo_records([change], False)
    assert change["state"] == "made"                # nothing said undone
    said = relay_apply.undo_records([change], True)   # forced: forgotten, said so
    assert change["state"] == "forgotten" and "forgotten" in said[0]
