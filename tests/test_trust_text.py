"""Issue 35, findings 6 and 7: helper programs run isolated from a private folder; values
written into a shell file are quoted; texts from file names and records reach the terminal
without control characters."""

from __future__ import annotations

import asyncio
import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from rosnet_tui.core.checks.security import run_here
from rosnet_tui.core.config.settings_model import Peer, RosSettings, Settings, ThisComponent
from rosnet_tui.core.exposure import outsider
from rosnet_tui.core.peer import zenohproto
from rosnet_tui.core.peer.commands import (
    python_command,
    python_stdin_command,
    zenoh_peer_command,
)
from rosnet_tui.core.printable import printable
from rosnet_tui.core.ros import ros2
from rosnet_tui.core.sync.folder import FolderStore
from rosnet_tui.core.sync.status import empty_status, render_status

needs_bash = pytest.mark.skipif(not shutil.which("bash"), reason="bash is not installed")


# --------------------------------------------------------------------------- 6: python -I
def _plant(folder: Path) -> Path:
    marker = folder / "planted-ran"
    for mod in ("ssl", "json", "socket"):
        (folder / f"{mod}.py").write_text(f"open({str(marker)!r}, 'a').write('{mod}\\n')\n"
                                          "raise SystemExit(7)\n")
    return marker


def test_the_outsider_probe_never_runs_a_module_planted_where_the_caller_stands(
        tmp_path, monkeypatch):
    """A planted ssl.py in the caller's folder ran under `python -` (finding 6)."""
    marker = _plant(tmp_path)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("PYTHONPATH", str(tmp_path))        # nor through PYTHON* variables
    program = (b"import ssl, json, os, sys\n"
               b"import rosnet_tui.core.ros.fleet_tls\n"
               b"print('RAN', json.dumps([os.getcwd(), sys.flags.isolated]))\n")
    out, err = asyncio.run(run_here(program, [], 30))
    assert not marker.exists(), marker.read_text()
    line = next(x for x in out.splitlines() if x.startswith("RAN "))
    cwd, isolated = json.loads(line[4:])
    assert isolated == 1 and cwd != str(tmp_path) and not Path(cwd).exists(), (out, err)
    # and the real probe program still gives its verdict from there
    out, err = asyncio.run(run_here(outsider.tls_probe_program(),
                                    ["127.0.0.1", "9", "0.5"], 30))
    assert outsider.parse_marked(out, outsider.TLS_MARK) is not None, (out, err)
    # so does the SSH audit, whose program opens with `from __future__` (it must stay first)
    out, err = asyncio.run(run_here(outsider.SSH_AUDIT_PROGRAM.encode(),
                                    ["127.0.0.1", "9", "0.5", "nobody"], 30))
    assert outsider.parse_marked(out, outsider.SSH_MARK) is not None, (out, err)
    assert not marker.exists()


def test_the_programs_fed_to_peers_run_isolated(tmp_path):
    marker = _plant(tmp_path)
    for cmd in (python_command("import json; print('ok')"), python_stdin_command()):
        r = subprocess.run(["sh", "-c", cmd], input="import json; print('ok')\n",
                           capture_output=True, text=True, timeout=30, cwd=tmp_path,
                           env={"PATH": "/usr/bin:/bin", "PYTHONPATH": str(tmp_path)})
        assert r.stdout.strip() == "ok", (cmd, r.stdout, r.stderr)
    assert not marker.exists()
    # the Zenoh peer program, on the interpreter of the rosnet-tui installed there
    path = f"{Path(sys.executable).parent}:/usr/bin:/bin"
    r = subprocess.run(["sh", "-c", zenoh_peer_command("graph", "--timeout", "1")],
                       input=Path(zenohproto.__file__).read_text(), capture_output=True,
                       text=True, timeout=60, cwd=tmp_path,
                       env={"HOME": str(tmp_path), "PATH": path})
    assert zenohproto.parse_report(r.stdout) is not None, (r.stdout, r.stderr)
    assert not marker.exists(), marker.read_text()


# --------------------------------------------------------------------------- 7: quoting
def _member(**ros) -> Settings:
    return Settings(this=ThisComponent(name="sami", role="member", local_ip="192.168.1.10"),
                    peers=[Peer(name="turtlebot", public_ip="203.0.113.2")],
                    ros=RosSettings(master="turtlebot", version=2, **ros))


@needs_bash
@pytest.mark.parametrize("distro", ["", "jazzy", "humble"])
def test_ros2_lines_in_bashrc_are_quoted(tmp_path, distro):
    """A config path with ' and $(..) ran code at login (finding 7)."""
    marker = tmp_path / "pwned"
    evil = tmp_path / f"it's $(touch {marker}) `touch {marker}` here.json5"
    s = _member()
    for client in (False, True):
        lines = ros2.env_lines(s, client=client, router_config_path=evil,
                               session_config_path=evil, distro=distro)
        script = tmp_path / "rc"
        script.write_text("\n".join(lines) + "\n")
        names = [ln.split("=", 1)[0].split()[-1] for ln in lines]
        r = subprocess.run(["bash", "--norc", "--noprofile", "-c",
                            f"source {script}; " + "; ".join(
                                f'printf "%s\\n" "${n}"' for n in names)],
                           capture_output=True, text=True, timeout=10,
                           env={"PATH": "/usr/bin:/bin"})
        assert not marker.exists(), lines
        got = dict(zip(names, r.stdout.splitlines(), strict=True))
        for key in ("ZENOH_ROUTER_CONFIG_URI", "ZENOH_SESSION_CONFIG_URI"):
            if key in got:
                assert got[key] == str(evil)
        if "ZENOH_CONFIG_OVERRIDE" in got:
            assert got["ZENOH_CONFIG_OVERRIDE"] == ros2.client_override(s)


# --------------------------------------------------------------------------- 7: control chars
def test_printable_strips_c0_del_and_c1():
    assert printable("a\x1b]0;owned\x07b\x9b31mc\x7fd\ne") == "a?]0;owned?b?31mc?d?e"
    assert printable("Zoë 名") == "Zoë 名"


def test_sync_status_shows_no_escape_from_a_shared_folder_file_name(tmp_path):
    """A shared-folder file name reached `sync status` with raw terminal escapes (finding 7)."""
    folder = tmp_path / "shared"
    folder.mkdir()
    evil = "turtlebot (\x1b]0;pwned\x07\x1b[2J\x9b1m).json"
    (folder / evil).write_text("{not json")
    store = FolderStore(folder)
    res = store.fetch(["turtlebot"], "sami", {})
    assert res.refused, res
    st = empty_status()
    st["refused"] = [{"at": 0, "source": r.source, "name": r.name, "why": r.why}
                     for r in res.refused]
    st["peers"] = {"turtlebot\x1b[31m": {"record": {"role": "m\x1bx", "seq": 1}}}
    text = "\n".join(render_status(st, now=1.0))
    assert not any(ch in text for ch in "\x1b\x07\x9b"), repr(text)
    assert "turtlebot (?]0;pwned?" in text
