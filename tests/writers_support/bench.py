"""rosnet-tui commands against an /etc/hosts that cannot be renamed over (issue 29 section 5).

:class:`HostsBench` makes a private mount namespace (``unshare -m``) where ``/etc`` is an overlay
whose changes land in the test's folder and ``/etc/hosts`` is a bind mount of ``src`` (a file in
the test's folder): writers take the in-place path, as in a container, and nothing reaches the
machine's own /etc. Commands run there through :mod:`.cmd_server`, each in a fresh process,
killed when asked. Needs root, unshare(1), mount(8) and overlayfs.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
NOBODY = 65534


def bench_problem() -> str | None:
    """Why the bench cannot run here (None: it can)."""
    if os.geteuid() != 0:
        return "needs root (mount namespaces, bind mounts)"
    for tool in ("unshare", "mount"):
        if not shutil.which(tool):
            return f"needs {tool}(8)"
    return None


@dataclass
class Ran:
    rc: int
    killed: bool
    out: str
    err: str


class HostsBench:
    def __init__(self, content: bytes, config: str) -> None:
        # Its own folder under /tmp (removed by stop()): pytest's is private to root, and a
        # user's run must read the settings.
        self.dir = folder = Path(tempfile.mkdtemp(prefix="rosnet-torn-"))
        os.chmod(folder, 0o755)
        for name in ("upper", "work", "home"):
            (folder / name).mkdir(mode=0o755)
        self.src = folder / "hosts-src"
        self.src.write_bytes(content)
        os.chmod(self.src, 0o644)
        self.config = folder / "config.toml"
        self.config.write_text(config)
        os.chmod(self.config, 0o644)
        self.home = folder / "home"
        self.proc: subprocess.Popen | None = None
        self.n = 0

    # ----------------------------------------------------------------- server
    def start(self) -> None:
        d = self.dir
        script = (f"mount -t overlay overlay -o lowerdir=/etc,upperdir={d}/upper,"
                  f"workdir={d}/work /etc && mount --bind {self.src} /etc/hosts && "
                  f"exec {sys.executable} -m tests.writers_support.cmd_server")
        env = {"PATH": os.environ.get("PATH", "/usr/bin:/bin"), "HOME": str(self.home),
               "PYTHONPATH": str(REPO), "LANG": "C.UTF-8",
               "ROSNET_TUI_STRICT_DATA": os.environ.get("ROSNET_TUI_STRICT_DATA", "1")}
        self.proc = subprocess.Popen(
            ["unshare", "-m", "--propagation", "private", "sh", "-c", script],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            env=env, cwd=REPO)
        line = self.proc.stdout.readline()
        if not line.startswith('{"ready"'):
            err = self.proc.stderr.read() if self.proc.poll() is not None else ""
            self.stop()
            if "Traceback" in err or line:
                raise RuntimeError(f"the command server did not start: {line!r} {err[-2000:]}")
            pytest.skip(f"cannot build the mount namespace here: {err.strip()[-500:]}")

    def stop(self) -> None:
        if self.proc is None:
            shutil.rmtree(self.dir, ignore_errors=True)
            return
        try:
            self.proc.stdin.close()
            self.proc.wait(timeout=20)
        except (OSError, subprocess.TimeoutExpired):
            self.proc.kill()
            self.proc.wait(timeout=10)
        for f in (self.proc.stdout, self.proc.stderr):
            f.close()
        self.proc = None
        shutil.rmtree(self.dir, ignore_errors=True)

    def __enter__(self) -> HostsBench:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    # ----------------------------------------------------------------- commands
    def run(self, *argv: str, crash: list | None = None, uid: int = 0,
            limit_s: float = 30.0) -> Ran:
        """Run ``rosnet-tui ARGV`` (a fresh process), killed as *crash* says; as *uid*."""
        assert self.proc is not None
        self.n += 1
        out, err = self.dir / f"run-{self.n}.out", self.dir / f"run-{self.n}.err"
        req = {"argv": list(argv), "crash": crash, "uid": uid, "limit_s": limit_s,
               "out": str(out), "err": str(err)}
        self.proc.stdin.write(json.dumps(req) + "\n")
        self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError(f"the command server died: {self.proc.stderr.read()[-2000:]}")
        ans = json.loads(line)
        ran = Ran(ans["rc"], ans["killed"], _read(out), _read(err))
        for f in (out, err):
            f.unlink(missing_ok=True)
        return ran

    def cfg(self) -> list[str]:
        return ["--config", str(self.config)]

    def journals(self) -> list[str]:
        """In-place journals left anywhere the writers put them (the overlay's /etc, states)."""
        return sorted(str(p.relative_to(self.dir)) for p in self.dir.rglob("*.inplace"))


def _read(p: Path) -> str:
    try:
        return p.read_text(errors="replace")
    except FileNotFoundError:
        return ""
