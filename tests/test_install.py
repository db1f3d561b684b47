"""Installing rosnet-tui the way the README says, on the machines robots really run.

- The README opens with the two set-up commands, and CI runs the second.
- The first command, read from the README (so the two cannot drift), is typed by a brand-new
  normal user in a throwaway HOME on the distribution's own Python (/usr/bin/python3, externally
  managed on Debian 12); the program it installs then answers ``--version`` and ``check --help``
  from where it was installed, opens the wizard on a terminal, writes a root-owned file through
  sudo, undoes it, and writes the systemd unit through the sudo line it prints.
- The sudo command of the writers and the unit's ExecStart name the program by its absolute path,
  so they run without the user's PATH (sudo's secure_path, systemd's clean environment).
- The lowest Python that pyproject.toml claims installs the package and passes part of the suite.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import pty
import pwd
import re
import select
import shlex
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import termios
import time
from pathlib import Path

import psutil
import pytest

import rosnet_tui
from rosnet_tui.cli import build_parser
from rosnet_tui.cli import sync as sync_cli
from rosnet_tui.core.files import privilege
from tests.builders import ROBOT_CONFIG, loopback_master_config
from tests.plugins.web import WebServer

REPO = Path(__file__).resolve().parent.parent
SYSTEM_PYTHON = Path("/usr/bin/python3")
SECURE_PATH = "/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin"  # Debian's sudoers
USER_PATH = "/usr/local/bin:/usr/bin:/bin"         # what a new login shell has before ~/.local/bin
VERSION_LINE = f"rosnet-tui {rosnet_tui.__version__}"

HOSTS = b"127.0.0.1\tlocalhost\n::1 localhost ip6-localhost\n"


# --------------------------------------------------------------------------- the README
def readme_code_blocks() -> list[list[str]]:
    """The non-blank lines of each of the README's code blocks, in order."""
    text = (REPO / "README.md").read_text(encoding="utf-8")
    blocks = re.findall(r"^```[^\n]*\n(.*?)^```", text, re.S | re.M)
    assert blocks, "README.md has no code block"
    return [[line for line in b.splitlines() if line.strip()] for b in blocks]


def readme_setup_commands() -> list[str]:
    """The README's two set-up commands: the user's (its first code block), then the developers'
    (its second)."""
    return [line for block in readme_code_blocks()[:2] for line in block]


def install_line() -> tuple[str, str]:
    """The README's first command split into (what installs, the program it then opens)."""
    head, sep, program = readme_setup_commands()[0].rpartition(" && ")
    assert sep, "the first command must install, then open the wizard: 'INSTALL && PROGRAM'"
    return head, program


def test_readme_opens_with_the_two_set_up_commands():
    text = (REPO / "README.md").read_text(encoding="utf-8")
    title, _, rest = text.partition("\n\n")
    assert title.startswith("# ") and rest.startswith("```"), \
        "the README must open with the set-up commands, right under its title"
    commands = readme_setup_commands()
    assert len(commands) == 2, commands
    user, developers = readme_code_blocks()[:2]
    # Two blocks, never one paste: the developers' command installs servers and disables
    # services, which a technician copying the first block onto a robot must never run.
    assert user == [commands[0]] and developers == [commands[1]], (user, developers)
    head, program = install_line()
    assert program == "~/.local/bin/rosnet-tui", \
        "the program is named by the path it installs to: ~/.local/bin is not on PATH yet"
    assert re.search(r"\bpipx install\b", head), head
    assert commands[1] == "bash scripts/run-tests"
    ci = (REPO / ".ci" / "run").read_text(encoding="utf-8")
    assert re.search(r"^exec bash scripts/run-tests\b", ci, re.M), "CI must run the README's tests"


# --------------------------------------------------------------------------- absolute paths
def test_the_sudo_command_runs_without_the_users_path(tmp_path):
    """sudo resets the environment (PATH = secure_path, HOME = root's): what it runs must be named
    by its absolute path and still find the package."""
    argv = privilege.sudo_argv(["--version"])
    assert argv[0] == "sudo"
    assert Path(argv[1]).is_absolute() and argv[1] == sys.executable and argv[2:4] == [
        "-m", "rosnet_tui"]
    r = subprocess.run(argv[1:], env={"PATH": SECURE_PATH, "HOME": str(tmp_path)},
                       cwd=privilege.package_root(), capture_output=True, text=True, timeout=60,
                       stdin=subprocess.DEVNULL)
    assert r.returncode == 0 and r.stdout.strip() == VERSION_LINE, r.stderr


