"""The Zenoh peer program runs with the rosnet-tui installed on the peer (issue 21).

The README installs rosnet-tui with pipx (or uv, or a root-owned pipx) in a virtual environment of
its own; the peer's python3 has no eclipse-zenoh. commands.zenoh_peer_command is a POSIX sh prelude
that finds that installation's interpreter and execs it on the program fed on stdin, in the one
SSH round trip. These tests run that very command with the real ``sh`` (dash) in throwaway homes
laid out as pipx, uv and pip lay them out, with real virtual environments.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from rosnet_tui.core.checks.probes.ros2 import zenoh_peer_problem
from rosnet_tui.core.config.settings_model import Peer
from rosnet_tui.core.peer import commands, zenohproto
from rosnet_tui.core.ssh.connection import SshResult

SRC = Path(zenohproto.__file__).read_bytes()
ROOT_INSTALLS = (Path("/usr/local/bin/rosnet-tui"), Path("/opt/pipx/venvs/rosnet-tui"))


def venv(path: Path) -> Path:
    """A real virtual environment at *path* whose Python has eclipse-zenoh (this one's
    site-packages), with a ``rosnet-tui`` launcher as pip writes it; *path* itself."""
    path.parent.mkdir(parents=True, exist_ok=True)
    subprocess.run([sys.executable, "-m", "venv", "--system-site-packages", "--without-pip",
                    str(path)], check=True, timeout=60)
    launcher = path / "bin" / "rosnet-tui"
    launcher.write_text(f"#!{path}/bin/python\nimport sys\nfrom rosnet_tui.cli import main\n"
                        "sys.exit(main())\n")
    launcher.chmod(0o755)
    return path


def run(cmd: str, home: Path, timeout: float = 30, **env: str) -> tuple[dict | None, int, float]:
    full = {"HOME": str(home), "PATH": "/usr/bin:/bin", "SHELL": "/bin/sh", **env}
    t0 = time.monotonic()
    r = subprocess.run(["/bin/sh", "-c", cmd], input=SRC, capture_output=True, timeout=timeout,
                       env=full, cwd=home)
    return zenohproto.parse_report(r.stdout.decode()), r.returncode, time.monotonic() - t0


def no_root_install() -> None:
    if any(p.exists() for p in ROOT_INSTALLS):
        pytest.skip("this machine has a root-owned rosnet-tui install")


def test_pipx_layout_runs_the_venvs_python_not_the_path_python3(tmp_path):
    home = tmp_path / "home"
    v = venv(home / ".local/share/pipx/venvs/rosnet-tui")
    (home / ".local/bin").mkdir(parents=True)
    (home / ".local/bin/rosnet-tui").symlink_to(v / "bin" / "rosnet-tui")
    rep, rc, _ = run(commands.zenoh_peer_command("info"), home)
    assert rc == 0 and rep is not None, rep
    assert rep["python"] == f"{v}/bin/python", rep


@pytest.mark.parametrize("quote", ['"', "'"])
def test_the_sh_launcher_pip_and_uv_write_for_long_paths(tmp_path, quote):
    """pip (distlib) writes ``'''exec' "python"``, uv ``'''exec' 'python'`` when the shebang
    would be too long or hold a space; the interpreter is read from the second line."""
    home = tmp_path / "home"
    far = venv(tmp_path / ("a long and spaced " + "x" * 120) / "rosnet-tui")
    py = f"{far}/bin/python"
    launcher = home / ".local/bin/rosnet-tui"
    launcher.parent.mkdir(parents=True)
    launcher.write_text(f"#!/bin/sh\n'''exec' {quote}{py}{quote} \"$0\" \"$@\"\n' '''\n"
                        "import sys\n")
    launcher.chmod(0o755)
    rep, rc, _ = run(commands.zenoh_peer_command("info"), home)
    assert rc == 0 and rep is not None and rep["python"] == py, rep


def test_a_launcher_is_also_found_on_the_path_and_in_a_login_shell(tmp_path):
    no_root_install()
    home = tmp_path / "home"
    v = venv(tmp_path / "apps" / "rosnet-tui")
    bindir = tmp_path / "apps" / "bin"
    bindir.mkdir()
    (bindir / "rosnet-tui").symlink_to(v / "bin" / "rosnet-tui")
    home.mkdir()
    rep, _, _ = run(commands.zenoh_peer_command("info"), home, PATH=f"/usr/bin:/bin:{bindir}")
    assert rep is not None and rep["python"] == f"{v}/bin/python", rep
    (home / ".profile").write_text(f'PATH="{bindir}:$PATH"\necho a line from .profile\n')
    rep, _, _ = run(commands.zenoh_peer_command("info"), home)
    assert rep is not None and rep["python"] == f"{v}/bin/python", rep


def test_pipx_home_and_uv_tool_dir_are_honoured(tmp_path):
    home = tmp_path / "home"
    home.mkdir()
    v = venv(tmp_path / "pipx" / "venvs" / "rosnet-tui")
    rep, _, _ = run(commands.zenoh_peer_command("info"), home, PIPX_HOME=str(tmp_path / "pipx"))
    assert rep is not None and rep["python"] == f"{v}/bin/python", rep
    u = venv(home / ".local/share/uv/tools/rosnet-tui")   # uv's default
    rep, _, _ = run(commands.zenoh_peer_command("info"), home)
    assert rep is not None and rep["python"] == f"{u}/bin/python", rep


def test_the_installed_python_imports_zenoh(tmp_path):
    """The peer program gets as far as a Zenoh session: no "no eclipse-zenoh" from the venv."""
    home = tmp_path / "home"
    v = venv(home / ".local/share/pipx/venvs/rosnet-tui")
    cmd = commands.zenoh_peer_command("graph", "--timeout", "1", "--local", "tcp/127.0.0.1:9")
    rep, _, _ = run(cmd, home)
    assert rep is not None and rep.get("error") == "open" and rep["python"] == f"{v}/bin/python"


def test_nothing_installed_skips_naming_the_readme_line_and_never_pip(tmp_path):
    no_root_install()
    home = tmp_path / "home"
    home.mkdir()
    (home / ".profile").write_text("sleep 30\n")    # a login shell that hangs is cut short
    rep, rc, took = run(commands.zenoh_peer_command("graph", "--timeout", "1"), home)
    assert rc == commands.NO_INSTALL_EXIT and rep == {"error": "no_install",
                                                    "detail": "no rosnet-tui installed"}
    assert took < 5, took
    res = SshResult(ok=True, exit_status=rc, stdout="", stderr="", failure=None, detail="",
                    fingerprint=None)
    why = zenoh_peer_problem(res, Peer(name="turtlebot"), rep)
    assert why is not None and "rosnet-tui is not installed on turtlebot" in why, why
    assert f"`{commands.README_INSTALL}`" in why and "pip install" not in why.replace("pipx", "")
    # info needs the standard library only: the peer's python3 answers it
    rep, rc, _ = run(commands.zenoh_peer_command("info", need_zenoh=False), home)
    assert rc == 0 and rep is not None and "env" in rep and rep["python"].startswith("/usr/bin/")


def test_no_advice_anywhere_to_pip_install_into_a_python():
    """PEP 668 refuses it, and the package comes with rosnet-tui anyway."""
    root = Path(commands.__file__).resolve().parents[3]
    bad = []
    for path in (root / "rosnet_tui").rglob("*.py"):
        for n, line in enumerate(path.read_text().splitlines(), 1):
            low = line.lower().replace("pipx install", "")
            if "pip install" in low or "pip3 install" in low:
                bad.append(f"{path.relative_to(root)}:{n}: {line.strip()}")
    assert not bad, bad


def test_the_program_reaches_the_interpreter_whole(tmp_path):
    """The prelude reads nothing from stdin (a big program arrives complete)."""
    home = tmp_path / "home"
    venv(home / ".local/share/pipx/venvs/rosnet-tui")
    big = SRC + b"\n" + b"#" * 200_000 + b"\n"
    r = subprocess.run(["/bin/sh", "-c", commands.zenoh_peer_command("info")], input=big,
                       capture_output=True, timeout=30,
                       env={"HOME": str(home), "PATH": "/usr/bin:/bin", "SHELL": "/bin/sh"})
    assert zenohproto.parse_report(r.stdout.decode()) is not None, r.stderr


def test_the_labs_readme_install_runs_from_any_home_even_a_long_one(tmp_path):
    """tests/lab/readme_install.py: the cached build copied into a home whose path is too long
    for a ``#!`` line gets pip's ``#!/bin/sh`` launcher, which both the shell and the prelude
    follow; the copy's Python has eclipse-zenoh, and /usr/bin/python3 still has none."""
    from tests.lab import readme_install

    home = tmp_path / ("h" * 100) / "home"
    launcher = readme_install.install(home)
    venv_python = f"{home / readme_install.VENV}/bin/python"
    target = launcher.resolve().read_text().splitlines()
    assert target[0] == "#!/bin/sh" and venv_python in target[1], target[:3]
    r = subprocess.run([str(launcher), "--version"], capture_output=True, text=True, timeout=60,
                       env={"PATH": "/usr/bin:/bin", "HOME": str(home)})
    assert r.returncode == 0 and r.stdout.startswith("rosnet-tui "), r.stderr
    cmd = commands.zenoh_peer_command("graph", "--timeout", "1", "--local", "tcp/127.0.0.1:9")
    rep, _, _ = run(cmd, home)
    assert rep is not None and rep.get("error") == "open" and rep["python"] == venv_python, rep
    sys_py = subprocess.run(["/usr/bin/python3", "-c", "import zenoh"], capture_output=True,
                            timeout=30)
    assert sys_py.returncode != 0
    assert readme_install.install(home) == launcher          # installed already: kept
    readme_install.uninstall(home)
    assert not readme_install.installed(home) and not (home / readme_install.VENV).exists()


