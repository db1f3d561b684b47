"""The reverse tunnel a component nobody can reach keeps on the relay (``rosnet-tui relay
tunnel``): OpenSSH's client holds ``-R 127.0.0.1:<port>:127.0.0.1:<sshd>`` on the relay, so the
component's sshd answers at the relay's loopback only, and peers jump there
(:mod:`.connection`). When the link drops, ssh exits (ServerAlive notices a dead link in ~10 s,
ExitOnForwardFailure a port still held by the old session) and :class:`TunnelKeeper` starts it
again after a short, bounded pause, saying why each time.
"""

from __future__ import annotations

import subprocess
import threading
from collections.abc import Callable
from dataclasses import dataclass, field

from rosnet_tui.core.config.settings_model import RelaySettings
from rosnet_tui.core.ssh.connection import KEY_FILES
from rosnet_tui.core.ssh.options import SshOptions, known_hosts_files, relay_route, ssh_dir

ALIVE_INTERVAL_S = 5          # ServerAliveInterval: a keepalive every 5 s ...
ALIVE_COUNT = 2               # ... two unanswered ones end the tunnel (~10 s after a drop)
BACKOFF_S = (0.5, 1.0, 2.0, 4.0)
"""Pauses before each new try while the tunnel does not come up; it starts again from the first
once it was up (so a tunnel that drops is back within a few seconds)."""
STOP_GRACE_S = 3.0
UP_WORDS = "remote forward success"          # ssh -v's line once the relay listens for us
QUIET_PREFIXES = ("debug", "OpenSSH_", "Authenticated to", "Transferred:", "Bytes per second")


def _quoted(path: str) -> str:
    """A path as one word of an ssh -o value (double quotes when it has a space)."""
    return f'"{path}"' if " " in path else path


def tunnel_argv(relay: RelaySettings, name: str, sshd_port: int = 22,
                opts: SshOptions | None = None) -> list[str]:
    """The ssh command that keeps *name*'s tunnel: the relay's 127.0.0.1:<its port> to this
    machine's sshd (127.0.0.1:*sshd_port*); the relay's host key checked against our known_hosts
    (StrictHostKeyChecking: never accepted silently), keys only. Raises ValueError when the
    settings give *name* no tunnel."""
    route = relay_route(relay)
    port = route.tunnel_port(name) if route is not None else None
    if route is None or port is None:
        raise ValueError(f"no tunnel for {name}: the settings need [relay] host and a port for "
                         f"{name} under [relay.tunnels]")
    files = " ".join(_quoted(str(f)) for f in known_hosts_files(opts))
    argv = ["ssh", "-N", "-v"]
    if opts is not None and opts.ssh_dir is not None:     # a folder of our own: only its keys
        d = ssh_dir(opts)
        cfg = d / "config"
        argv += ["-F", str(cfg) if cfg.is_file() else "/dev/null", "-o", "IdentitiesOnly=yes"]
        for k in KEY_FILES:
            if (d / k).is_file():
                argv += ["-i", str(d / k)]
    argv += ["-o", "BatchMode=yes", "-o", "StrictHostKeyChecking=yes",
             "-o", f"UserKnownHostsFile={files}", "-o", "GlobalKnownHostsFile=/dev/null",
             "-o", "ExitOnForwardFailure=yes",
             "-o", f"ServerAliveInterval={ALIVE_INTERVAL_S}",
             "-o", f"ServerAliveCountMax={ALIVE_COUNT}", "-o", "ConnectTimeout=10",
             "-p", str(route.port), "-R", f"127.0.0.1:{port}:127.0.0.1:{int(sshd_port)}",
             f"{route.user}@{route.host}"]
    return argv


@dataclass
class TunnelKeeper:
    """Keeps *argv* (see :func:`tunnel_argv`) running until :attr:`stop` is set: each end is
    told through *say* with the pause before the next try."""

    argv: list[str]
    say: Callable[[str], None]
    stop: threading.Event = field(default_factory=threading.Event)
    backoff: tuple[float, ...] = BACKOFF_S
    ups: int = 0                       # how many times the relay took the forward

    def run(self) -> None:
        tries = 0
        while not self.stop.is_set():
            came_up, why = self._once()
            if self.stop.is_set():
                break
            tries = 0 if came_up else tries + 1
            pause = self.backoff[min(max(tries - 1, 0), len(self.backoff) - 1)]
            self.say(f"the tunnel {'dropped' if came_up else 'did not come up'} ({why}); "
                     f"trying again in {pause:g} s")
            self.stop.wait(pause)
        self.say("tunnel closed")

    def _once(self) -> tuple[bool, str]:
        """One ssh run: (whether the relay took the forward, why it ended)."""
        proc = subprocess.Popen(self.argv, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                stderr=subprocess.PIPE, text=True, errors="replace",
                                start_new_session=True)
        up = threading.Event()
        last: list[str] = []

        def read() -> None:
            assert proc.stderr is not None
            for line in proc.stderr:
                line = line.strip()
                if UP_WORDS in line and not up.is_set():
                    up.set()
                    self.ups += 1
                    where = line.split(UP_WORDS, 1)[1].strip().removeprefix("for:").strip()
                    self.say(f"tunnel up ({where})")
                elif line and not line.startswith(QUIET_PREFIXES):
                    last[:] = [line[:200]]

        reader = threading.Thread(target=read, daemon=True, name="rosnet-tunnel-stderr")
        reader.start()
        while proc.poll() is None and not self.stop.wait(0.1):
            pass
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(STOP_GRACE_S)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(STOP_GRACE_S)
        reader.join(1.0)
        why = last[0] if last else f"ssh exit status {proc.returncode}"
        return up.is_set(), why