def _unit_for(tmp_path: Path) -> tuple[list[str], dict[str, str]]:
    """(ExecStart's words, the Environment= variables) of the system unit for a settings file."""
    cfg = tmp_path / "config.toml"
    cfg.write_text(ROBOT_CONFIG)
    args = build_parser(["sync"]).parse_args(["sync", "install-service", "--config", str(cfg)])
    text, _ = sync_cli.unit_text(args, user=False)
    (exec_line,) = [x for x in text.splitlines() if x.startswith("ExecStart=")]
    env = dict(shlex.split(x.partition("=")[2])[0].split("=", 1)
               for x in text.splitlines() if x.startswith("Environment="))
    return shlex.split(exec_line.partition("=")[2]), env


def test_the_unit_runs_in_systemds_clean_environment(tmp_path):
    """ExecStart names the interpreter of this very install by its absolute path; with only the
    unit's own Environment= lines, from /, it runs."""
    argv, env = _unit_for(tmp_path)
    assert argv[0] == sys.executable and Path(argv[0]).is_absolute()
    assert argv[1:3] == ["-m", "rosnet_tui"]
    r = subprocess.run([*argv[:3], "--version"], env={"PATH": SECURE_PATH, **env}, cwd="/",
                       capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)
    assert r.returncode == 0 and r.stdout.strip() == VERSION_LINE, r.stderr


def test_the_sudo_line_for_the_unit_names_the_users_settings(tmp_path, monkeypatch):
    """Under sudo ~ is root's home: the printed line must carry the settings file the user meant
    (here the default one, no --config given), or root writes a unit for root's settings."""
    home = tmp_path / "home"
    cfg = home / ".config" / "rosnet-tui" / "config.toml"
    cfg.parent.mkdir(parents=True)
    cfg.write_text(ROBOT_CONFIG)
    units = tmp_path / "units"
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.setenv("XDG_CONFIG_HOME", str(home / ".config"))
    args = build_parser(["sync"]).parse_args(
        ["sync", "install-service", "--unit-dir", str(units), "--yes"])
    argv = sync_cli.sudo_install_argv(args)
    assert argv[:4] == ["sudo", sys.executable, "-m", "rosnet_tui"]
    assert argv[4:6] == ["--config", str(cfg)]
    assert argv[argv.index("--unit-dir") + 1] == str(units) and "--yes" in argv
    # What root runs: sudo's environment (another HOME, secure_path), from where sudo runs it.
    root_home = tmp_path / "roothome"
    root_home.mkdir()
    r = subprocess.run(argv[1:], env={"PATH": SECURE_PATH, "HOME": str(root_home)},
                       cwd=privilege.package_root(), capture_output=True, text=True,
                       timeout=60, stdin=subprocess.DEVNULL)
    assert r.returncode == 0, r.stderr
    unit = (units / sync_cli.UNIT_NAME).read_text()
    assert f"--config {cfg} " in unit and str(root_home) not in unit


# --------------------------------------------------------------------------- a new user
def _sudoers_word(word: str) -> str:
    return re.sub(r"([\\,:=\s])", r"\\\1", word)