def test_installed_python_command_serves_any_program_with_its_own_mark(tmp_path):
    """The install prelude, generalised (issue 22: the SSH audit needs the install's paramiko):
    another program's mark in the no_install report, the installed interpreter otherwise."""
    no_root_install()
    home = tmp_path / "home"
    home.mkdir()
    cmd = commands.installed_python_command("x", mark="ROSNET_SSHAUDIT ")
    r = subprocess.run(["/bin/sh", "-c", cmd], input=b"print('ran')", capture_output=True,
                       timeout=30, env={"HOME": str(home), "PATH": "/usr/bin:/bin",
                                        "SHELL": "/bin/sh"}, cwd=home)
    assert r.returncode == commands.NO_INSTALL_EXIT, r
    assert r.stdout.decode().startswith('ROSNET_SSHAUDIT {"error": "no_install"'), r.stdout
    v = venv(home / ".local/share/pipx/venvs/rosnet-tui")
    (home / ".local/bin").mkdir(parents=True)
    (home / ".local/bin/rosnet-tui").symlink_to(v / "bin" / "rosnet-tui")
    r = subprocess.run(["/bin/sh", "-c", cmd], input=b"import sys; print(sys.executable)",
                       capture_output=True, timeout=30, env={"HOME": str(home),
                                                             "PATH": "/usr/bin:/bin"}, cwd=home)
    assert r.returncode == 0 and r.stdout.decode().strip() == f"{v}/bin/python", r


