"""Reaching a peer over SSH: resolve its name, TCP, host key checked against known_hosts, login
with keys only; every step under a deadline, every failure a classified result (never raised).

paramiko is blocking; it runs in daemon threads (see :func:`run_blocking`) and a cancelled caller
closes the socket (:class:`Holder`) so the thread ends at once.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import logging
import os
import pwd
import socket
import time
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, TypeVar

from rosnet_tui.core.config.settings_model import Peer
from rosnet_tui.core.net.blocking import run_blocking
from rosnet_tui.core.net.connect import tcp_failure_kind
from rosnet_tui.core.net.lazy_import import import_without
from rosnet_tui.core.ssh.known_hosts import host_key_name, known_host_keys, verify_commands
from rosnet_tui.core.ssh.options import RelayRoute, SshOptions, known_hosts_files, ssh_dir

if TYPE_CHECKING:
    import paramiko

# paramiko logs handshake errors at ERROR level; without a handler Python would print them.
logging.getLogger("paramiko").addHandler(logging.NullHandler())

FAILURES = ("network", "resolve", "host_key_unknown", "host_key_changed", "auth", "sshd",
            "no_user", "timeout", "relay")
"""Why SSH failed. "relay": at the relay on the way to a peer behind it (its name, TCP, host key,
login or forwarding); the peer's own "network" through the relay: its tunnel is down."""
KEY_FILES = ("id_ed25519", "id_ecdsa", "id_rsa")

T = TypeVar("T")


def load_paramiko() -> ModuleType:
    """paramiko, imported on first use without invoke, which paramiko.config imports only to run
    the commands of ssh_config's ``Match exec``: :func:`load_keys` never gets there (paramiko's
    ``get_hostnames`` fails on a config with any Match block). Every import of paramiko in the
    product comes through here first."""
    return import_without("paramiko", "invoke")


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
    tcp: str | None = None       # TCP to the SSH port: core.net.connect's kind (None: not tried)


# --------------------------------------------------------------------------- blocking helpers
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


# --------------------------------------------------------------------------- connecting
class Holder:
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
class Conn:
    result: SshResult
    transport: paramiko.Transport | None = None
    said: str = ""                # notes on known_hosts, carried into the command's result


def failed(failure: str, detail: str, *, fingerprint: str | None = None,
          host_key: str | None = None, address: str | None = None,
          tcp: str | None = "connected") -> Conn:
    return Conn(SshResult(False, None, "", "", failure, detail, fingerprint, host_key, address,
                           tcp))


def load_keys(opts: SshOptions | None) -> tuple[list[paramiko.PKey], list[str]]:
    """Private keys to offer: the agent's, then ~/.ssh/id_* and IdentityFile from ~/.ssh/config."""
    paramiko = load_paramiko()

    keys: list[paramiko.PKey] = []
    notes: list[str] = []
    if getattr(opts, "ssh_agent", True) and os.environ.get("SSH_AUTH_SOCK"):
        try:
            keys.extend(paramiko.Agent().get_keys())
        except Exception as exc:  # noqa: BLE001
            notes.append(f"ssh-agent unusable: {exc}")
    d = ssh_dir(opts)
    paths = [d / n for n in KEY_FILES]
    for p in config_identity_files(d / "config"):
        if p not in paths:
            paths.append(p)
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


def config_identity_files(cfg: Path) -> list[Path]:
    """The IdentityFile paths of an ssh_config, in its order, whatever block they sit in. Read
    line by line: paramiko's SSHConfig.get_hostnames raises on any ``Match`` block, which hid
    every key such a config names. ``~``, ``%d`` (home), ``%u`` (user) and ``%%`` are expanded;
    a path with another token depends on the host it is used for and is left out."""
    try:
        text = cfg.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return []
    tokens = {"%%": "\x00", "%d": os.path.expanduser("~"), "%u": local_user_name()}
    out = []
    for line in text.splitlines():
        words = line.strip().replace("=", " ", 1).split(None, 1)
        if len(words) != 2 or words[0].lower() != "identityfile":
            continue
        value = words[1].strip().strip('"')
        for token, meaning in tokens.items():
            value = value.replace(token, meaning)
        if "%" in value or not value or value.lower() == "none":
            continue
        out.append(Path(os.path.expanduser(value.replace("\x00", "%"))))
    return out