class NewUser:
    """A throwaway normal user with a fresh HOME, removed (with its HOME) by :meth:`remove`."""

    def __init__(self) -> None:
        self.name = f"rosnet-ci-{os.getpid()}"
        try:
            pwd.getpwnam(self.name)
            pytest.skip(f"a user {self.name} already exists")
        except KeyError:
            pass
        subprocess.run(["useradd", "--create-home", "--shell", "/bin/bash", "--comment",
                        "rosnet-tui install test (temporary)", self.name],
                       check=True, capture_output=True, timeout=30)
        pw = pwd.getpwnam(self.name)
        self.uid, self.gid, self.home = pw.pw_uid, pw.pw_gid, Path(pw.pw_dir)
        self.sudoers = Path("/etc/sudoers.d") / self.name
        self.rules: list[str] = []

    def allow(self, *argv: str) -> None:
        """Let this user run exactly *argv* (any arguments when only a program) as root."""
        self.rules.append(f"{self.name} ALL=(root) NOPASSWD: "
                          + " ".join(_sudoers_word(a) for a in argv))
        # sudo reads /etc/sudoers.d/NAME; a name with a dot is ignored, so the draft is safe.
        draft = self.sudoers.with_name(f".{self.name}.draft")
        draft.write_text("\n".join(self.rules) + "\n")
        os.chmod(draft, 0o440)
        check = subprocess.run(["visudo", "-c", "-q", "-f", str(draft)], capture_output=True,
                               text=True, timeout=30)
        if check.returncode != 0:
            draft.unlink()
            raise AssertionError(f"bad sudoers rule: {check.stdout}{check.stderr}")
        os.replace(draft, self.sudoers)

    def chown_tree(self, top: Path) -> None:
        for d, dirs, files in os.walk(top):
            for n in (d, *[os.path.join(d, x) for x in dirs + files]):
                os.lchown(n, self.uid, self.gid)

    def env(self, **extra: str) -> list[str]:
        pairs = {"HOME": str(self.home), "USER": self.name, "LOGNAME": self.name,
                 "SHELL": "/bin/bash", "PATH": USER_PATH, "LANG": "C.UTF-8", **extra}
        return ["env", "-i", *[f"{k}={v}" for k, v in pairs.items()]]

    def argv(self, script: str, **env: str) -> list[str]:
        return ["runuser", "-u", self.name, "--", *self.env(**env), "bash", "-c", script]

    def run(self, script: str, *, cwd: Path | None = None, timeout: float = 120,
            etc_hosts: Path | None = None) -> subprocess.CompletedProcess:
        """*script* in bash as this user, in a clean login-like environment; bounded. With
        *etc_hosts*, in a mount namespace of its own where that file is /etc/hosts."""
        argv = self.argv(script)
        if etc_hosts is not None:
            argv = ["unshare", "--mount", "--propagation", "private", "--", "sh", "-c",
                    'mount --bind "$0" /etc/hosts && exec "$@"', str(etc_hosts), *argv]
        proc = subprocess.Popen(argv, cwd=cwd or self.home, stdin=subprocess.DEVNULL,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                start_new_session=True)
        try:
            out, err = proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            out, err = proc.communicate(timeout=10)
            raise AssertionError(f"timed out after {timeout}s: {script}\n{out}\n{err}") from None
        return subprocess.CompletedProcess(script, proc.returncode, out, err)

    def remove(self) -> None:
        self.sudoers.unlink(missing_ok=True)
        self.sudoers.with_name(f".{self.name}.draft").unlink(missing_ok=True)
        # what it left running (a warm process of rosnet-tui check) would keep userdel off
        subprocess.run(["pkill", "-KILL", "-u", self.name], capture_output=True, timeout=30)
        for _ in range(100):
            if subprocess.run(["pgrep", "-u", self.name], capture_output=True,
                              timeout=30).returncode != 0:
                break
            time.sleep(0.05)
        subprocess.run(["userdel", "--remove", self.name], capture_output=True, timeout=60)
        shutil.rmtree(self.home, ignore_errors=True)
        shutil.rmtree(f"/tmp/rosnet-tui-{self.uid}", ignore_errors=True)


def _copy_checkout(dest: Path) -> None:
    """The checkout as the user would have it (a clone): sources, no caches, no git data."""
    shutil.copytree(REPO, dest, symlinks=True, ignore=shutil.ignore_patterns(
        ".git", "__pycache__", "*.pyc", ".pytest_cache", ".ruff_cache", ".hypothesis",
        "*.egg-info", ".venv", "build", "dist"))


