"""The network lab: the procedure's remote ROS network, built from Linux network namespaces.

Build one with ``Lab().build()`` (the ``lab`` fixture does it per test module) and always
``destroy()`` it (the fixture, an atexit hook and SIGTERM/SIGHUP handlers do). See
``tests/lab/topology.py`` for the map.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import os
import re
import selectors
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import xmlrpc.client
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from cryptography.hazmat.primitives import serialization as ser
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

from rosnet_tui.core.files.managed_write import write_all

from . import cleanup, procs, readme_install, topology
from .topology import ADDR, COMPUTERS, HOSTNAMES, HOSTS, MODEM, PEER, SERVERS, VARIANTS

REPO = Path(__file__).resolve().parents[2]
ROS_SCRIPTS = Path(__file__).resolve().parent / "ros_scripts"
TALKER = ROS_SCRIPTS / "talker.py"
LISTENER = ROS_SCRIPTS / "listener.py"
DNS_SERVER = Path(__file__).resolve().parent / "dns_server.py"
ROS_PYTHON = "/usr/bin/python3"

REQUIRED_TOOLS = ("ip", "iptables", "iptables-restore", "unshare", "mount", "hostname", "nc",
                  "ping", "ssh")
SSHD = "/usr/sbin/sshd"

# Inside a computer's namespace: set its hostname (own UTS namespace from `unshare --uts`),
# put its ~/.ssh where ssh and sshd look (the passwd home, /root) and its HOME in the env.
# A computer's own /etc/ssh too (its sshd's config and host keys), as on a real machine: what
# rosnet-tui reads there (relay.tunnel: this machine's sshd keys) is the lab computer's.
_WRAP_SCRIPT = ('hostname "$1" && mount --bind "$2" /root/.ssh && mount --bind "$4" /etc/ssh && '
                'export HOME="$3" USER=root LOGNAME=root && shift 4 && exec "$@"')

_HTTP_GET = """
import json, sys, urllib.error, urllib.request
try:
    with urllib.request.urlopen(sys.argv[1], timeout=float(sys.argv[2])) as r:
        print(json.dumps([r.status, r.read().decode("utf-8", "replace")]))
except urllib.error.HTTPError as e:
    print(json.dumps([e.code, e.read().decode("utf-8", "replace")]))
except Exception as e:
    print(json.dumps([0, f"{type(e).__name__}: {e}"]))
