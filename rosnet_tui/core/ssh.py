"""SSH to a peer by name: verified host keys, keys only, every step under a deadline.

Two entry points, both async and both returning results rather than raising:

- :func:`ssh_run` runs one command (optionally fed *stdin*) and returns an :class:`SshResult`.
- :func:`ssh_session` starts a command and keeps it running while the caller does something
  locally (e.g. the peer listens while we connect to it); the caller reads its output as it
  arrives, writes to its stdin, then waits for it to end.

Connecting follows what ``ssh user@name`` does, minus anything interactive: the peer's *name* is
resolved by this machine, the server's host key must already be in ``~/.ssh/known_hosts`` (or
``/etc/ssh/ssh_known_hosts``) — an unknown key stops before authentication and reports its
fingerprint, a different key is refused — and authentication uses the keys in ``~/.ssh`` and the
SSH agent, never a password. Failures are classified (network, sshd, host key, auth, ...) so the
advisor can say what to fix. paramiko is blocking; it runs in daemon threads (see
:func:`run_blocking`) and a cancelled caller closes the socket so the thread ends at once.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import logging
import os
import socket
import threading
import time
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from rosnet_tui.core.known_hosts import (  # noqa: F401 (host keys; re-exported)
    _KEY_FILE_KIND,
    MAX_KNOWN_HOSTS_BYTES,
    SYSTEM_KNOWN_HOSTS,
    KnownHostKeys,
    _hosts_match,
    _key_blob,
    _known_host_keys,
    _known_keys,
    _pattern_matches,
    _read_known_hosts,
    host_key_name,
    key_fingerprint,
    known_hosts_files,
    ssh_dir,
    trust_host_key,
    verify_commands,
)
from rosnet_tui.core.settings import Peer

if TYPE_CHECKING:
    import paramiko

# paramiko logs handshake errors at ERROR level; without a handler Python would print them.
logging.getLogger("paramiko").addHandler(logging.NullHandler())

FAILURES = ("network", "resolve", "host_key_unknown", "host_key_changed", "auth", "sshd",
            "no_user", "timeout")
KEY_FILES = ("id_ed25519", "id_ecdsa", "id_rsa")
_POLL_S = 0.02

T = TypeVar("T")


@dataclass
class SshResult:
    ok: bool                 # connected, authenticated, command ran (exit_status may be nonzero)
    exit_status: int | None
    stdout: str
    stderr: str
    failure: str | None      # None or one of FAILURES
    detail: str              # one human line on what happened
    fingerprint: str | None  # SHA256:... of the server's host key when seen
    host_key: str | None = None  # "<type> <base64>" of the server's key, for trust_host_key()
    address: str | None = None   # the address the peer's name resolved to here


# --------------------------------------------------------------------------- blocking helpers
async def run_blocking(func: Callable[..., T], *args: Any, timeout: float | None = None) -> T:
    """Run blocking *func* in a daemon thread and await it (raises asyncio.TimeoutError).

    Unlike ``asyncio.to_thread`` a stuck call (a resolver waiting on a dead DNS server) never
    holds up the interpreter's exit: the thread is a daemon and nobody joins it.
    """
    loop = asyncio.get_running_loop()
    fut: asyncio.Future[T] = loop.create_future()

    def deliver(setter: Callable[[Any], None], value: Any) -> None:
        if not fut.done():
            setter(value)

    def target() -> None:
        try:
            value = func(*args)
        except BaseException as exc:  # noqa: BLE001 - handed to the awaiting task
            with contextlib.suppress(RuntimeError):  # loop already closed
                loop.call_soon_threadsafe(deliver, fut.set_exception, exc)
        else:
            with contextlib.suppress(RuntimeError):
                loop.call_soon_threadsafe(deliver, fut.set_result, value)

    threading.Thread(target=target, daemon=True, name=f"rosnet-{getattr(func, '__name__', 'io')}").start()
    if timeout is None:
        return await fut
    return await asyncio.wait_for(fut, max(timeout, 0.001))


def _getaddrinfo_v4(name: str, port: int | None) -> list[str]:
    infos = socket.getaddrinfo(name, port, socket.AF_INET, socket.SOCK_STREAM)
    out: list[str] = []
    for info in infos:
        ip = str(info[4][0])
        if ip not in out:
            out.append(ip)
    return out


async def resolve_ipv4(name: str, timeout: float) -> tuple[list[str], str | None]:
    """Resolve *name* with the system resolver (hosts file, DNS): (addresses, error or None)."""
    try:
        return await run_blocking(_getaddrinfo_v4, name, None, timeout=timeout), None
    except asyncio.TimeoutError:
        return [], f"no answer from the resolver within {timeout:.1f} s"
    except socket.gaierror as exc:
        return [], f"does not resolve ({exc.strerror or exc})"
    except OSError as exc:
        return [], f"does not resolve ({exc.strerror or exc})"


# --------------------------------------------------------------------------- options
@dataclass(frozen=True)
class SshOptions:
    """What the SSH layer needs to know, and nothing more.

    ``ssh_dir``: the folder with our keys and known_hosts (None: ``$HOME/.ssh``);
    ``known_hosts_files``: the files to trust (None: that folder's known_hosts and
    /etc/ssh/ssh_known_hosts); ``ssh_agent``: offer the agent's keys; ``timeout_s``: the default
    connect budget.
    """

    ssh_dir: Path | None = None
    known_hosts_files: tuple[Path, ...] | None = None
    ssh_agent: bool = True
    timeout_s: float = 3.0



# --------------------------------------------------------------------------- connecting
class _Holder:
    """What a connecting thread owns, so a cancelled caller can close it."""

    def __init__(self) -> None:

        self.sock: socket.socket | None = None
        self.transport: paramiko.Transport | None = None
        self.cancelled = False

    def close(self) -> None:
        self.cancelled = True
        if self.transport is not None:
            with contextlib.suppress(Exception):
                self.transport.close()
        if self.sock is not None:
            with contextlib.suppress(Exception):
                self.sock.close()


@dataclass
class _Conn:
    result: SshResult
    transport: paramiko.Transport | None = None
    said: str = ""                # notes on known_hosts, carried into the command's result


def _fail(failure: str, detail: str, *, fingerprint: str | None = None,
          host_key: str | None = None, address: str | None = None) -> _Conn:
    return _Conn(SshResult(False, None, "", "", failure, detail, fingerprint, host_key, address))


def _load_keys(opts: SshOptions | None) -> tuple[list[paramiko.PKey], list[str]]:
    """Private keys to offer: the agent's, then ~/.ssh/id_* and IdentityFile from ~/.ssh/config."""
    import paramiko

    keys: list[paramiko.PKey] = []
    notes: list[str] = []
    if getattr(opts, "ssh_agent", True) and os.environ.get("SSH_AUTH_SOCK"):
        try:
            keys.extend(paramiko.Agent().get_keys())
        except Exception as exc:  # noqa: BLE001
            notes.append(f"ssh-agent unusable: {exc}")
    d = ssh_dir(opts)
    paths = [d / n for n in KEY_FILES]
    cfg = d / "config"
    if cfg.is_file():
        try:
            conf = paramiko.SSHConfig.from_path(str(cfg))
            for host in conf.get_hostnames():
                for ident in conf.lookup(host).get("identityfile", []) if host != "*" else []:
                    p = Path(os.path.expanduser(ident))
                    if p not in paths:
                        paths.append(p)
        except Exception:  # noqa: BLE001 - a broken config is not our business here
            pass
    for p in paths:
        if not p.is_file():
            continue
        try:
            keys.append(paramiko.PKey.from_path(p))
        except paramiko.PasswordRequiredException:
            notes.append(f"{p} has a passphrase: load it into ssh-agent (ssh-add {p})")
        except Exception as exc:  # noqa: BLE001
            notes.append(f"{p} could not be read: {exc}")
    return keys, notes