def _open_wizard(user: NewUser, program: str, timeout: float = 60) -> tuple[int, bytes]:
    """Start the installed wizard on a pseudo-terminal as *user*, wait for its set-up screen,
    quit with Ctrl+Q; (exit code, what it drew)."""
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 80, 0, 0))
    proc = subprocess.Popen(user.argv(f"exec {program}", TERM="xterm-256color"), cwd=user.home,
                            stdin=slave, stdout=slave, stderr=slave, start_new_session=True)
    os.close(slave)
    seen, next_quit = b"", None
    deadline = time.monotonic() + timeout
    try:
        while time.monotonic() < deadline:
            if proc.poll() is not None:
                break
            r, _, _ = select.select([master], [], [], 0.2)
            if r:
                try:
                    seen += os.read(master, 65536)
                except OSError:
                    break
            # Ctrl+Q once the set-up screen is drawn, again each second until the wizard
            # ends (the event waited on; no guess at when it reads keys): a Ctrl+Q that came
            # too early is sent again, one that worked leaves nothing to send it to
            if b"set-up" in seen and (next_quit is None or time.monotonic() >= next_quit):
                with contextlib.suppress(OSError):     # the wizard may have just ended
                    os.write(master, b"\x11")
                next_quit = time.monotonic() + 1.0
        rc = proc.wait(timeout=max(1.0, deadline - time.monotonic()))
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
        rc = -1
    finally:
        os.close(master)
    return rc, seen


@pytest.mark.skipif(os.geteuid() != 0, reason="needs root: it creates a throwaway user")
@pytest.mark.skipif(not SYSTEM_PYTHON.exists(), reason="no distribution Python at /usr/bin/python3")
@pytest.mark.skipif(not Path("/usr/bin/apt").exists(), reason="not a Debian/Ubuntu system")
@pytest.mark.skipif(not all(shutil.which(t) for t in ("sudo", "useradd", "userdel", "runuser",
                                                       "visudo", "unshare")),
                    reason="needs sudo, useradd, userdel, runuser, visudo and unshare "
                           "(scripts/run-tests installs sudo)")
