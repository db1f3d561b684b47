"""A loopback-only world for the rows that run anywhere (1, 4, 5): settings, a probe server, a tarpit.

Every address in these settings is on 127.0.0.0/8: this component is 127.0.0.1 on ``lo``, the peer
is 127.0.0.2 / 127.0.0.3 with no SSH user (so no check ever opens SSH, and no name is looked up in
DNS: the router step only uses IP literals), and the what-is-my-IP / port-check URLs point at the
product's own probe server on 127.0.0.1 (or at a tarpit there that accepts and never answers, to
make a check run into its timeout). The wizard opens on the ISP step and runs nothing by itself.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from bench.compiled import compiled_copy, run_compiled
from bench.pty_harness import PtyProcess

REPO = Path(__file__).resolve().parents[1]


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def base_env() -> dict[str, str]:
    """The environment for programs the bench starts: no proxies, no ROS, the repo importable."""
    env = {k: v for k, v in os.environ.items()
           if not k.startswith("ROS_") and not k.lower().endswith("_proxy")
           and k not in ("PYTHONHOME", "VIRTUAL_ENV", "TEXTUAL", "NO_COLOR")}
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO), env.get("PYTHONPATH")) if p)
    env["ROSNET_TUI_ALLOW_ROOT"] = "1"  # no "running as root" note before the first frame
    env.pop("TEXTUAL_DEBUG", None)
    return env


def write_settings(path: Path, *, probe_url: str, public_ip_url: str, test_port: int,
                   timeout_s: float = 3.0) -> None:
    """A complete settings file pointing only at loopback addresses."""
    from rosnet_tui.core.config.settings_model import Peer, ThisComponent
    from rosnet_tui.core.saved.settings import atomic_write_text, render_settings
    from tests.builders import checked_settings

    s = checked_settings(
        ThisComponent(name="benchbox", role="master", connection="home", profile="remote",
                      local_ip="127.0.0.1", public_ip="127.0.0.1", interface="lo"),
        [Peer(name="benchpeer", local_ip="127.0.0.2", public_ip="127.0.0.3", ssh_user="")],
        "benchbox", probe_port=test_port, public_ip_url=public_ip_url, port_check_url=probe_url,
        timeout_s=timeout_s)
    problems = s.problems()
    if problems:
        raise RuntimeError(f"bench settings are not complete: {problems}")
    atomic_write_text(path, render_settings(s), mode=0o600)


class Tarpit:
    """A TCP server on 127.0.0.1 that accepts connections and never says a word (bounded life)."""

    def __init__(self, max_life_s: float = 600.0) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(64)
        self.sock.settimeout(0.2)
        self.port = self.sock.getsockname()[1]
        self._held: list[socket.socket] = []
        self._stop = threading.Event()
        self._deadline = time.monotonic() + max_life_s
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        while not self._stop.is_set() and time.monotonic() < self._deadline:
            try:
                conn, _ = self.sock.accept()
            except (TimeoutError, OSError):
                continue
            self._held.append(conn)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2)
        for c in self._held:
            with contextlib.suppress(OSError):
                c.close()
        with contextlib.suppress(OSError):
            self.sock.close()


@dataclass
class LocalWorld:
    """Temp XDG folders with a complete loopback settings file, a probe server and a tarpit."""

    root: Path
    config: Path            # settings: probe server on 127.0.0.1 (checks finish quickly)
    config_slow: Path       # settings: probe URLs at the tarpit (router.port_open times out)
    probe_port: int
    tarpit: Tarpit
    probe: subprocess.Popen
    package: Path | None = None  # rosnet-tui byte-compiled, as installed (bench/compiled.py)

    def env(self) -> dict[str, str]:
        env = base_env()
        env["XDG_CONFIG_HOME"] = str(self.root / "config")
        env["XDG_STATE_HOME"] = str(self.root / "state")
        env["HOME"] = str(self.root / "home")
        return env

    def fresh_state(self) -> None:
        """Forget the last step and the public-IP history, so every run starts the same way."""
        shutil.rmtree(self.root / "state", ignore_errors=True)
        (self.root / "state").mkdir()

    def close(self) -> None:
        from tests.lab import procs

        self.tarpit.close()
        procs.stop(self.probe, 3)
        shutil.rmtree(self.root, ignore_errors=True)


def _wait_listening(port: int, proc: subprocess.Popen, timeout: float) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end and proc.poll() is None:
        with socket.socket() as s:
            s.settimeout(0.2)
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return True
        time.sleep(0.05)
    return False


@contextlib.contextmanager
def local_world(compiled: bool = False):
    """The world; with *compiled*, spawn_app runs a byte-compiled copy of rosnet-tui (as the
    benchmarks do; tests run the repository's own files)."""
    root = Path(tempfile.mkdtemp(prefix="rosnet-bench-"))
    for d in ("config/rosnet-tui", "state", "home"):
        (root / d).mkdir(parents=True)
    tarpit = Tarpit()
    probe_port = free_port()
    log = open(root / "probe.log", "w")
    probe = subprocess.Popen(
        [sys.executable, "-m", "rosnet_tui", "probe-server", "--listen", f"127.0.0.1:{probe_port}",
         "--rate-limit", "100000", "--max-concurrent", "64", "--connect-timeout", "1"],
        env=base_env(), stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT,
        cwd=str(REPO), start_new_session=True)
    log.close()
    world = None
    try:
        if not _wait_listening(probe_port, probe, 15):
            raise RuntimeError("the probe server did not start: "
                               + (root / "probe.log").read_text(errors="replace")[-1000:])
        test_port = free_port()
        config = root / "config" / "rosnet-tui" / "config.toml"
        write_settings(config, probe_url=f"http://127.0.0.1:{probe_port}",
                       public_ip_url=f"http://127.0.0.1:{probe_port}/ip", test_port=test_port)
        config_slow = root / "slow.toml"
        write_settings(config_slow, probe_url=f"http://127.0.0.1:{tarpit.port}",
                       public_ip_url=f"http://127.0.0.1:{tarpit.port}/ip", test_port=test_port)
        world = LocalWorld(root, config, config_slow, probe_port, tarpit, probe,
                           compiled_copy(root / "package") if compiled else None)
        yield world
    finally:
        if world is not None:
            world.close()
        else:
            tarpit.close()
            if probe.poll() is None:
                probe.kill()
                probe.wait(3)
            shutil.rmtree(root, ignore_errors=True)


def spawn_app(world: LocalWorld, *, config: Path | None = None, cols: int = 80,
              rows: int = 24, term: str = "xterm-256color", args: tuple[str, ...] = (),
              no_color: bool = False) -> PtyProcess:
    argv = [sys.executable, "-m", "rosnet_tui"]
    if config is not None:
        argv += ["--config", str(config)]
    argv += list(args)
    env = world.env() if world.package is None else run_compiled(world.env(), world.package)
    return PtyProcess(argv, env, cols=cols, rows=rows, cwd=str(REPO), term=term,
                      no_color=no_color)


def spawn_bare(world: LocalWorld | None, updates: int = 4, cols: int = 80,
               rows: int = 24, term: str = "xterm-256color") -> PtyProcess:
    env = world.env() if world is not None else base_env()
    return PtyProcess([sys.executable, "-m", "bench.bare_app", str(updates)], env, cols=cols,
                      rows=rows, cwd=str(REPO), term=term)