def local_user_name() -> str:
    """This process's user name, as ssh_config's ``%u`` means it."""
    try:
        return pwd.getpwuid(os.getuid()).pw_name
    except KeyError:
        return os.environ.get("USER", "")


_ALGOS_FOR_TYPE = {"ssh-rsa": ("rsa-sha2-512", "rsa-sha2-256", "ssh-rsa")}


def _tcp(name: str, port: int, deadline: float, holder: Holder,
         tcp_deadline: float | None) -> tuple[socket.socket | None, str | None, Conn | None]:
    """Resolve *name* and open TCP to its *port*: (socket, address, None) or (None, address, the
    failure)."""
    try:
        addrs = _getaddrinfo_v4(name, port)
    except OSError as exc:
        return None, None, failed("resolve", f"{name} does not resolve here "
                                  f"({getattr(exc, 'strerror', None) or exc})", tcp=None)
    if not addrs:
        return None, None, failed("resolve", f"{name} has no IPv4 address here", tcp=None)
    addr = addrs[0]
    tcp_left = max((deadline if tcp_deadline is None else min(tcp_deadline, deadline))
                   - time.monotonic(), 0.05)
    try:
        sock = socket.create_connection((addr, port), timeout=tcp_left)
    except TimeoutError:
        return None, addr, failed(
            "network", f"no answer from {name} ({addr}) on TCP {port} within {tcp_left:.1f} s: "
            "the packets are dropped (no port forwarding, a firewall, or nobody at that address)",
            address=addr, tcp="timeout")
    except OSError as exc:
        why = {errno.ECONNREFUSED: f"connection refused: {addr} answers and rejects port {port}"
                                   " (sshd does not listen there - it may listen on another "
                                   "port, see ssh_port - or the modem does not forward it)",
               errno.EHOSTUNREACH: "no route to the host",
               errno.ENETUNREACH: "the network is unreachable"}.get(exc.errno or 0, str(exc))
        return None, addr, failed("network", f"cannot reach {name} ({addr}) on TCP {port}: {why}",
                                  address=addr, tcp=tcp_failure_kind(exc))
    with contextlib.suppress(OSError):  # our messages (a check's run on the peer's agent, the
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)  # next check's) go out at
    holder.sock = sock                  # once, not after the ACK of the one before (Nagle)
    if holder.cancelled:
        sock.close()
        return None, addr, failed("timeout", "cancelled", address=addr)
    return sock, addr, None