def test_the_readme_install_line_as_a_new_user_on_the_system_python():
    install, program = install_line()
    user = NewUser()
    scratch = Path(tempfile.mkdtemp(prefix="rosnet-install-"))   # root's, as /etc would be
    try:
        os.chmod(scratch, 0o755)
        # Whatever the line runs with sudo, this user may run (and nothing else).
        for part in install.split(" && "):
            words = shlex.split(part)
            if words[0] == "sudo":
                prog = shutil.which(words[1], path=SECURE_PATH)
                assert prog, f"{words[1]} is not on sudo's secure_path"
                user.allow(prog, *words[2:])
        checkout = user.home / "rosnet_tui"
        _copy_checkout(checkout)
        user.chown_tree(checkout)

        # 1. The README's line, as written, minus opening the wizard.
        t0 = time.monotonic()
        r = user.run(install, cwd=checkout, timeout=600)
        took = time.monotonic() - t0
        assert r.returncode == 0, f"the README's install line failed:\n{r.stdout}\n{r.stderr}"
        print(f"install line: {took:.1f}s")

        # 2. From where it installed, anywhere, without ~/.local/bin on PATH.
        r = user.run(f"{program} --version", timeout=60)
        assert r.returncode == 0 and r.stdout.strip() == VERSION_LINE, r.stderr
        r = user.run(f"{program} check --help", timeout=60)
        assert r.returncode == 0 and "usage: rosnet-tui check" in r.stdout, r.stderr

        # ... on the distribution's Python, in a virtual environment of its own.
        script = Path(os.path.realpath(user.home / ".local" / "bin" / "rosnet-tui"))
        python = script.read_text().splitlines()[0].removeprefix("#!").strip()
        venv = Path(python).parent.parent
        assert user.home in venv.parents, venv
        cfg = dict(line.split(" = ", 1) for line in
                   (venv / "pyvenv.cfg").read_text().splitlines() if " = " in line)
        assert Path(cfg["home"]) == SYSTEM_PYTHON.parent, cfg
        system_version = subprocess.run(
            [str(SYSTEM_PYTHON), "-c", "import platform; print(platform.python_version())"],
            capture_output=True, text=True, timeout=30).stdout.strip()
        assert cfg.get("version", cfg.get("version_info")) == system_version, cfg

        # 3. The wizard opens on a terminal (the set-up screen: no settings yet), Ctrl+Q quits.
        rc, drawn = _open_wizard(user, program)
        assert b"set-up" in drawn, drawn[-2000:]
        assert rc == 0, drawn[-2000:]

        # 4. /etc/hosts (this run's own, in a mount namespace) is written through sudo, by this
        #    very install, and the change is undone through sudo too.
        user.allow(python)
        settings = user.home / ".config" / "rosnet-tui" / "config.toml"
        settings.parent.mkdir(parents=True, exist_ok=True)
        settings.write_text(ROBOT_CONFIG)
        user.chown_tree(user.home / ".config")
        hosts = scratch / "hosts"
        hosts.write_bytes(HOSTS)
        os.chmod(hosts, 0o644)
        r = user.run(f"{program} hosts apply --yes --no-checks", etc_hosts=hosts)
        assert r.returncode == 0, f"{r.stdout}\n{r.stderr}"
        assert f"sudo {python} -m rosnet_tui --config {settings} hosts apply" in r.stdout
        written = hosts.read_bytes()
        assert b"# BEGIN rosnet-tui" in written and b"198.51.100.2" in written
        assert os.stat(hosts).st_uid == 0
        journal = user.home / ".local" / "state" / "rosnet-tui" / "journal"
        assert all(p.stat().st_uid == user.uid for p in journal.iterdir())
        r = user.run(f"{program} undo --yes --no-checks", etc_hosts=hosts)
        assert r.returncode == 0, f"{r.stdout}\n{r.stderr}"
        assert f"sudo {python} -m rosnet_tui undo" in r.stdout
        assert hosts.read_bytes() == HOSTS

        # 5. The system unit: refused as the user, with the sudo line to run; that line, run as
        #    printed, writes the unit for this user's settings, naming this install's Python.
        units = scratch / "units"
        units.mkdir(mode=0o755)
        r = user.run(f"{program} sync install-service --unit-dir {units} --yes", timeout=120)
        assert r.returncode == 1 and "run it with sudo: " in r.stderr, r.stderr
        line = r.stderr.split("run it with sudo: ", 1)[1].strip().splitlines()[0]
        assert shlex.split(line)[:2] == ["sudo", python], line
        r = user.run(line, timeout=120)
        assert r.returncode == 0, f"{line}\n{r.stdout}\n{r.stderr}"
        unit = (units / sync_cli.UNIT_NAME).read_text()
        (exec_line,) = [x for x in unit.splitlines() if x.startswith("ExecStart=")]
        argv = shlex.split(exec_line.partition("=")[2])
        assert argv == [python, "-m", "rosnet_tui", "--config", str(settings), "sync",
                        "--state-dir", str(user.home / ".local" / "state" / "rosnet-tui"),
                        "--bashrc", str(user.home / ".bashrc")], exec_line
        assert "PYTHONPATH" not in unit
        # As systemd starts it: root, a clean environment, from /.
        r = subprocess.run([*argv[:3], "--version"], env={"PATH": SECURE_PATH}, cwd="/",
                           capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)
        assert r.returncode == 0 and r.stdout.strip() == VERSION_LINE, r.stderr

        # 6. The checks again: the second run is served by the warm process the first one left,
        #    this install's Python in the user's own socket folder.
        _served_by_a_warm_process(user, program)
    finally:
        user.remove()
        shutil.rmtree(scratch, ignore_errors=True)
    assert not user.home.exists() and not user.sudoers.exists()
    with pytest.raises(KeyError):
        pwd.getpwnam(user.name)


def _served_by_a_warm_process(user: NewUser, program: str) -> None:
    asked: list[int] = []       # the parent of each process that asked the service

    def note(client: tuple[str, int]) -> None:
        for c in psutil.net_connections(kind="tcp4"):
            if c.laddr and (c.laddr.ip, c.laddr.port) == tuple(client) and c.pid:
                with contextlib.suppress(psutil.Error):
                    asked.append(psutil.Process(c.pid).ppid())
                return
        asked.append(0)

    web = WebServer()
    web.routes["/ip"] = (200, "203.0.113.9\n")
    web.on_request = note
    try:
        folder = user.home / "checks"
        folder.mkdir()
        loopback_master_config(folder, web.url("/ip"), "http://127.0.0.1:9")
        user.chown_tree(folder)
        run = f"{program} check --step isp --json --no-upnp --config {folder}/config.toml"
        first = user.run(run, timeout=60)
        assert first.returncode == 0, first.stderr
        sockets = Path(f"/tmp/rosnet-tui-{user.uid}")
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and not list(sockets.glob("warm-*.sock")):
            time.sleep(0.05)
        (sock,) = sockets.glob("warm-*.sock")
        assert sock.stat().st_uid == user.uid and (sockets.stat().st_mode & 0o777) == 0o700
        servers = [p.pid for p in psutil.process_iter(["cmdline", "uids"])
                   if p.info["uids"] and p.info["uids"].real == user.uid
                   and any("serve_warm" in c for c in p.info["cmdline"] or [])]
        assert len(servers) == 1, servers
        second = user.run(run, timeout=60)
        assert second.returncode == 0, second.stderr
        assert asked[-1] == servers[0], (asked, servers)
        verdicts = [[(c["id"], c["status"]) for c in json.loads(r.stdout)["checks"]]
                    for r in (first, second)]
        assert verdicts[0] == verdicts[1]
    finally:
        web.close()


