"""Step 3, Linux: what its checks report in ``data``.

One TypedDict per check id; the comment on each key is its documentation (see
:mod:`rosnet_tui.core.checks.data`)."""

from __future__ import annotations

from typing import Literal, TypedDict

from rosnet_tui.core.checks.data.kinds import TcpKind


# ---- step 3, Linux (rosnet_tui/core/checks/linux.py)
class HostsWrong(TypedDict, total=False):
    name: str      # a name the hosts file maps to the wrong address
    found: str     # the address found there
    expected: str  # the address it should be


class LinuxHostsData(TypedDict, total=False):
    missing: list[str]        # names with no IPv4 entry in the hosts file
    wrong: list[HostsWrong]   # names mapped to another (non-loopback) address
    duplicates: list[str]     # names on several lines with different addresses
    loopback: list[str]       # names mapped to a loopback address (127.x) that should not be


class AddressDated(TypedDict, total=False):
    ip: str       # the address this source gives for the component
    by: Literal["settings", "sync"]  # "settings": the settings file holding it was saved then;
    #                                  "sync": the component's own address record (applied here)
    at: str       # when (ISO 8601, UTC): the file's modification time, or the record's timestamp
    age_s: float  # seconds from then until this check ran (0 for a time in the future)


class Resolved(TypedDict, total=False):
    resolved: str | None  # the first IPv4 address the resolver gave (None: does not resolve)
    expected: str         # the address the settings expect
    dated: list[AddressDated]  # peers: what says when their address was last confirmed, newest
    #                            first ([]: nothing here dates it)


class LinuxResolveData(TypedDict, total=False):
    names: dict[str, Resolved]  # every expected name, by name
    wrong: list[str]            # names that do not resolve, or resolve to another address
    loopback: list[str]         # names that resolve to a loopback address and should not
    unpinned: list[str]         # peers sync cannot follow ([sync] on, no sync_key pinned)


class PingPeer(TypedDict, total=False):
    icmp: bool | None   # answered ping by name (None: ping could not run here)
    tcp22: bool         # accepted a TCP connection on its SSH port (the fallback when ICMP is filtered)
    tcp: TcpKind | Literal["resolve"]  # how that TCP connection went ("resolve": no address)
    port: int           # the SSH port tried (ssh_port of the peer)


class LinuxPingData(TypedDict, total=False):
    peers: dict[str, PingPeer]  # by peer name


class SshPeer(TypedDict, total=False):
    ok: bool                # a command ran over SSH (key login, host key verified)
    failure: str | None     # why not: network, resolve, host_key_unknown, host_key_changed,
    #                         auth, sshd, timeout, relay (at the relay), no_user (none set)
    fingerprint: str | None  # SHA256:... of the peer's host key, when seen
    host_key: str | None    # "<type> <base64>" of that key (for trusting it after a comparison)
    address: str | None     # the address the peer's name resolved to here
    detail: str             # what happened, in words
    tcp: TcpKind | None     # how the TCP connection to its SSH port went (None: not tried)
    port: int               # the SSH port tried (ssh_port of the peer)


class LinuxSshData(TypedDict, total=False):
    peers: dict[str, SshPeer]  # by peer name (every peer, those without an SSH user too)


class LinuxFirewallData(TypedDict, total=False):
    security: str            # [ros] security: "firewall", "none" (opted out), "mtls" (ROS 2)
    wanted: bool             # the settings ask for the table (ROS 1, security "firewall")
    present: bool | None     # our table (table inet rosnet_tui) is loaded (None: not readable)
    readable: bool | None    # nftables could be read (reading needs root)
    allowed: list[str]       # the addresses in our set now
    expected: list[str]      # the peers' current addresses (the profile's: public or LAN)
    missing: list[str]       # peers' addresses not in the set (those peers are shut out)
    extra: list[str]         # addresses in the set no peer has now (stale: a past address)
    rules_match: bool | None  # the table's rules are the ones the settings give
    lan: list[str]           # this machine's LAN networks in the table (SSH and ROS)
    allow: list[str]         # [firewall] allow entries in the table (SSH)
    sessions: list[str]      # the session kept in by the last apply: "address . sshd port"
    expected_lan: list[str]  # this machine's LAN networks now (private, link-local, ULA)
    expected_allow: list[str]  # [firewall] allow of the settings, merged
    client: str | None       # the address this check runs from over SSH (None: not over SSH)
    client_in: str | None    # why that address gets in ("": it would not; None: not judged)


class ChatPeer(TypedDict, total=False):
    ok: bool             # the message went both ways
    failure: str | None  # where it broke: no_user, ssh:<SSH failure>, resolve, peer_resolve,
    #                      connect, peer_listen, local_listen, wrong_peer, no_message
    tcp: TcpKind         # how the chat's own TCP connection went (absent: it was not tried)


class LinuxChatData(TypedDict, total=False):
    peers: dict[str, ChatPeer]  # by peer name


DATA: dict[str, type] = {
    "linux.hosts": LinuxHostsData,
    "linux.resolve": LinuxResolveData,
    "linux.ping": LinuxPingData,
    "linux.ssh": LinuxSshData,
    "linux.chat_out": LinuxChatData,
    "linux.chat_in": LinuxChatData,
    "linux.firewall": LinuxFirewallData,
}