_ALGOS_FOR_TYPE = {"ssh-rsa": ("rsa-sha2-512", "rsa-sha2-256", "ssh-rsa")}


def _connect_blocking(opts: SshOptions | None, peer: Peer, deadline: float,
                      holder: _Holder) -> _Conn:
    import paramiko

    name, port, user = peer.name, int(peer.ssh_port or 22), peer.ssh_user

    def left() -> float:
        return max(deadline - time.monotonic(), 0.05)

    if not user:
        return _fail("no_user", f"no SSH user is set for {name} in the settings")
    try:
        addrs = _getaddrinfo_v4(name, port)
    except OSError as exc:
        return _fail("resolve", f"{name} does not resolve here ({getattr(exc, 'strerror', None) or exc})")
    if not addrs:
        return _fail("resolve", f"{name} has no IPv4 address here")
    addr = addrs[0]
    try:
        sock = socket.create_connection((addr, port), timeout=left())
    except TimeoutError:
        return _fail("network", f"no answer from {name} ({addr}) on TCP {port} within the timeout "
                                "(no route, a firewall, or no port forwarding)", address=addr)
    except OSError as exc:
        why = {errno.ECONNREFUSED: "connection refused: nothing listens there (sshd not running, "
                                   "or the modem does not forward the port)",
               errno.EHOSTUNREACH: "no route to the host",
               errno.ENETUNREACH: "the network is unreachable"}.get(exc.errno or 0, str(exc))
        return _fail("network", f"cannot reach {name} ({addr}) on TCP {port}: {why}", address=addr)
    holder.sock = sock
    if holder.cancelled:
        sock.close()
        return _fail("timeout", "cancelled", address=addr)
    info = _known_host_keys(known_hosts_files(opts), host_key_name(name, port))
    known = info.keys
    said = f" (known_hosts: {'; '.join(info.notes)})" if info.notes else ""
    try:
        t = paramiko.Transport(sock)
        holder.transport = t
        t.banner_timeout = left()
        t.handshake_timeout = left()
        t.auth_timeout = left()
        if known:
            sec = t.get_security_options()
            first: list[str] = []
            for ktype in known:
                first.extend(_ALGOS_FOR_TYPE.get(ktype, (ktype,)))
            avail = list(sec.key_types)
            sec.key_types = [a for a in first if a in avail] + [a for a in avail if a not in first]
        t.start_client(timeout=left())
    except Exception as exc:  # noqa: BLE001 - paramiko raises many kinds here
        sock.close()
        msg = str(exc) or type(exc).__name__
        return _fail("sshd", f"{name} ({addr}) port {port} accepted the connection but did not speak "
                             f"SSH properly: {msg}", address=addr)
    try:
        key = t.get_remote_server_key()  # start_client returns quietly on a timeout
    except paramiko.SSHException:
        t.close()
        return _fail("sshd", f"{name} ({addr}) port {port} accepted the connection but no SSH "
                             "handshake came within the timeout (not sshd, or a stuck one)",
                     address=addr)
    fp, ktype = key.fingerprint, key.get_name()
    key_text = f"{ktype} {key.get_base64()}"
    blob = key.asbytes()
    if blob in info.revoked:
        t.close()
        return _fail("host_key_changed",
                     f"the host key of {name} ({ktype} {fp}) is REVOKED in known_hosts "
                     f"(@revoked): refused. Its keys must be replaced on {name}, then the new "
                     f"key verified: " + verify_commands(name, port, ktype, user) + said,
                     fingerprint=fp, host_key=key_text, address=addr)
    if ktype not in known:
        t.close()
        if known:
            others = ", ".join(known)
            return _fail("host_key_changed",
                         f"known_hosts has a {others} key for {name} but the server now offers a "
                         f"{ktype} key ({fp}); refused. If {name} was reinstalled, remove the old "
                         f"entry (ssh-keygen -R {host_key_name(name, port)}) and verify the new one: "
                         + verify_commands(name, port, ktype, user) + said,
                         fingerprint=fp, host_key=key_text, address=addr)
        return _fail("host_key_unknown",
                     f"the host key of {name} is not in known_hosts: {ktype} {fp}; not trusted "
                     f"until you confirm it: " + verify_commands(name, port, ktype, user) + said,
                     fingerprint=fp, host_key=key_text, address=addr)
    if blob not in known[ktype]:
        t.close()
        return _fail("host_key_changed",
                     f"the host key of {name} CHANGED: known_hosts has "
                     f"{', '.join(info.fingerprints(ktype))}, "
                     f"the server shows {fp}; refused (a reinstall, or someone in the middle). "
                     f"If you know why, remove the old entry with ssh-keygen -R "
                     f"{host_key_name(name, port)} and verify the new one: "
                     + verify_commands(name, port, ktype, user) + said,
                     fingerprint=fp, host_key=key_text, address=addr)
    keys, notes = _load_keys(opts)
    if not keys:
        t.close()
        return _fail("auth", f"no SSH key to log in to {name} with: create one (ssh-keygen -t "
                             f"ed25519) and copy it (ssh-copy-id {user}@{name})"
                     + (f"; {'; '.join(notes)}" if notes else ""),
                     fingerprint=fp, host_key=key_text, address=addr)
    last = ""
    for k in keys:
        if not t.is_active():
            break
        try:
            t.auth_publickey(user, k)
        except paramiko.BadAuthenticationType as exc:
            last = f"the server does not accept keys for {user} (allowed: {', '.join(exc.allowed_types)})"
            break
        except paramiko.AuthenticationException as exc:
            last = str(exc) or "key refused"
            continue
        except Exception as exc:  # noqa: BLE001 - transport died mid-auth
            last = str(exc) or type(exc).__name__
            break
        if t.is_authenticated():
            return _Conn(SshResult(True, None, "", "", None,
                                   f"logged in to {name} ({addr}) as {user} with a key" + said,
                                   fp, key_text, addr), t, said)
    t.close()
    if holder.cancelled or time.monotonic() >= deadline:
        return _fail("timeout", f"no login to {name} within the timeout", fingerprint=fp,
                     host_key=key_text, address=addr)
    return _fail("auth", f"{name} refused our SSH keys for user {user} ({last}): copy a key with "
                         f"ssh-copy-id {user}@{name}" + (f"; {'; '.join(notes)}" if notes else ""),
                 fingerprint=fp, host_key=key_text, address=addr)