# --------------------------------------------------------------------------- lowest Python
def _lowest_claimed() -> tuple[int, int]:
    text = (REPO / "pyproject.toml").read_text(encoding="utf-8")
    m = re.search(r'^requires-python\s*=\s*">=\s*(\d+)\.(\d+)"', text, re.M)
    assert m, "requires-python must state a lowest version: '>=X.Y'"
    return int(m.group(1)), int(m.group(2))


def _find_python(major: int, minor: int) -> str | None:
    """An interpreter of exactly that version that runs (a pyenv build, or python3.X on PATH)."""
    name = f"python{major}.{minor}"
    pyenv = Path(os.environ.get("PYENV_ROOT", Path.home() / ".pyenv")) / "versions"
    found = [str(p) for p in sorted(pyenv.glob(f"{major}.{minor}.*/bin/{name}"), reverse=True)]
    found.append(shutil.which(name))
    for p in filter(None, found):
        try:
            r = subprocess.run([p, "-c", "import sys; print(*sys.version_info[:2])"],
                               capture_output=True, text=True, timeout=20)
        except (OSError, subprocess.TimeoutExpired):
            continue
        if r.returncode == 0 and r.stdout.split() == [str(major), str(minor)]:
            return p
    return None


def test_requires_python_and_classifiers_agree():
    major, minor = _lowest_claimed()
    text = (REPO / "pyproject.toml").read_text(encoding="utf-8")
    listed = re.findall(r'"Programming Language :: Python :: 3\.(\d+)"', text)
    assert listed and min(int(x) for x in listed) == minor and major == 3, listed


LOWEST_PYTHON_TESTS = ["tests/test_settings.py", "tests/test_cli_basics.py",
                       "tests/test_cli_writers.py", "tests/test_sync.py"]


@pytest.mark.skipif(_find_python(*_lowest_claimed()) is None,
                    reason="no interpreter of the lowest claimed Python version here "
                           "(python3.X on PATH or pyenv)")
def test_the_lowest_claimed_python_installs_and_passes(tmp_path):
    """requires-python is honest: on that very version the package installs, starts, and part of
    the suite passes."""
    python = _find_python(*_lowest_claimed())
    venv = tmp_path / "venv"
    subprocess.run([python, "-m", "venv", str(venv)], check=True, timeout=120,
                   capture_output=True)
    vpy = str(venv / "bin" / "python")
    r = subprocess.run([vpy, "-m", "pip", "install", "-q", "--disable-pip-version-check",
                        f"{REPO}[test]"], capture_output=True, text=True, timeout=400,
                       stdin=subprocess.DEVNULL)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    clean = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    r = subprocess.run([str(venv / "bin" / "rosnet-tui"), "--version"], env=clean, cwd="/",
                       capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)
    assert r.returncode == 0 and r.stdout.strip() == VERSION_LINE, r.stderr
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTEST_")}
    env["PYTHONPATH"] = str(REPO)
    r = subprocess.run([vpy, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-m", "not lab",
                        *LOWEST_PYTHON_TESTS], env=env, cwd=REPO, capture_output=True,
                       text=True, timeout=400, stdin=subprocess.DEVNULL)
    tail = "\n".join(r.stdout.splitlines()[-15:])
    assert r.returncode == 0, tail + r.stderr[-2000:]
    print(f"{python}: {tail.splitlines()[-1]}")
