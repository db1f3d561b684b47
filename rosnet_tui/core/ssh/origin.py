"""The SSH session this process runs in: the client's address and the sshd port it reached.

What keeps a technician from being locked out (the firewall admits the session that loads it,
``linux.firewall`` warns when the session running a check would not get back in). Read from
SSH_CONNECTION or SSH_CLIENT; under sudo, whose env_reset drops them, from the shell that ran
sudo; else from the terminal's login record.
"""

from __future__ import annotations

import ipaddress
import os
from collections.abc import Mapping
from dataclasses import dataclass

SSH_PORT = 22
SESSION_VARS = ("SSH_CONNECTION", "SSH_CLIENT")
ELEVATORS = ("sudo", "doas")          # what may stand between the user's shell and us
ANCESTORS_MAX = 8


class SessionError(ValueError):
    """The SSH session running us cannot be told apart (an address that does not parse)."""


@dataclass(frozen=True)
class Session:
    """Where an SSH session comes from: the client's address and the port of this machine's sshd
    it is connected to; *source* says where that was read."""

    address: str
    port: int = SSH_PORT
    source: str = ""

    @property
    def element(self) -> str:
        return f"{self.address} . {self.port}"


def parse_session(value: str, var: str, source: str = "") -> Session:
    """*value* of SSH_CONNECTION ("client port server port") or SSH_CLIENT ("client port
    port"); refuses (SessionError) one whose first field is no IP address."""
    fields = value.split()
    raw = fields[0] if fields else ""
    try:
        addr = ipaddress.ip_address(raw.split("%")[0])
    except ValueError:
        raise SessionError(f"{var} is set, but its first field '{raw[:40]}' is not an IP "
                           "address, so the address of this SSH session is not known") from None
    if addr.version == 6 and addr.ipv4_mapped is not None:
        addr = addr.ipv4_mapped
    want = 4 if var == "SSH_CONNECTION" else 3
    port = SSH_PORT
    if len(fields) >= want and fields[want - 1].isdigit() and 0 < int(fields[want - 1]) < 65536:
        port = int(fields[want - 1])
    return Session(str(addr), port, source or var)


def session_from_env(environ: Mapping[str, str]) -> Session | None:
    """The session named by SSH_CONNECTION (else SSH_CLIENT) in *environ*; None when neither
    is set."""
    for var in SESSION_VARS:
        value = (environ.get(var) or "").strip()
        if value:
            return parse_session(value, var)
    return None


def _session_before_sudo() -> Session | None:
    """Run by sudo (whose env_reset drops SSH_CONNECTION): the session of the shell that ran
    sudo, from its environment (root may read it)."""
    import psutil

    try:
        proc = psutil.Process().parent()
        hops = 0
        if proc is None or proc.name() not in ELEVATORS:
            return None
        while proc is not None and proc.name() in ELEVATORS and hops < ANCESTORS_MAX:
            proc, hops = proc.parent(), hops + 1
        if proc is None:
            return None
        env = proc.environ()
    except (psutil.Error, OSError):
        return None
    found = session_from_env(env)
    if found is None:
        return None
    return Session(found.address, found.port, f"{found.source} of the shell that ran sudo")


def _session_of_terminal() -> Session | None:
    """The login record of this process's terminal (what `who am i` shows): sshd writes the
    client's address there. Only an IP address counts (tmux, screen and X write other words)."""
    import psutil

    try:
        tty = psutil.Process().terminal()
        users = psutil.users() if tty else []
    except (psutil.Error, OSError):
        return None
    for u in users:
        if tty and f"/dev/{u.terminal}" == tty and u.host:
            try:
                addr = ipaddress.ip_address(u.host.split("%")[0])
            except ValueError:
                return None
            return Session(str(addr), SSH_PORT, f"the login record of {u.terminal}")
    return None


def detect_session() -> Session | None:
    """The SSH session this process runs in: SSH_CONNECTION or SSH_CLIENT; under sudo (which
    drops them) the ones of the shell that ran sudo; else the login record of the terminal.
    None: not over SSH, as far as can be told. Raises SessionError for an unreadable one."""
    return (session_from_env(os.environ) or (_session_before_sudo() if os.geteuid() == 0
                                              else None) or _session_of_terminal())