async def _connect(opts: SshOptions | None, peer: Peer, timeout: float) -> _Conn:
    holder = _Holder()
    deadline = time.monotonic() + timeout
    try:
        return await run_blocking(_connect_blocking, opts, peer, deadline, holder,
                                  timeout=timeout + 0.5)
    except asyncio.TimeoutError:
        holder.close()
        return _fail("timeout", f"no SSH connection to {peer.name} within {timeout:.1f} s")
    except Exception as exc:  # noqa: BLE001 - a failure is a result, never an exception
        holder.close()
        return _fail("sshd", f"the SSH connection to {peer.name} broke: "
                             f"{type(exc).__name__}: {exc}")
    except BaseException:
        holder.close()
        raise


# --------------------------------------------------------------------------- sessions
class SshSession:
    """A remote command that keeps running while we work; see :func:`ssh_session`.

    ``ok`` is False when the connection failed (``result`` says why); the I/O methods are then
    no-ops. Reads never block the event loop: the channel is polled.
    """

    def __init__(self, peer: Peer, conn: _Conn, timeout: float) -> None:

        self.peer = peer
        self.result = conn.result
        self.timeout = timeout
        self._transport = conn.transport
        self._said = conn.said
        self._chan: paramiko.Channel | None = None
        self._out = bytearray()
        self._err = bytearray()

    @property
    def ok(self) -> bool:
        return self._chan is not None

    @property
    def stdout(self) -> str:
        return self._out.decode("utf-8", "replace")

    @property
    def stderr(self) -> str:
        return self._err.decode("utf-8", "replace")

    def _start(self, command: str) -> None:
        assert self._transport is not None
        chan = self._transport.open_session(timeout=self.timeout)
        chan.setblocking(False)
        chan.exec_command(command)
        self._chan = chan

    def _pump(self) -> bool:
        """Move whatever arrived into the buffers; True when the channel is finished."""
        chan = self._chan
        if chan is None:
            return True
        while chan.recv_ready():
            data = chan.recv(65536)
            if not data:
                break
            self._out += data
        while chan.recv_stderr_ready():
            data = chan.recv_stderr(65536)
            if not data:
                break
            self._err += data
        if chan.exit_status_ready() and not chan.recv_ready() and not chan.recv_stderr_ready():
            return True
        return chan.closed or not (self._transport and self._transport.is_active())

    async def write(self, data: bytes | str) -> bool:
        """Send *data* to the command's stdin; False when it could not be sent."""
        import paramiko

        if self._chan is None:
            return False
        buf = data.encode() if isinstance(data, str) else bytes(data)
        deadline = time.monotonic() + self.timeout
        while buf:
            try:
                if self._chan.send_ready():
                    n = self._chan.send(buf)
                    if n <= 0:
                        return False
                    buf = buf[n:]
                    continue
            except (OSError, paramiko.SSHException):
                return False
            if time.monotonic() > deadline or self._chan.closed:
                return False
            await asyncio.sleep(_POLL_S)
        return True

    async def close_stdin(self) -> None:
        if self._chan is not None:
            with contextlib.suppress(Exception):
                self._chan.shutdown_write()

    async def read_until(self, marker: str, timeout: float | None = None) -> str | None:
        """Wait until stdout contains *marker*; the stdout so far, or None on timeout or exit."""
        if self._chan is None:
            return None
        deadline = time.monotonic() + (self.timeout if timeout is None else timeout)
        while True:
            done = self._pump()
            if marker in self.stdout:
                return self.stdout
            if done or time.monotonic() > deadline:
                return None
            await asyncio.sleep(_POLL_S)

    async def wait(self, timeout: float | None = None) -> SshResult:
        """Wait for the command to end; its result (failure "timeout" if it did not end)."""
        if self._chan is None:
            return self.result
        deadline = time.monotonic() + (self.timeout if timeout is None else timeout)
        while not self._pump():
            if time.monotonic() > deadline:
                return SshResult(False, None, self.stdout, self.stderr, "timeout",
                                 f"the command on {self.peer.name} did not finish in time",
                                 self.result.fingerprint, self.result.host_key, self.result.address)
            await asyncio.sleep(_POLL_S)
        status = self._chan.recv_exit_status() if self._chan.exit_status_ready() else None
        detail = (f"ran on {self.peer.name} as {self.peer.ssh_user}, exit status {status}"
                  if status is not None else f"the session with {self.peer.name} closed")
        detail += self._said
        return SshResult(status is not None, status, self.stdout, self.stderr,
                         None if status is not None else "sshd", detail,
                         self.result.fingerprint, self.result.host_key, self.result.address)

    def close(self) -> None:
        if self._chan is not None:
            with contextlib.suppress(Exception):
                self._chan.close()
        if self._transport is not None:
            with contextlib.suppress(Exception):
                self._transport.close()