"""

_counter = itertools.count()


class LabUnavailable(Exception):
    """This machine cannot run the lab (not root, no namespaces, a tool missing)."""


def _unavailable(reason: str) -> None:
    """Skip the calling test when running under pytest; raise LabUnavailable otherwise."""
    try:
        import pytest
    except ImportError:  # pragma: no cover
        raise LabUnavailable(reason) from None
    pytest.skip(reason)


def lab_available() -> tuple[bool, str]:
    """Whether the lab can be built here, and if not, why (a skip reason)."""
    if sys.platform != "linux":
        return False, "the network lab needs Linux network namespaces"
    if os.geteuid() != 0:
        return False, "the network lab needs root (network namespaces, iptables, sshd)"
    missing = [t for t in REQUIRED_TOOLS if shutil.which(t) is None]
    if not os.access(SSHD, os.X_OK):
        missing.append(SSHD)
    if missing:
        return False, f"the network lab needs these tools: {', '.join(missing)}"
    return True, ""


def _check_kernel(ns: str) -> None:
    """Fail fast with a clear reason when namespaces, iptables or unshare do not work."""
    r = subprocess.run(["ip", "netns", "exec", ns, "iptables", "-S"], capture_output=True,
                       text=True, timeout=10)
    if r.returncode != 0:
        raise LabUnavailable(f"iptables does not work in a network namespace: {r.stderr.strip()}")
    r = subprocess.run(["ip", "netns", "exec", ns, "unshare", "--uts", "true"],
                       capture_output=True, text=True, timeout=10)
    if r.returncode != 0:
        raise LabUnavailable(f"unshare --uts does not work: {r.stderr.strip()}")


LINK_VARIANTS = ("unplugged", "double_nat", "cgnat", "cgnat_both")   # the variants that switch or move links
LINKS_SETTLE_S = 5.0   # the kernel's link watcher needs up to ~1 s; more only on a stalled machine


def links_behind(namespace: str) -> list[str]:
    """The links of *namespace* whose state the kernel has not caught up with yet: switched on,
    and their carrier there but the state not UP (or the carrier gone, the state still UP).

    The kernel's link watcher sets the state up to a second after the carrier changes (at once
    only for an "urgent" change, which a veth whose two ends have the same index in their
    namespaces, every lab link, is not). Programs that read the state (router.local_ip, `ip
    link`'s "state DOWN") would meet a link that already carries traffic as not running.
    """
    r = subprocess.run(["ip", "-n", namespace, "-j", "link", "show"], capture_output=True,
                       text=True, timeout=10)
    if r.returncode != 0:
        raise RuntimeError(f"ip link in {namespace}: {r.stderr.strip()}")
    behind = []
    for link in json.loads(r.stdout or "[]"):
        flags = link.get("flags", [])
        if "UP" in flags and ("LOWER_UP" in flags) != (link.get("operstate") in ("UP", "UNKNOWN")):
            behind.append(f"{link.get('ifname')} ({link.get('operstate')}, "
                          f"{'carrier' if 'LOWER_UP' in flags else 'no carrier'})")
    return behind


def wait_links_settled(namespaces: list[str], timeout: float = LINKS_SETTLE_S) -> None:
    """Return once no link of *namespaces* is behind (links_behind); raise after *timeout*."""
    deadline = time.monotonic() + timeout
    while True:
        behind = {ns: b for ns in namespaces if (b := links_behind(ns))}
        if not behind:
            return
        if time.monotonic() >= deadline:
            raise RuntimeError(f"links whose state did not follow their carrier in {timeout} s: "
                               f"{behind}")
        time.sleep(0.02)


def _write_in_place(path: Path, text: str, mode: int | None = None) -> None:
    """Rewrite *path* keeping its inode: /etc/hosts and resolv.conf are bind-mounted files.

    The new bytes go over the old ones and the file is cut after them (as rosnet-tui's own
    in-place writer does), never emptied first: a program reading it meanwhile gets the old
    bytes, the new ones or, for the moment of the copy, a mix; not an empty file for as long
    as a truncating open() and a buffered write leave one (roscore, still starting, looked
    its master's name up in an emptied /etc/hosts and exited: see start_roscore)."""
    data = text.encode("utf-8")
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_CLOEXEC, 0o666)
    try:
        write_all(fd, data)
        os.ftruncate(fd, len(data))
    finally:
        os.close(fd)
    if mode is not None:
        os.chmod(path, mode)


def keypair(comment: str) -> tuple[bytes, bytes]:
    key = Ed25519PrivateKey.generate()
    private = key.private_bytes(ser.Encoding.PEM, ser.PrivateFormat.OpenSSH, ser.NoEncryption())
    public = key.public_key().public_bytes(ser.Encoding.OpenSSH, ser.PublicFormat.OpenSSH)
    return private, public + f" {comment}".encode()


class Lab:
    """The lab. Attribute and method names are the contract other tests code against."""

    addr = ADDR
    HOSTS = HOSTS
    COMPUTERS = COMPUTERS  # the hosts with a name, sshd, HOME (a subclass may have others)
    SERVERS = SERVERS      # a name, sshd and HOME with rosnet-tui, but no ROS nor settings
    VARIANTS = VARIANTS

    def __init__(self) -> None:
        self.index = next(_counter)
        self.prefix = f"rnl-{os.getpid()}-{self.index}-"
        self.dir: Path | None = None
        self.built = False
        self.destroyed = False
        self._procs: list[subprocess.Popen] = []
        self._roscore: subprocess.Popen | None = None
        self._services: dict[str, subprocess.Popen] = {}
        self._netns_inodes: list[tuple[int, int]] = []
        self._created_root_ssh = False
        self._state: dict[str, Any] = {}
        self._netem: bool | None = None
        self._reset_state()

    # ================================================================== names and paths
    def ns(self, host: str) -> str:
        """The network namespace name of *host*."""
        if host not in self.HOSTS:
            raise ValueError(f"unknown lab host {host!r} (known: {', '.join(self.HOSTS)})")
        return self.prefix + host

    def netns_path(self, host: str) -> str:
        return f"{procs.NETNS_DIR}/{self.ns(host)}"

    def hostname(self, host: str) -> str:
        return HOSTNAMES[host]

    def _hostdir(self, host: str) -> Path:
        assert self.dir is not None, "the lab is not built"
        return self.dir / host

    def home(self, host: str) -> Path:
        """HOME of robot, laptop or the relay (.ssh with key, authorized_keys, known_hosts;
        the computers' .bashrc)."""
        if host not in self.SERVERS:
            self._computer(host)
        return self._hostdir(host) / "home"

    def hosts_path(self, host: str) -> Path:
        """The file that is /etc/hosts inside *host* (rewrite it in place, never by rename)."""
        return Path("/etc/netns") / self.ns(host) / "hosts"

    def resolv_path(self, host: str) -> Path:
        return Path("/etc/netns") / self.ns(host) / "resolv.conf"

    def bashrc_path(self, host: str) -> Path:
        return self.home(host) / ".bashrc"

    def log_path(self, name: str) -> Path:
        """Log of a lab service: 'probe', 'dns', 'sshd-robot', 'sshd-laptop', 'roscore'."""
        assert self.dir is not None
        return self.dir / "logs" / f"{name}.log"

    def public_ip(self, host: str) -> str:
        """The public address *host* currently shows to the internet (follows the variants)."""
        if host == "robot":
            return ADDR.CARRIER_PUBLIC if self._state["cgnat"] else self._state["robot_wan"]
        if host == "laptop":
            return ADDR.LAPTOP_CARRIER_PUBLIC if self._state["cgnat_both"] else ADDR.LAPTOP_PUBLIC
        raise ValueError("public_ip is for 'robot' or 'laptop'")

    @staticmethod
    def _computer(host: str) -> None:
        if host not in COMPUTERS:
            raise ValueError(f"{host!r} is not a computer of the lab (robot or laptop)")

    @property
    def master(self) -> str:
        """The computer that runs the ROS master (roscore; ROS 2: the hub router)."""
        return "robot"

    def local_ip(self, host: str) -> str:
        self._computer(host)
        return topology.LOCAL_IP[host]

    def settings_public_ip(self, host: str) -> str:
        """The public address the settings give *host* (its modem's, whatever a variant does)."""
        self._computer(host)
        return topology.PUBLIC_IP[host]

    def peers_of(self, host: str) -> list[str]:
        """The computers *host* knows: it trusts their user keys, knows their host keys by name,
        and has them as its settings' peers."""
        self._computer(host)
        return [PEER[host]]

    # ================================================================== configuration text
    def hosts_text(self, host: str) -> str:
        """*host*'s /etc/hosts as the lab builds it."""
        return topology.hosts_text(host)

    def bashrc_text(self, host: str) -> str:
        return topology.bashrc_text(host)

    def ip_batch(self, host: str) -> list[str]:
        """`ip -batch` lines that address and route *host* (its links already exist)."""
        return topology.ip_batch(host)

    def _namespace_script(self, host: str, hdir: Path) -> list[str]:
        """The shell lines that set *host*'s namespace up: sysctls, addresses and routes (from
        hdir/ip.batch), firewall."""
        script = [topology.sysctl_script(host), f"ip -batch {hdir / 'ip.batch'}",
                  topology.sysctl_script(host)]  # again: rp_filter of the new interfaces
        if host in ("robot_modem", "laptop_modem", "carrier", "travel_router", "laptop_carrier"):
            rules = (topology.carrier_ruleset() if host in ("carrier", "laptop_carrier")
                     else topology.modem_ruleset(None) if host == "travel_router"
                     else topology.modem_ruleset("robot" if host == "robot_modem" else "laptop"))
            (hdir / "rules.v4").write_text(rules)
            script.append(f"iptables-restore {hdir / 'rules.v4'}")
        return script

    # ================================================================== running things
    def wrap(self, host: str) -> list[str]:
        """argv prefix running a command on *host*: its netns, hostname, HOME, ~/.ssh, /etc/hosts."""
        ns = self.ns(host)
        if host in self.COMPUTERS or host in self.SERVERS:
            return ["ip", "netns", "exec", ns, "unshare", "--uts", "--", "/bin/sh", "-c",
                    _WRAP_SCRIPT, "rnl-wrap", self.hostname(host), str(self.home(host) / ".ssh"),
                    str(self.home(host)), str(self._hostdir(host) / "etc")]
        return ["ip", "netns", "exec", ns]

    def env(self, host: str) -> dict[str, str]:
        """A clean environment for *host*: no ROS or proxy variables, the repo importable."""
        env = {k: v for k, v in os.environ.items()
               if not k.startswith("ROS_") and k not in ("PYTHONHOME", "VIRTUAL_ENV")
               and not k.lower().endswith("_proxy")   # nothing in the lab goes via a proxy
               and k not in ("SSH_CONNECTION", "SSH_CLIENT", "SSH_TTY")}  # nor over our SSH
        env["PYTHONPATH"] = str(REPO)
        env["PYTHONUNBUFFERED"] = "1"
        if host in self.COMPUTERS or host in self.SERVERS:
            env["HOME"] = str(self.home(host))
        return env

    def ros_env(self, host: str) -> dict[str, str]:
        """Environment for ROS tools on *host*, as its ~/.bashrc sets it (variants included)."""
        self._computer(host)
        env = self.env(host)
        env["ROS_MASTER_URI"] = ADDR.ROS_MASTER_URI
        env.update(self._state["ros_extra"].get(host, {}))
        return env

    def run(self, host: str, argv: list[str], *, timeout: float = 10, env: dict | None = None,
            input: str | None = None) -> subprocess.CompletedProcess:
        """Run *argv* on *host* to completion (text output captured). On timeout the whole
        process group is killed and subprocess.TimeoutExpired is raised."""
        proc = subprocess.Popen(
            self.wrap(host) + list(argv), env=self.env(host) if env is None else env,
            stdin=subprocess.PIPE if input is not None else subprocess.DEVNULL,
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
        try:
            out, err = proc.communicate(input=input, timeout=timeout)
        except subprocess.TimeoutExpired:
            procs.kill_tree(proc.pid, grace=0.2)
            out, err = proc.communicate()
            raise subprocess.TimeoutExpired(proc.args, timeout, output=out, stderr=err) from None
        return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)

    def spawn(self, host: str, argv: list[str], *, env: dict | None = None,
              **popen: Any) -> subprocess.Popen:
        """Start *argv* on *host* in the background; tracked and killed at tear-down.

        Default: stdout and stderr merged into a text pipe; read it with :meth:`wait_output`.
        """
        self._require_built()
        kwargs: dict[str, Any] = {"stdin": subprocess.DEVNULL, "stdout": subprocess.PIPE,
                                  "stderr": subprocess.STDOUT, "text": True}
        kwargs.update(popen)
        proc = subprocess.Popen(self.wrap(host) + list(argv),
                                env=self.env(host) if env is None else env,
                                start_new_session=True, **kwargs)
        self._procs = [p for p in self._procs if p.returncode is None]  # forget finished ones
        self._procs.append(proc)
        return proc

    def kill(self, proc: subprocess.Popen, grace: float = 1.0) -> None:
        """Stop a spawned process, its group and its descendants (bounded)."""
        if proc.poll() is None:
            procs.kill_tree(proc.pid, grace=grace)
        try:
            proc.wait(timeout=2)
        except subprocess.TimeoutExpired:
            pass
        self._drain(proc)
        for stream in (proc.stdout, proc.stderr, proc.stdin):
            if stream is not None:
                with contextlib.suppress(OSError):
                    stream.close()

    def rosnet(self, host: str, *args: str, timeout: float = 60,
               env: dict | None = None, input: str | None = None) -> subprocess.CompletedProcess:
        """``python -m rosnet_tui ARGS`` on *host*, in its ROS environment by default."""
        env = dict(self.ros_env(host) if env is None else env)
        if str(REPO) not in env.get("PYTHONPATH", "").split(os.pathsep):
            env["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO), env.get("PYTHONPATH")) if p)
        return self.run(host, [sys.executable, "-m", "rosnet_tui", *args], timeout=timeout,
                        env=env, input=input)

    def http_get(self, host: str, url: str, timeout: float = 8.0) -> tuple[int, str]:
        """GET *url* from *host* (names resolved as *host* resolves them): (status, body);
        status 0 when no HTTP answer came (the body then says why)."""
        r = self.run(host, [sys.executable, "-c", _HTTP_GET, url, str(timeout)],
                     timeout=timeout + 10)
        try:
            status, body = json.loads(r.stdout)
        except ValueError:
            return 0, (r.stdout + r.stderr).strip()
        return int(status), body

    def call_in(self, host: str, fn, *args: Any, timeout: float = 30, **kwargs: Any):
        """Run ``fn(*args, **kwargs)`` in this process, inside *host*'s network namespace only
        (a thread that joined it): use addresses, not names. Sockets made there stay there."""
        return procs.call_in_netns(self.netns_path(host), fn, *args, timeout=timeout, **kwargs)

    def listening(self, host: str, port: int, proto: str = "tcp") -> bool:
        return port in self.call_in(host, procs.listening_ports, proto)

    def wait_listening(self, host: str, port: int, proto: str = "tcp",
                       timeout: float = 10.0, proc: subprocess.Popen | None = None) -> bool:
        """Wait (bounded) until something listens on *port* in *host*; False on timeout or if
        *proc* exits first."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.listening(host, port, proto):
                return True
            if proc is not None and proc.poll() is not None:
                return False
            time.sleep(0.01)
        return False

    # ---------------------------------------------------------------- process output
    def _drain(self, proc: subprocess.Popen) -> str:
        """Collect what *proc* wrote so far (non-blocking); returns the whole output."""
        text: str = getattr(proc, "_rnl_out", "")
        stream = proc.stdout
        if stream is None or stream.closed:
            return text
        fd = stream.fileno()
        os.set_blocking(fd, False)
        chunks = []
        while True:
            try:
                data = os.read(fd, 65536)
            except BlockingIOError:
                break
            except OSError:
                break
            if not data:
                break
            chunks.append(data)
        if chunks:
            text += b"".join(chunks).decode("utf-8", "replace")
            proc._rnl_out = text  # type: ignore[attr-defined]
        return text

    def output(self, proc: subprocess.Popen) -> str:
        """Everything a spawned process has written so far."""
        return self._drain(proc)

    def wait_output(self, proc: subprocess.Popen, pattern: str, timeout: float = 10.0,
                    ) -> re.Match | None:
        """Wait (bounded) until *proc*'s output matches the regex *pattern*; None on timeout or
        when the process ends without it."""
        rx = re.compile(pattern)
        deadline = time.monotonic() + timeout
        sel = selectors.DefaultSelector()
        try:
            if proc.stdout is not None and not proc.stdout.closed:
                sel.register(proc.stdout.fileno(), selectors.EVENT_READ)
            while True:
                m = rx.search(self._drain(proc))
                if m:
                    return m
                left = deadline - time.monotonic()
                if left <= 0:
                    return None
                if proc.poll() is not None:
                    m = rx.search(self._drain(proc))
                    return m
                if sel.get_map():
                    sel.select(min(left, 0.2))
                else:
                    time.sleep(min(left, 0.05))
        finally:
            sel.close()

    # ================================================================== build
    def build(self) -> Lab:
        """Create namespaces, links, NAT, firewalls, files, keys and services (< 1 s)."""
        ok, why = lab_available()
        if not ok:
            raise LabUnavailable(why)
        cleanup.sweep_stale()
        cleanup.register(self)
        self.dir = Path(tempfile.mkdtemp(prefix=self.prefix, dir=tempfile.gettempdir()))
        try:
            self._build()
        except BaseException:
            self.destroy()
            raise
        self.built = True
        return self

    def _build(self) -> None:
        assert self.dir is not None
        (self.dir / "logs").mkdir()
        # 1. namespaces and links, in one go
        lines = [f"netns add {self.ns(h)}" for h in HOSTS]
        lines += [f"link add name {ia} netns {self.ns(a)} type veth peer name {ib} netns {self.ns(b)}"
                  for a, ia, b, ib in topology.LINKS]
        self._create_links(lines)
        _check_kernel(self.ns("internet"))

        # 2. files: /etc/netns, homes, keys (before anything starts)
        self._write_files()

        # 3. per namespace: sysctls, addresses, routes, firewall (all namespaces at once)
        self._configure_namespaces()

        # 4. services, started together, then waited for together
        self._start_services()

        # 5. no link handed out before the kernel calls it up (links_behind)
        self.settle_links()

    def settle_links(self) -> None:
        """Wait (bounded) until every link's state follows its carrier (links_behind)."""
        wait_links_settled([self.ns(h) for h in self.HOSTS])

    def _create_links(self, lines: list[str]) -> None:
        """Run the `ip -batch` *lines* that add the namespaces and their links."""
        r = subprocess.run(["ip", "-batch", "-"], input="\n".join(lines) + "\n", text=True,
                           capture_output=True, timeout=30)
        self._netns_inodes = [i for i in (procs.netns_inode(self.netns_path(h))
                                          for h in self.HOSTS) if i]
        if r.returncode != 0:
            if not self._netns_inodes:
                raise LabUnavailable(f"cannot create network namespaces: {r.stderr.strip()}")
            raise RuntimeError(f"lab links failed: {r.stderr.strip()}")

    def _configure_namespaces(self) -> None:
        """Every namespace's _namespace_script, all at once."""
        running = []
        for h in self.HOSTS:
            hdir = self._hostdir(h)
            hdir.mkdir(exist_ok=True)
            (hdir / "ip.batch").write_text("\n".join(self.ip_batch(h)) + "\n")
            running.append((h, subprocess.Popen(
                ["ip", "netns", "exec", self.ns(h), "sh", "-ec",
                 "\n".join(self._namespace_script(h, hdir))],
                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)))
        for h, p in running:
            out, _ = p.communicate(timeout=30)
            if p.returncode != 0:
                raise RuntimeError(f"setting up {h} failed: {out.strip()}")

    def _write_files(self) -> None:
        """/etc/netns of every namespace; each computer's keys, sshd config, HOME (.ssh trusting
        its peers_of, .bashrc) and settings file."""
        assert self.dir is not None
        root_ssh = Path("/root/.ssh")
        if not root_ssh.exists():  # the mount point for each computer's ~/.ssh
            root_ssh.mkdir(mode=0o700)
            self._created_root_ssh = True
        Path("/run/sshd").mkdir(mode=0o755, exist_ok=True)  # sshd's privilege separation dir
        for h in self.HOSTS:
            etc = Path("/etc/netns") / self.ns(h)
            etc.mkdir(parents=True, exist_ok=True)
            _write_in_place(etc / "hosts", self.hosts_text(h), 0o644)
            _write_in_place(etc / "resolv.conf", topology.resolv_text(), 0o644)
        keys = {h: {"host": keypair(f"host key of {self.hostname(h)}"),
                    "user": keypair(f"root@{self.hostname(h)}")}
                for h in (*self.COMPUTERS, *self.SERVERS)}
        for h in (*self.COMPUTERS, *self.SERVERS):
            # A server (the relay) lets every computer in and is known to each by name.
            server = h in self.SERVERS
            hdir = self._hostdir(h)
            peers = list(self.COMPUTERS) if server else self.peers_of(h)
            known = [] if server else [*peers, *self.SERVERS]
            ssh = hdir / "home" / ".ssh"
            ssh.mkdir(parents=True, mode=0o700)
            os.chmod(hdir / "home", 0o755)
            (hdir / "etc").mkdir(mode=0o700)
            host_key = hdir / "etc" / "ssh_host_ed25519_key"
            host_key.write_bytes(keys[h]["host"][0])
            os.chmod(host_key, 0o600)
            host_key.with_suffix(".pub").write_bytes(keys[h]["host"][1] + b"\n")
            (ssh / "id_ed25519").write_bytes(keys[h]["user"][0])
            os.chmod(ssh / "id_ed25519", 0o600)
            (ssh / "id_ed25519.pub").write_bytes(keys[h]["user"][1] + b"\n")
            (ssh / "authorized_keys").write_bytes(b"".join(keys[o]["user"][1] + b"\n"
                                                           for o in peers))
            os.chmod(ssh / "authorized_keys", 0o600)
            (ssh / "known_hosts").write_bytes(b"".join(
                self.hostname(o).encode() + b" " + b" ".join(keys[o]["host"][1].split()[:2])
                + b"\n" for o in known))
            (hdir / "etc" / "sshd_config").write_text(topology.sshd_config(
                str(host_key), str(hdir / "home"), topology.SSH_SESSION_PATH, ""))
            if server:
                continue
            _write_in_place(hdir / "home" / ".bashrc", self.bashrc_text(h))
            self.config_path(h)

    def _start_services(self) -> None:
        def logfile(name: str):
            return open(self.log_path(name), "w")

        starts = {}
        for h in (*self.COMPUTERS, *self.SERVERS):
            with logfile(f"sshd-{h}") as log:
                starts[f"sshd-{h}"] = (h, 22, "tcp", self.spawn(
                    h, [SSHD, "-D", "-e", "-f", str(self._hostdir(h) / "etc" / "sshd_config")],
                    stdout=log, stderr=subprocess.STDOUT))
        with logfile("probe") as log:
            starts["probe"] = ("internet", 80, "tcp", self.spawn(
                "internet", [sys.executable, "-m", "rosnet_tui", "probe-server", "--listen",
                             f"{ADDR.PROBE_IP}:80", "--rate-limit", "100000",
                             "--max-concurrent", "64"],
                stdout=log, stderr=subprocess.STDOUT))
        with logfile("dns") as log:
            starts["dns"] = ("internet", 53, "udp", self.spawn(
                "internet", [sys.executable, str(DNS_SERVER), "--listen", ADDR.DNS_IP,
                             "--record", f"{ADDR.PROBE_NAME}={ADDR.PROBE_IP}"],
                stdout=log, stderr=subprocess.STDOUT))
        deadline = time.monotonic() + 20
        for name, (host, port, proto, proc) in starts.items():
            self._services[name] = proc
            if not self.wait_listening(host, port, proto, max(0.1, deadline - time.monotonic()),
                                       proc=proc):
                log_text = self.log_path(name).read_text(errors="replace")[-2000:]
                raise RuntimeError(f"lab service {name} did not start: {log_text}")

    # ================================================================== settings for the product
    def settings(self, host: str):
        """The rosnet-tui Settings of *host*: the master behind a telecom router, every other
        computer a member at home; its peers_of reached over SSH as root (the two-site lab:
        robot is the master turtlebot, laptop the member sami)."""
        from rosnet_tui.core.config.settings_model import Peer, ThisComponent
        from tests.builders import checked_settings

        self._computer(host)
        is_master = host == self.master
        this = ThisComponent(name=self.hostname(host), role="master" if is_master else "member",
                             connection="telecom" if is_master else "home", profile="remote",
                             local_ip=self.local_ip(host),
                             public_ip=self.settings_public_ip(host), interface="eth0")
        peers = [Peer(name=self.hostname(p), local_ip=self.local_ip(p),
                      public_ip=self.settings_public_ip(p), ssh_user="root")
                 for p in self.peers_of(host)]
        return checked_settings(this, peers, self.hostname(self.master), probe_port=12345,
                                public_ip_url=ADDR.PUBLIC_IP_URL, port_check_url=ADDR.PROBE_URL)

    def config_path(self, host: str) -> Path:
        """(Re)write *host*'s settings file at its default place (HOME/.config/rosnet-tui/
        config.toml, found without --config) and return its path."""
        from rosnet_tui.core.saved.settings import atomic_write_text, render_settings

        path = self.home(host) / ".config" / "rosnet-tui" / "config.toml"
        atomic_write_text(path, render_settings(self.settings(host)), mode=0o644)
        return path

    # ================================================================== ROS
    def start_roscore(self, timeout: float = 30.0) -> subprocess.Popen:
        """Start roscore on the master and wait (bounded) until its start-up is over: the master
        answers and lists /rosout, which roscore launches after its own calls to the master.
        Until then roscore looks the master's name up (ROS_MASTER_URI) and exits on a name
        that does not resolve; the master answering alone came before those calls."""
        self._require_built()
        if self._roscore is not None and self._roscore.poll() is None:
            return self._roscore
        if shutil.which("roscore") is None:
            _unavailable("roscore is not installed (Debian package ros-core)")
        with open(self.log_path("roscore"), "w") as log:
            self._roscore = self.spawn(self.master, ["roscore", "-p", "11311"],
                                       env=self.ros_env(self.master), stdout=log,
                                       stderr=subprocess.STDOUT)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self._roscore.poll() is not None:
                break
            if "/rosout" in (self.master_nodes() or ()):
                return self._roscore
            time.sleep(0.1)
        tail = self.log_path("roscore").read_text(errors="replace")[-3000:]
        self.stop_roscore()
        raise RuntimeError(f"roscore did not answer within {timeout} s:\n{tail}")

    def master_answers(self, timeout: float = 2.0) -> bool:
        """Whether the ROS master answers getSystemState (asked on the master's computer)."""
        return self.master_nodes(timeout) is not None

    def master_nodes(self, timeout: float = 2.0) -> list[str] | None:
        """The nodes the ROS master lists (getSystemState, asked on the master's computer), or
        None when it does not answer."""
        local = self.local_ip(self.master)

        def ask() -> list[str] | None:
            class T(xmlrpc.client.Transport):
                def make_connection(self, host):
                    conn = super().make_connection(host)
                    conn.timeout = timeout
                    return conn
            try:
                code, _, state = xmlrpc.client.ServerProxy(
                    f"http://{local}:11311/", transport=T()).getSystemState("/rnl")
            except (OSError, xmlrpc.client.Error):
                return None
            if code != 1:
                return None
            return sorted({n for group in state for _, nodes in group for n in nodes})
        return self.call_in(self.master, ask, timeout=timeout + 5)

    def roscore_said(self) -> str:
        """What a failed ROS 1 check needs to be read: is the lab's roscore running, does the
        master answer, and the end of its log."""
        p = self._roscore
        state = ("not started" if p is None else
                 f"running (pid {p.pid})" if p.poll() is None else f"exited ({p.returncode})")
        log = self.log_path("roscore")
        tail = log.read_text(errors="replace")[-1500:] if log.exists() else ""
        return f"roscore: {state}; master answers: {self.master_answers()}\n{tail}"

    def stop_roscore(self) -> None:
        if self._roscore is not None:
            self.kill(self._roscore, grace=2.0)
            self._roscore = None

    def talker(self, host: str, topic: str = "/rnl_chatter", *, env: dict | None = None,
               rate_hz: float = 5.0) -> subprocess.Popen:
        """A ROS talker on *host* (messages 'hello from <hostname> <n>')."""
        return self.spawn(host, [ROS_PYTHON, str(TALKER), topic, str(rate_hz)],
                          env=self.ros_env(host) if env is None else env)

    def listener(self, host: str, topic: str = "/rnl_chatter", *,
                 env: dict | None = None) -> subprocess.Popen:
        """A ROS listener on *host*; its output has a line 'heard: <data>' per message."""
        return self.spawn(host, [ROS_PYTHON, str(LISTENER), topic],
                          env=self.ros_env(host) if env is None else env)

    # ================================================================== variants
    def _reset_state(self) -> None:
        self._state = {"variant": "healthy", "forward": {"robot": "healthy", "laptop": "healthy"},
                       "cgnat": False, "robot_wan": ADDR.ROBOT_PUBLIC, "lossy": False,
                       "unplugged": False, "ros_extra": {}, "files_dirty": False,
                       "stale_dhcp": False, "double_nat": False, "sshd_port": False,
                       "cgnat_both": False, "shaped": None}

    @property
    def current_variant(self) -> str:
        return self._state["variant"]

    @contextlib.contextmanager
    def variant(self, name: str, **options: Any) -> Iterator[Lab]:
        """Switch to a variant for the ``with`` block, then back to healthy (always).

        Options: no_forwarding / wrong_forward take ``side="robot"|"laptop"|"both"`` (default
        robot); no_forwarding also ``refuse=True`` (the modem answers every TCP connection with a
        reset instead of dropping it); lossy takes ``loss`` (0..1, default 0.05), ``delay_ms``
        (100) and ``rate`` ("2mbit"; used when the kernel has no netem); unplugged takes
        ``side="laptop"|"robot"`` (default laptop) and ``silent=True`` (its modem drops what it
        would forward to it, so no ICMP error comes back either).

        More variants: stale_dhcp (the robot got a new local IP, 10.10.10.5, from DHCP; its
        modem still forwards to 10.10.10.1), double_nat (a travel router of the user's own
        between the robot and its modem, which forwards correctly to the travel router; the
        travel router forwards nothing), sshd_port (the robot's sshd listens on 2222, not 22),
        cgnat_both (both modems behind a carrier's NAT: nothing reaches either site from the
        internet; ROS 2 and SSH meet at the relay).
        """
        if name not in VARIANTS:
            raise ValueError(f"unknown variant {name!r} (known: {', '.join(VARIANTS)})")
        self._require_built()
        self.reset()
        try:
            self._apply(name, **options)
            self._state["variant"] = name
            if name in LINK_VARIANTS:
                self.settle_links()
            yield self
        finally:
            self.reset()

    def _sides(self, side: str) -> list[str]:
        if side not in ("robot", "laptop", "both"):
            raise ValueError("side must be 'robot', 'laptop' or 'both'")
        return ["robot", "laptop"] if side == "both" else [side]

    def _apply(self, name: str, side: str | None = None, loss: float = 0.05, delay_ms: int = 100,
               rate: str = "2mbit", refuse: bool = False, silent: bool = False) -> None:
        if name == "healthy":
            return
        if name in ("no_forwarding", "wrong_forward"):
            mode = ("refuse" if refuse else "none") if name == "no_forwarding" else "wrong"
            for s in self._sides(side or "robot"):
                self._set_forwarding(s, mode)
        elif name == "cgnat":
            self._set_cgnat(True)
        elif name == "cgnat_both":
            self._set_cgnat(True)
            self._set_laptop_cgnat(True)
        elif name == "ros_ip_laptop":
            self._state["ros_extra"]["laptop"] = {"ROS_IP": ADDR.LAPTOP_LOCAL}
            self._state["files_dirty"] = True
            _write_in_place(self.bashrc_path("laptop"),
                            topology.bashrc_text("laptop", ros_ip=ADDR.LAPTOP_LOCAL))
        elif name == "stale_hosts":
            self._state["files_dirty"] = True
            self.write_hosts("laptop", topology.hosts_text(
                "laptop", robot_public=ADDR.STALE_ROBOT_PUBLIC))
        elif name == "lossy":
            self._set_lossy(True, loss=loss, delay_ms=delay_ms, rate=rate)
        elif name == "unplugged":
            who = side or "laptop"
            if who not in ("robot", "laptop"):
                raise ValueError("unplugged: side must be 'robot' or 'laptop'")
            self._state["unplugged"] = who
            if silent:
                self._unplug_rule(MODEM[who], True)
            self._ip(who, ["link set eth0 down"])
        elif name == "stale_dhcp":
            self._state["stale_dhcp"] = True
            self._ip("robot", ["addr flush dev eth0", f"addr add {ADDR.ROBOT_NEW_LOCAL}/24 dev eth0",
                               f"route replace default via {ADDR.ROBOT_GW}"])
        elif name == "double_nat":
            self._set_double_nat(True)
        elif name == "sshd_port":
            self._restart_sshd("robot", int(ADDR.ROBOT_SSHD_PORT))

    def reset(self) -> None:
        """Back to the healthy network: forwarding, addresses, links, files, ROS variables, and
        rosnet-tui installed on every computer the README's way (readme_install: quick when it
        is there). Not the peers-only firewall of ROS 1's default security: the variants start
        from here and change addresses and NAT, which it would block; a test that wants every
        check to pass loads it first (tests/lab/firewall.py secured)."""
        if not self.built or self.destroyed:
            return
        for h in (*COMPUTERS, *SERVERS):
            readme_install.install(self.home(h))
        st = self._state
        links_moved = bool(st["unplugged"] or st["double_nat"] or st["cgnat"]
                           or st["cgnat_both"])
        for s in ("robot", "laptop"):
            if st["forward"][s] != "healthy":
                self._set_forwarding(s, "healthy")
        if st["cgnat_both"]:
            self._set_laptop_cgnat(False)
        if st["cgnat"]:
            self._set_cgnat(False)
        if st["robot_wan"] != ADDR.ROBOT_PUBLIC:
            self.set_robot_wan(ADDR.ROBOT_PUBLIC)
        if st["lossy"]:
            self._set_lossy(False)
        if st["shaped"]:
            self.shape_robot(None)
        if st["unplugged"]:
            who = st["unplugged"]
            self._ip(who, ["link set eth0 up",
                           f"route replace default via {topology.GATEWAY[who]}"])
            self._unplug_rule(MODEM[who], False)
        if st["stale_dhcp"]:
            self._ip("robot", ["addr flush dev eth0", f"addr add {ADDR.ROBOT_LOCAL}/24 dev eth0",
                               f"route replace default via {ADDR.ROBOT_GW}"])
        if st["double_nat"]:
            self._set_double_nat(False)
        if st["sshd_port"]:
            self._restart_sshd("robot", 22)
        for h in COMPUTERS:
            if self.hosts_path(h).read_text() != topology.hosts_text(h):
                self.write_hosts(h, topology.hosts_text(h))
            if self.bashrc_path(h).read_text() != topology.bashrc_text(h):
                _write_in_place(self.bashrc_path(h), topology.bashrc_text(h))
        self._reset_state()
        if links_moved:
            self.settle_links()   # the links brought back up are up when handed out

    def write_hosts(self, host: str, text: str) -> None:
        """Replace *host*'s /etc/hosts content in place (running processes see it too)."""
        _write_in_place(self.hosts_path(host), text)

    def _ip(self, host: str, lines: list[str]) -> None:
        r = subprocess.run(["ip", "-n", self.ns(host), "-batch", "-"], input="\n".join(lines) + "\n",
                           text=True, capture_output=True, timeout=10)
        if r.returncode != 0:
            raise RuntimeError(f"ip on {host} failed: {r.stderr.strip()} ({lines})")

    def _in_ns(self, host: str, script: str, check: bool = True) -> subprocess.CompletedProcess:
        r = subprocess.run(["ip", "netns", "exec", self.ns(host), "sh", "-ec", script], text=True,
                           capture_output=True, timeout=10)
        if check and r.returncode != 0:
            raise RuntimeError(f"on {host}: {script!r} failed: {r.stderr.strip()}")
        return r

    def _set_forwarding(self, side: str, mode: str) -> None:
        """Port forwarding of *side*'s modem: 'healthy', 'none', 'refuse' (none, and a reset for
        every TCP connection), 'wrong' (the wrong local IP) or 'travel' (double_nat)."""
        refuse = topology.refuse_rules() if mode == "refuse" else []
        rules = "\n".join(["*nat", "-F RNL_PF", *topology.forward_rules(side, mode), "COMMIT",
                           "*filter", "-F RNL_REFUSE", *refuse, "COMMIT", ""])
        r = subprocess.run(["ip", "netns", "exec", self.ns(MODEM[side]), "iptables-restore",
                            "--noflush"], input=rules, text=True, capture_output=True, timeout=10)
        if r.returncode != 0:
            raise RuntimeError(f"forwarding on {MODEM[side]}: {r.stderr.strip()}")
        self._state["forward"][side] = mode

    def cut_uplink(self, side: str, on: bool = True) -> None:
        """*side*'s modem silently drops everything it would forward, both ways (its uplink
        dead: no reset, no ICMP; the far end learns it only from its lease); ``on=False`` (or
        reset()) ends it. Not a variant: the links stay up, so ending it is instant."""
        self._unplug_rule(MODEM[side], on, both=True)
        self._state["unplugged"] = self._state["unplugged"] or (side if on else False)

    def shape_robot(self, rate: str | None, latency: str = "400ms") -> None:
        """The robot's modem shaped to *rate* ("2mbit") both ways: tc tbf on what leaves its WAN
        (the robot's upload) and its LAN (its download), queueing up to *latency* of it; None
        (or reset()) takes it off. This kernel has tbf but not netem: no delay."""
        for dev in ("wan0", "lan0"):
            self._in_ns("robot_modem", f"tc qdisc replace dev {dev} root tbf rate {rate} "
                                       f"burst 32kbit latency {latency}" if rate else
                        f"tc qdisc del dev {dev} root 2>/dev/null || true")
        self._state["shaped"] = rate

    def _unplug_rule(self, modem: str, on: bool, both: bool = False) -> None:
        """The modem drops what it would forward to its LAN (a computer that is gone, silently);
        with *both*, what comes from it too."""
        drop = ["-A RNL_UNPLUG -o lan0 -j DROP"] + (["-A RNL_UNPLUG -i lan0 -j DROP"] if both
                                                    else [])
        rules = "\n".join(["*filter", "-F RNL_UNPLUG", *(drop if on else []), "COMMIT", ""])
        r = subprocess.run(["ip", "netns", "exec", self.ns(modem), "iptables-restore",
                            "--noflush"], input=rules, text=True, capture_output=True, timeout=10)
        if r.returncode != 0:
            raise RuntimeError(f"unplug rule on {modem}: {r.stderr.strip()}")

    def _set_double_nat(self, on: bool) -> None:
        """Put the travel router between the robot and its modem (or take it out again).

        The robot's cable (the robot modem's lan0) moves to the travel router; a new link joins
        the travel router's wan0 to the robot modem's new lan0 (192.168.0.0/24); the robot modem
        forwards to the travel router, which forwards nothing.
        """
        travel, modem = self.ns("travel_router"), self.ns("robot_modem")
        if on:
            self._ip("robot_modem", [f"link set lan0 netns {travel}"])
            self._ip("robot_modem", [f"link add name lan0 type veth peer name wan0 netns {travel}",
                                     f"addr add {ADDR.OUTER_LAN_GW}/24 dev lan0",
                                     "link set lan0 up"])
            self._ip("travel_router", [f"addr add {ADDR.ROBOT_GW}/24 dev lan0", "link set lan0 up",
                                       f"addr add {ADDR.TRAVEL_WAN}/24 dev wan0",
                                       "link set wan0 up",
                                       f"route add default via {ADDR.OUTER_LAN_GW}"])
            self._state["double_nat"] = True
            self._set_forwarding("robot", "travel")
        else:
            self._ip("robot_modem", ["link del lan0"])
            self._ip("travel_router", [f"link set lan0 netns {modem}"])
            self._ip("robot_modem", [f"addr add {ADDR.ROBOT_GW}/24 dev lan0", "link set lan0 up"])
            self._state["double_nat"] = False
            self._set_forwarding("robot", "healthy")
        self._ip("robot", [f"route replace default via {ADDR.ROBOT_GW}"])

    def _restart_sshd(self, host: str, port: int) -> None:
        """Restart *host*'s sshd listening on *port* (22 is the lab's normal)."""
        name = f"sshd-{host}"
        old = self._services.get(name)
        if old is not None:
            self.kill(old, grace=1.0)
        hdir = self._hostdir(host)
        conf = hdir / "etc" / ("sshd_config" if port == 22 else f"sshd_config.{port}")
        if port != 22:
            conf.write_text(topology.sshd_config(str(hdir / "etc" / "ssh_host_ed25519_key"),
                                                 str(hdir / "home"), topology.SSH_SESSION_PATH,
                                                 "", port))
        with open(self.log_path(name), "a") as log:
            proc = self.spawn(host, [SSHD, "-D", "-e", "-f", str(conf)], stdout=log,
                              stderr=subprocess.STDOUT)
        self._services[name] = proc
        if not self.wait_listening(host, port, "tcp", 10.0, proc=proc):
            raise RuntimeError(f"{name} did not start on port {port}")
        self._state["sshd_port"] = port != 22

    def _set_cgnat(self, on: bool) -> None:
        """Move the robot modem's WAN link behind the carrier's NAT (or back to the internet)."""
        if on:
            self._ip("internet", [f"link set r-wan netns {self.ns('carrier')}"])
            self._ip("carrier", [f"addr add {ADDR.CARRIER_LAN}/10 dev r-wan", "link set r-wan up"])
            self._ip("robot_modem", ["addr flush dev wan0",
                                     f"addr add {ADDR.ROBOT_MODEM_CGNAT_WAN}/10 dev wan0",
                                     f"route replace default via {ADDR.CARRIER_LAN}"])
        else:
            self._ip("carrier", [f"link set r-wan netns {self.ns('internet')}"])
            self._ip("internet", [f"addr add {ADDR.INTERNET_ROBOT_SIDE}/24 dev r-wan",
                                  "link set r-wan up"])
            self._ip("robot_modem", ["addr flush dev wan0",
                                     f"addr add {self._state['robot_wan']}/24 dev wan0",
                                     f"route replace default via {ADDR.INTERNET_ROBOT_SIDE}"])
        self._state["cgnat"] = on

    def _set_laptop_cgnat(self, on: bool) -> None:
        """Move the laptop modem's WAN link behind its carrier's NAT (or back to the internet)."""
        if on:
            self._ip("internet", [f"link set l-wan netns {self.ns('laptop_carrier')}"])
            self._ip("laptop_carrier", [f"addr add {ADDR.LAPTOP_CARRIER_LAN}/16 dev l-wan",
                                        "link set l-wan up"])
            self._ip("laptop_modem", ["addr flush dev wan0",
                                      f"addr add {ADDR.LAPTOP_MODEM_CGNAT_WAN}/16 dev wan0",
                                      f"route replace default via {ADDR.LAPTOP_CARRIER_LAN}"])
        else:
            self._ip("laptop_carrier", [f"link set l-wan netns {self.ns('internet')}"])
            self._ip("internet", [f"addr add {ADDR.INTERNET_LAPTOP_SIDE}/24 dev l-wan",
                                  "link set l-wan up"])
            self._ip("laptop_modem", ["addr flush dev wan0",
                                      f"addr add {ADDR.LAPTOP_PUBLIC}/24 dev wan0",
                                      f"route replace default via {ADDR.INTERNET_LAPTOP_SIDE}"])
        self._state["cgnat_both"] = on

    def set_robot_wan(self, ip: str) -> contextlib.AbstractContextManager:
        """Give the robot modem a new public address (a modem restart with a new IP), now.

        Returns a context manager that puts the previous address back on exit; variants and
        reset() restore the default (ROBOT_PUBLIC) too. Hosts files are not touched.
        """
        self._require_built()
        if not ip.startswith("203.0.113.") or ip in (ADDR.INTERNET_ROBOT_SIDE, ADDR.CARRIER_PUBLIC):
            raise ValueError("the robot's public address must be a free 203.0.113.x address")
        if self._state["cgnat"]:
            raise RuntimeError("set_robot_wan is not available in the cgnat variant")
        previous = self._state["robot_wan"]
        self._ip("robot_modem", ["addr flush dev wan0", f"addr add {ip}/24 dev wan0",
                                 f"route replace default via {ADDR.INTERNET_ROBOT_SIDE}"])
        self._ip("internet", ["neigh flush dev r-wan"])
        self._state["robot_wan"] = ip

        @contextlib.contextmanager
        def restore() -> Iterator[str]:
            try:
                yield ip
            finally:
                if self.built and not self.destroyed and self._state["robot_wan"] == ip:
                    self.set_robot_wan(previous)
        return restore()

    def netem_available(self) -> bool:
        if self._netem is None:
            r = self._in_ns("internet", "tc qdisc add dev lo root netem delay 1ms && "
                                        "tc qdisc del dev lo root", check=False)
            self._netem = r.returncode == 0
        return self._netem

    def _set_lossy(self, on: bool, loss: float = 0.05, delay_ms: int = 100,
                   rate: str = "2mbit") -> None:
        """Loss and delay on both modems' WAN (tc netem; without netem: iptables random drop
        plus a tbf rate limit, which delays only under load)."""
        netem = self.netem_available()
        for modem in ("robot_modem", "laptop_modem"):
            if on:
                if netem:
                    script = (f"tc qdisc replace dev wan0 root netem delay {int(delay_ms)}ms "
                              f"{max(1, int(delay_ms) // 5)}ms loss {loss * 100:.2f}%")
                else:
                    script = (f"tc qdisc replace dev wan0 root tbf rate {rate} burst 32kbit "
                              f"latency 400ms\n"
                              f"iptables -t mangle -A RNL_LOSS -m statistic --mode random "
                              f"--probability {loss:.4f} -j DROP")
            else:
                script = "tc qdisc del dev wan0 root 2>/dev/null || true\niptables -t mangle -F RNL_LOSS"
            self._in_ns(modem, script)
        self._state["lossy"] = on

    # ================================================================== tear-down
    def _require_built(self) -> None:
        if self.dir is None or self.destroyed:
            raise RuntimeError("the lab is not built (or already destroyed)")

    def destroy(self) -> None:
        """Kill what the lab started, delete its namespaces, files and folder. Idempotent."""
        if self.destroyed:
            return
        self.destroyed = True
        cleanup.unregister(self)
        tracked = [p for p in self._procs if p.poll() is None]
        family: list[int] = []
        for p in tracked:
            family += [p.pid, *procs.descendants(p.pid)]
            procs.signal_group(p.pid, signal.SIGTERM)
        procs.signal_pids(family, signal.SIGTERM)
        left = procs.wait_dead(family, 1.0)
        for p in tracked:
            procs.signal_group(p.pid, signal.SIGKILL)
        procs.signal_pids(left, signal.SIGKILL)
        for p in self._procs:
            with contextlib.suppress(subprocess.TimeoutExpired):
                p.wait(timeout=2)
            for stream in (p.stdout, p.stderr, p.stdin):
                if stream is not None:
                    with contextlib.suppress(OSError):
                        stream.close()
        cleanup.remove_netns([self.prefix + h for h in self.HOSTS])  # kills anything else inside
        for h in self.HOSTS:
            shutil.rmtree(Path("/etc/netns") / (self.prefix + h), ignore_errors=True)
        with contextlib.suppress(OSError):
            Path("/etc/netns").rmdir()
        if self.dir is not None:
            shutil.rmtree(self.dir, ignore_errors=True)
        if self._created_root_ssh and not cleanup.any_lab_netns():
            with contextlib.suppress(OSError):
                Path("/root/.ssh").rmdir()

    def lab_pids(self) -> list[int]:
        """Live processes in this lab's namespaces, or started by it (for leak checks)."""
        pids = set(procs.pids_in_netns(self._netns_inodes))
        pids.update(p.pid for p in self._procs if procs.alive(p.pid))
        return sorted(pids)

    def __enter__(self) -> Lab:
        return self.build() if not self.built else self

    def __exit__(self, *exc: Any) -> None:
        self.destroy()