def _login(opts: SshOptions | None, sock: object, name: str, port: int, user: str,
           addr: str | None, where: str, deadline: float, holder: Holder) -> Conn:
    """SSH over *sock* (a socket, or a channel through the relay): the server's key checked
    against known_hosts under *name*:*port* (whatever *sock* leads to, as OpenSSH's
    HostKeyAlias), then a key login as *user*. *where* names the server in messages."""
    paramiko = load_paramiko()

    def left() -> float:
        return max(deadline - time.monotonic(), 0.05)

    info = known_host_keys(known_hosts_files(opts), host_key_name(name, port))
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
        with contextlib.suppress(Exception):
            sock.close()  # type: ignore[attr-defined]
        msg = str(exc) or type(exc).__name__
        return failed("sshd", f"{where} port {port} accepted the connection but did not speak "
                             f"SSH properly: {msg}", address=addr)
    try:
        key = t.get_remote_server_key()  # start_client returns quietly on a timeout
    except paramiko.SSHException:
        t.close()
        return failed("sshd", f"{where} port {port} accepted the connection but no SSH "
                             "handshake came within the timeout (not sshd, or a stuck one)",
                     address=addr)
    fp, ktype = key.fingerprint, key.get_name()
    key_text = f"{ktype} {key.get_base64()}"
    blob = key.asbytes()
    if blob in info.revoked:
        t.close()
        return failed("host_key_changed",
                     f"the host key of {name} ({ktype} {fp}) is REVOKED in known_hosts "
                     f"(@revoked): refused. Its keys must be replaced on {name}, then the new "
                     f"key verified: " + verify_commands(name, port, ktype, user) + said,
                     fingerprint=fp, host_key=key_text, address=addr)
    if ktype not in known:
        t.close()
        if known:
            others = ", ".join(known)
            return failed("host_key_changed",
                         f"known_hosts has a {others} key for {name} but the server now offers a "
                         f"{ktype} key ({fp}); refused. If {name} was reinstalled, remove the old "
                         f"entry (ssh-keygen -R {host_key_name(name, port)}) and verify the new one: "
                         + verify_commands(name, port, ktype, user) + said,
                         fingerprint=fp, host_key=key_text, address=addr)
        return failed("host_key_unknown",
                     f"the host key of {name} is not in known_hosts: {ktype} {fp}; not trusted "
                     f"until you confirm it: " + verify_commands(name, port, ktype, user) + said,
                     fingerprint=fp, host_key=key_text, address=addr)
    if blob not in known[ktype]:
        t.close()
        return failed("host_key_changed",
                     f"the host key of {name} CHANGED: known_hosts has "
                     f"{', '.join(info.fingerprints(ktype))}, "
                     f"the server shows {fp}; refused (a reinstall, or someone in the middle). "
                     f"If you know why, remove the old entry with ssh-keygen -R "
                     f"{host_key_name(name, port)} and verify the new one: "
                     + verify_commands(name, port, ktype, user) + said,
                     fingerprint=fp, host_key=key_text, address=addr)
    keys, notes = load_keys(opts)
    if not keys:
        t.close()
        return failed("auth", f"no SSH key to log in to {name} with: create one (ssh-keygen -t "
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
            return Conn(SshResult(True, None, "", "", None,
                                   f"logged in to {where} as {user} with a key" + said,
                                   fp, key_text, addr, "connected"), t, said)
    t.close()
    if holder.cancelled or time.monotonic() >= deadline:
        return failed("timeout", f"no login to {name} within the timeout", fingerprint=fp,
                     host_key=key_text, address=addr)
    return failed("auth", f"{name} refused our SSH keys for user {user} ({last}): copy a key with "
                         f"ssh-copy-id {user}@{name}" + (f"; {'; '.join(notes)}" if notes else ""),
                 fingerprint=fp, host_key=key_text, address=addr)


class JumpSock:
    """A ``direct-tcpip`` channel on the relay's connection, as the socket of the connection to
    the peer behind it: closing it closes the relay's connection too."""

    def __init__(self, chan: paramiko.Channel, relay: paramiko.Transport) -> None:
        self.chan, self.relay = chan, relay

    def __getattr__(self, attr: str) -> object:
        return getattr(self.chan, attr)

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.chan.close()
        with contextlib.suppress(Exception):
            self.relay.close()


CHANNEL_CONNECT_FAILED = 2   # RFC 4254 7.1: nothing accepted the connection at the far end


def _jump(opts: SshOptions | None, route: RelayRoute, tunnel: int, peer: Peer, deadline: float,
          holder: Holder, tcp_deadline: float | None) -> Conn:
    """*peer* through the relay: log in to the relay (its host key checked as any other), open
    a ``direct-tcpip`` channel to the relay's 127.0.0.1:*tunnel*, where *peer*'s reverse tunnel
    ends, and speak SSH to *peer* over it (its key checked under its own name)."""
    paramiko = load_paramiko()

    name, port, user = peer.name, int(peer.ssh_port or 22), peer.ssh_user
    via = f"the relay {route.host}"
    sock, addr, bad = _tcp(route.host, route.port, deadline, holder, tcp_deadline)
    if sock is None:
        assert bad is not None
        return failed("relay", f"{name} is reached through {via}, and {bad.result.detail}",
                     tcp=None)
    hop = _login(opts, sock, route.host, route.port, route.user, addr, f"{route.host} ({addr})",
                 deadline, holder)
    relay_t = hop.transport
    if relay_t is None:
        return failed("relay", f"{name} is reached through {via}, and there: "
                               f"{hop.result.detail}", tcp=None)
    try:
        chan = relay_t.open_channel("direct-tcpip", ("127.0.0.1", tunnel), ("127.0.0.1", 0),
                                    timeout=max(deadline - time.monotonic(), 0.05))
    except paramiko.ChannelException as exc:
        relay_t.close()
        if exc.code == CHANNEL_CONNECT_FAILED:
            return failed("network", f"{name}'s tunnel is down: nothing answers at "
                                     f"127.0.0.1:{tunnel} on {via} (`rosnet-tui relay tunnel` "
                                     f"keeps it up on {name})", tcp="refused")
        return failed("relay", f"{via} does not let {route.user} reach 127.0.0.1:{tunnel} "
                               f"({exc.text or exc.code}): its sshd's AllowTcpForwarding, or "
                               "permitopen in its authorized_keys", tcp=None)
    except Exception as exc:  # noqa: BLE001 - the relay's connection died or did not answer
        relay_t.close()
        if holder.cancelled or time.monotonic() >= deadline:
            return failed("timeout", f"no SSH connection to {name} through {via} within the "
                                     "timeout", tcp=None)
        return failed("relay", f"{via} did not open a way to {name}: "
                               f"{str(exc) or type(exc).__name__}", tcp=None)
    if holder.cancelled:
        relay_t.close()
        return failed("timeout", "cancelled", tcp=None)
    return _login(opts, JumpSock(chan, relay_t), name, port, user, None,
                  f"{name} (through {via}, 127.0.0.1:{tunnel})", deadline, holder)


def connect_blocking(opts: SshOptions | None, peer: Peer, deadline: float,
                      holder: Holder, tcp_deadline: float | None = None) -> Conn:
    """Connect and log in to *peer* by the one way every SSH use takes: directly, or through
    the relay when *opts* has a relay with a tunnel for *peer*. Never raises for the network."""
    name, port, user = peer.name, int(peer.ssh_port or 22), peer.ssh_user
    if not user:
        return failed("no_user", f"no SSH user is set for {name} in the settings", tcp=None)
    route = getattr(opts, "relay", None)
    tunnel = route.tunnel_port(name) if route is not None else None
    if route is not None and tunnel is not None:
        return _jump(opts, route, tunnel, peer, deadline, holder, tcp_deadline)
    sock, addr, bad = _tcp(name, port, deadline, holder, tcp_deadline)
    if sock is None:
        assert bad is not None
        return bad
    return _login(opts, sock, name, port, user, addr, f"{name} ({addr})", deadline, holder)


async def connect(opts: SshOptions | None, peer: Peer, timeout: float,
                   tcp_timeout: float | None = None) -> Conn:
    holder = Holder()
    now = time.monotonic()
    deadline = now + timeout
    tcp_deadline = None if tcp_timeout is None else now + min(tcp_timeout, timeout)
    try:
        return await run_blocking(connect_blocking, opts, peer, deadline, holder, tcp_deadline,
                                  timeout=timeout + 0.5)
    except asyncio.TimeoutError:
        holder.close()
        return failed("timeout", f"no SSH connection to {peer.name} within {timeout:.1f} s",
                     tcp=None if holder.sock is None else "connected")
    except Exception as exc:  # noqa: BLE001 - a failure is a result, never an exception
        holder.close()
        return failed("sshd", f"the SSH connection to {peer.name} broke: "
                             f"{type(exc).__name__}: {exc}")
    except BaseException:
        holder.close()
        raise
