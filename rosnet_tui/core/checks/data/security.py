"""Security: what its checks report in ``data``.

One TypedDict per check id; the comment on each key is its documentation (see
:mod:`rosnet_tui.core.checks.data`)."""

from __future__ import annotations

from typing import Literal, TypedDict

from rosnet_tui.core.checks.data.kinds import TcpKind

# ---- security (rosnet_tui/core/checks/security.py; issue 22)
SecuritySshAuthData = TypedDict("SecuritySshAuthData", {
    "target": str,  # this component's address the peer dialled (the public IP the internet sees, else the settings'; a LAN profile: name)
    "port": int,  # the SSH port dialled there
    "user": str,  # the user auth_none asked for (this component's login user)
    "from": str,  # the peer that looked ("": none could)
    "reachable": bool,  # something answered TCP there (False: refused, dropped or no route from every peer that looked: sshd is out of the internet's reach)
    "tcp": TcpKind,  # how that peer's TCP connection to target:port went
    "methods": list[str],  # what sshd offers that user, unauthenticated (auth_none's allowed types)
    "root_methods": list[str],  # what it offers the user root (how a root password login is seen)
    "password": bool,  # "password" is offered
    "keyboard_interactive": bool,  # "keyboard-interactive" is offered
    "root_password": bool,  # password or keyboard-interactive is offered to root
    "error": str,  # why the offered methods could not be read
    "local_methods": list[str],  # not reachable: what this machine's sshd offers the user over loopback
    "local_root_methods": list[str],  # not reachable: what it offers root over loopback
    "ssh_failures": dict[str, str],  # by peer: how SSH to it failed (ssh FAILURES: "resolve"...) when the audit could not run there
}, total=False)


class OutsiderAttempt(TypedDict, total=False):
    result: str  # ROS 2: accepted, alert, closed, not_tls, server_cert, no_fleet_cert, refused, timeout (no answer in time)
    detail: str  # the TLS alert, the verify message, or the error seen


class MasterCertData(TypedDict, total=False):
    names: list[str]  # the Common Name and subjectAltNames of the master's router certificate
    not_after: str    # its expiry (ISO 8601, UTC)
    expired: bool     # it has expired


OutsiderCause = Literal["security_off", "plain_open", "no_mtls", "no_fleet_cert", "foreign_ca",
                        "expired", "wrong_name", "unreachable", "refused", "firewall_missing",
                        "insider_blocked", "checker_unavailable", "no_verdict"]


SecurityOutsiderData = TypedDict("SecurityOutsiderData", {
    "security": str,  # [ros] security as read ("mtls", "firewall", "none")
    "ros": int,  # the ROS version judged (1 or 2)
    "target": str,  # ROS 2: master:zenoh_port; ROS 1: this component's public IP
    "from": str,  # where the probe ran: a member's name, or "here" (a member's seat)
    "attempts": dict[str, OutsiderAttempt],  # ROS 2, by attempt: no_cert, foreign, plain, insider
    "master_cert": MasterCertData,  # ROS 2: the certificate the master's port presented
    "ports": list[int],  # ROS 1: the ports tried (the master's port on the master, a range port)
    "outsider_reachable": dict[str, bool | None],  # ROS 1, by port: the port checker got in (None: no verdict)
    "insider_reachable": dict[str, bool],  # ROS 1, by port: the peer got in
    "outsider_s": dict[str, float | None],  # ROS 1, by port: seconds until the port checker's verdict
    "cause": OutsiderCause | None,  # why it failed (None: it passed)
    "ssh_failures": dict[str, str],  # by peer: how SSH to it failed (as in security.ssh_auth) when the probe could not run there
}, total=False)


DATA: dict[str, type] = {
    "security.ssh_auth": SecuritySshAuthData,
    "security.outsider": SecurityOutsiderData,
}