def _fake_build(cache: Path, name: str, age_s: float = 0.0) -> Path:
    """A cached build as built_venv() leaves it (a launcher, pyvenv.cfg, the prefix file), last
    used *age_s* ago."""
    from tests.lab import readme_install

    b = cache / f"venv-{name}"
    (b / "bin").mkdir(parents=True)
    (b / "bin" / "rosnet-tui").write_text(f"#!{b}/bin/python\nprint('hi')\n")
    (b / "pyvenv.cfg").write_text(f"home = /usr/bin\ncommand = {b}\n")
    (b / readme_install.PREFIX_FILE).write_text(str(b))
    t = time.time() - age_s
    os.utime(b, (t, t))
    return b


def test_the_labs_install_survives_another_trees_prune_of_its_build(tmp_path, monkeypatch):
    """Lab install cache race: install() got its build's path outside any lock, and another
    pytest process (another source tree) pruning the cache (KEEP newest) removed it before the
    link: FileNotFoundError. Now it links under the shared lock and builds again when the build
    vanished; and a build installed from recently is never pruned."""
    from tests.lab import readme_install as ri

    cache = tmp_path / "cache"
    monkeypatch.setattr(ri, "CACHE", cache)
    ours = _fake_build(cache, "ours", age_s=7200)
    others = [_fake_build(cache, f"new{i}") for i in range(ri.KEEP)]
    calls = []

    def built_venv():                      # another process prunes right after we got the path
        calls.append(1)
        if len(calls) == 1:
            with ri.locked(shared=False):
                ri.prune(keep=others[0])
            assert not ours.exists()       # the race: gone under us
            return ours
        return _fake_build(cache, f"again{len(calls)}", age_s=7200)   # built again

    monkeypatch.setattr(ri, "built_venv", built_venv)
    home = tmp_path / "home"
    launcher = ri.install(home)
    assert len(calls) == 2 and launcher.resolve().is_file()
    assert str(home / ri.VENV) in launcher.resolve().read_text().splitlines()[0]
    used = cache / "venv-again2"
    assert time.time() - used.stat().st_mtime < 60          # marked in use by the install
    for i in range(ri.KEEP + 1):                             # newer builds pile up ...
        _fake_build(cache, f"later{i}")
    with ri.locked(shared=False):
        ri.prune(keep=cache / "venv-later0")
    assert (used / ri.PREFIX_FILE).is_file()                # ... it is still spared
    stale = _fake_build(cache, "stale", age_s=2 * ri.PRUNE_GRACE_S)
    with ri.locked(shared=False):
        ri.prune(keep=cache / "venv-later0")
    assert not stale.exists()                                # old and unused: pruned