@contextlib.asynccontextmanager
async def ssh_session(opts: SshOptions | None, peer: Peer, command: str, *,
                      timeout: float | None = None) -> AsyncIterator[SshSession]:
    """Start *command* on *peer* and keep it running for the ``async with`` body.

    ``timeout`` bounds the connection (and is the default for reads/waits). On leaving the block
    the channel and connection are closed; the remote command must bound itself (sshd does not
    kill a command without a terminal when the channel closes). Usage::

        async with ssh_session(opts, peer, "python3 -c ...") as s:
            if not s.ok:
                return s.result            # failure says why (network, host key, auth, ...)
            await s.read_until("LISTENING")
            ...                            # act locally while the peer listens
            res = await s.wait(5)
    """
    t = float(timeout if timeout is not None else (getattr(opts, "timeout_s", 3.0) or 3.0))
    conn = await _connect(opts, peer, t)
    session = SshSession(peer, conn, t)
    try:
        if conn.transport is not None:
            try:
                session._start(command)
            except Exception as exc:  # noqa: BLE001
                session.result = SshResult(False, None, "", "", "sshd",
                                           f"{peer.name} did not run the command: {exc}",
                                           conn.result.fingerprint, conn.result.host_key,
                                           conn.result.address)
        yield session
    finally:
        session.close()


async def ssh_run(opts: SshOptions | None, peer: Peer, command: str, *,
                  stdin: bytes | str | None = None, timeout: float | None = None,
                  connect_timeout: float | None = None) -> SshResult:
    """Run *command* on *peer* (by name, as ``peer.ssh_user``) within *timeout* seconds overall.

    *connect_timeout* (default: *timeout*) bounds reaching and logging in to the peer, so a
    caller can keep time for something else when the peer is unreachable.
    """
    t = float(timeout if timeout is not None else (getattr(opts, "timeout_s", 3.0) or 3.0))
    deadline = time.monotonic() + t
    ct = min(float(connect_timeout), t) if connect_timeout is not None else t
    async with ssh_session(opts, peer, command, timeout=ct) as s:
        if not s.ok:
            return s.result
        if stdin:
            await s.write(stdin)
        await s.close_stdin()
        return await s.wait(max(deadline - time.monotonic(), 0.05))
