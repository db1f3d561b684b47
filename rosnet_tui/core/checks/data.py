"""What each check reports in its ``data``: declared per check id, the ``check --json`` contract.

Checks produce plain dicts (their JSON form is unchanged); the declarations below say which keys
each check id may carry and what they hold. Consumers (the advisor's rules, the UI, the report)
read the data through :func:`view`, which refuses a key that no check declares: a renamed key
fails the ordinary test run instead of silently switching a rule off. Producers are held to the
same declarations by :func:`undeclared` (the check runner calls it in strict mode, which the
test suite turns on).

Standard library only: the advisor depends on it, not on any check module.
"""

from __future__ import annotations

import os
import types
import typing
from collections.abc import Iterator, Mapping
from typing import Any, Literal, TypedDict

STRICT_ENV = "ROSNET_TUI_STRICT_DATA"


def strict() -> bool:
    """True when undeclared keys must raise (the test suite sets ROSNET_TUI_STRICT_DATA=1)."""
    return os.environ.get(STRICT_ENV, "") not in ("", "0")


# --------------------------------------------------------------------------- declarations
# One TypedDict per check id (total=False: a check sets the keys its verdict has evidence for; a
# skip may carry only a few). Nested shapes (per-peer dicts, port rows) are TypedDicts too, which
# :func:`view` and :func:`undeclared` follow. The comment on each key is its documentation;
# docs/COMMANDS.md's table of the checks lists the top-level keys. Values are JSON (dict keys: str).

# How a TCP connection attempt went (rosnet_tui/core/net/connect.py): "connected"; "refused" (something
# at the address answered with a reset: online, rejecting the port); "timeout" (nothing answered:
# dropped); "unreachable" (an ICMP error: no route, or no machine where a modem forwards to);
# "error" (anything else).
TcpKind = Literal["connected", "refused", "timeout", "unreachable", "error"]


# ---- step 1, ISP (rosnet_tui/core/checks/isp.py)
class EndpointData(TypedDict, total=False):
    dns_ok: bool | None   # the endpoint's host name resolved (None: an IP address, not asked)
    http_ok: bool | None  # a GET answered with HTTP 2xx (None: not tried, the name did not resolve)


class IspInternetData(TypedDict, total=False):
    dns_ok: bool | None   # name resolution of `url` worked (None: not asked, or skipped)
    http_ok: bool | None  # the GET of `url` answered with HTTP 2xx (None: not tried, or skipped)
    failed_part: Literal["dns", "http"] | None  # what broke when not everything works
    url: str              # the endpoint the verdict describes (the first failing one if some work)
    endpoints: dict[str, EndpointData]  # every endpoint asked, by URL


class PublicIpSeen(TypedDict, total=False):
    ip: str          # a public address this component had
    first_seen: str  # when it was first seen (ISO 8601, UTC)
    last_seen: str   # when it was last seen (ISO 8601, UTC)


class IspPublicIpData(TypedDict, total=False):
    public_ip: str | None  # the address the internet sees (None: unknown, or the services disagree)
    sources: dict[str, str]  # by service URL: the address it answered, or "error: <why>"
    agree: bool              # every configured service answered the same address
    settings_ip: str         # this.public_ip from the settings ("" when not set)
    matches_settings: bool | None  # public_ip equals settings_ip (None: no address in the settings)
    previous_ip: str | None  # the address recorded before this one (None: none yet)
    changed: bool            # the address differs from the one recorded last time
    history: list[PublicIpSeen]  # the addresses recorded so far, oldest first


class IspCgnatData(TypedDict, total=False):
    wan_ip: str | None   # the modem's internet-side address as it told (UPnP IGD, NAT-PMP; "": it reports none; None: not told)
    method: Literal["none", "upnp", "traceroute"]  # how the verdict was reached ("upnp": the modem's own word)
    cgnat: bool          # carrier-grade NAT (100.64.0.0/10) seen on the way out
    double_nat: bool     # a second private NAT seen on the way out
    hop: str | None      # the address that shows the NAT (None: no NAT seen)
    hops: list[str | None]  # traceroute: the address answering at each TTL (None: no answer)
    source: str          # traceroute: this machine's source address towards the target


# ---- step 2, Router/modem (rosnet_tui/core/checks/router.py)
class RouterLocalIpData(TypedDict, total=False):
    local_ip: str     # the interface's IPv4 address ("" when the interface is down or has none)
    interface: str    # the interface used (this.interface, else the default route's)
    gateway: str      # the default gateway through that interface ("" when none)
    expected_ip: str  # this.local_ip from the settings: where the modem forwards to ("" if unset)
    differs: bool     # expected_ip is set and is not local_ip
    previous_ip: str | None  # the local IP recorded on the run before (None: none yet)
    changed: bool     # the local IP differs from the one recorded on the run before
    history: list[PublicIpSeen]  # the local IPs recorded so far, oldest first


class RouterPortFreeData(TypedDict, total=False):
    port: int            # the test port (probe.port)
    in_use: bool         # another process holds it
    process: str | None  # that process's command line (None: unknown or free)
    pid: int | None      # its pid (None: free, or another user's process)


class RouterListenerData(TypedDict, total=False):
    port: int         # the test port (probe.port)
    listening: bool   # our listener answered on it


# How a port answered the peer's test: "token" (our listener, its token read), "other" (accepted,
# but another program answered: forwarded elsewhere), or how the connection failed ("refused",
# "timeout", "unreachable", "error"; see TcpKind).
PortAnswer = Literal["token", "other", "refused", "timeout", "unreachable", "error"]


class PortRow(TypedDict, total=False):
    port: int               # a TCP port tested from outside
    reachable: bool | None  # open from outside (None: could not be tested)
    listener: bool          # our own listener held it during the test (True for others' services)
    via: str                # who tested: "peer:<name>" over SSH, or "echoip" (the port checker)
    answer: PortAnswer | None  # how it answered the peer (None: the port checker tells only
    #                            open or closed, or, under ROS 2, the test port was not waited
    #                            for once zenoh_port answered; see PortAnswer)


class RouterPortOpenData(TypedDict, total=False):
    ports: list[PortRow]    # the test port, two random ports, then 22 / the ROS port when in use
    test_port: int          # the test port (probe.port)
    test_port_open: bool | None  # the test port is open from outside (None: could not be tested)
    public_ip: str | None   # the address tested (None: unknown)
    public_ip_ping: bool | None  # the peer's ping of public_ip was answered (None: not asked)
    # ROS 2 (the master's modem forwards TCP zenoh_port only; test_port_open is then left out):
    zenoh_port: int         # the master's Zenoh router port
    zenoh_port_open: bool | None  # open from outside (None: could not be tested)
    zenoh_listener: Literal["router", "ours", "none"]  # who answered on it during the test


# ---- step 2, the modem's own word (rosnet_tui/core/checks/router_upnp.py)
class UpnpForwardRow(TypedDict, total=False):
    protocol: str          # "TCP" | "UDP"
    external_port: int     # the port on the modem's internet side
    internal_client: str   # where the modem forwards it (this machine's local IP here)
    internal_port: int     # the port there
    description: str       # the forward's label on the modem
    lease_s: int           # seconds of lease left (0: no expiry)
    ours: bool             # made by rosnet-tui (recorded, or labelled rosnet-tui)


class UpnpConflict(TypedDict, total=False):
    port: int              # a port this component needs
    internal_client: str   # the other machine the modem forwards it to
    description: str       # that forward's label on the modem


class RouterUpnpData(TypedDict, total=False):
    protocol: Literal["upnp", "pcp", "natpmp"] | None  # what rosnet-tui would map with (None: no modem)
    protocols: list[str]   # every protocol the modem answered
    gateway: str | None    # the modem asked (the default gateway)
    external_ip: str | None  # its external address as it reports it ("": none; None: not told)
    wan: Literal["public", "private", "shared", "none", "unknown"]  # what kind of address that is
    cgnat: bool            # the modem's own word points to carrier-grade NAT (no or shared address)
    needed: list[int]      # the TCP ports the settings call for (ROS 2 master: zenoh_port)
    present: list[int]     # needed ports the modem forwards to this machine
    missing: list[int]     # needed ports it does not forward
    conflicts: list[UpnpConflict]  # needed ports it forwards to another machine
    forwards: list[UpnpForwardRow]  # the modem's forwards that point at this machine (UPnP only)
    can_list: bool         # the protocol can list forwards (UPnP IGD; not NAT-PMP or PCP)
    range_needed: bool     # ROS 1: the whole range is needed, which no protocol maps
    tried: list[str]       # what was asked and what came back, in words


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
    #                         auth, sshd, timeout, no_user (no ssh_user in the settings)
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


# ---- step 4, ROS (rosnet_tui/core/checks/ros.py)
class RosEnvData(TypedDict, total=False):
    env_uri: str | None      # ROS_MASTER_URI in the environment (None: not set)
    bashrc_uri: str | None   # ROS_MASTER_URI exported in ~/.bashrc (None: not there)
    expected_uri: str        # what it should be for this role ("" when no master is configured)
    uri_ok: bool             # set, and right, in both places
    ros_ip: str | None       # ROS_IP (environment first, then ~/.bashrc; None: not set)
    ros_hostname: str | None  # ROS_HOSTNAME (likewise)


class RosMasterData(TypedDict, total=False):
    uri: str                 # the master URI asked ("" when no master is configured)
    reachable: bool          # the master answered getSystemState
    topics: list[list[str]]  # [name, type] of each topic (the probes of rosnet-tui left out)
    nodes: list[str]         # the nodes the master knows (the probes of rosnet-tui left out)
    tcp: TcpKind             # how the connection to the master went (absent: not tried)


UnreachableNode = TypedDict("UnreachableNode", {
    "node": str,    # the node's name
    "uri": str,     # the URI it advertises
    "host": str,    # the host part of that URI
    "reason": str,  # why it cannot be reached (or could not be checked)
    "from": str,    # where it was tested from: "here" or a peer's name
}, total=False)

RosNodeUrisData = TypedDict("RosNodeUrisData", {
    "unreachable": list[UnreachableNode],  # nodes that cannot be reached, the user's own first
    "checked": int,     # how many distinct nodes were checked
    "from": list[str],  # where the nodes were tested from: "here", then peer names
}, total=False)

FailedHop = Literal["registration", "xmlrpc_callback", "tcpros", "no_message"]


class PubsubPeer(TypedDict, total=False):
    peer: str                 # the peer on the other side of the exchange
    ok: bool                  # the message arrived
    failed_hop: FailedHop | None  # where it broke (None: it did not, or the probe could not run)
    node: str | None          # the node whose address failed, when known
    uri: str | None           # the URI that failed (the node's, or the master's at registration)


class RosPubsubData(PubsubPeer, total=False):
    # The keys above describe the worst peer's exchange ("" as peer when none could run).
    peers: dict[str, PubsubPeer]  # every peer's exchange, by peer name


# ---- step 4, ROS 2 over rmw_zenoh (rosnet_tui/core/checks/ros2.py)
class Ros2EnvData(TypedDict, total=False):
    rmw: str | None           # RMW_IMPLEMENTATION in the environment (None: not set)
    bashrc_rmw: str | None    # RMW_IMPLEMENTATION exported in ~/.bashrc (None: not there)
    rmw_ok: bool              # rmw_zenoh_cpp in both places
    dds: bool                 # no RMW_IMPLEMENTATION, or a DDS one: DDS cannot cross the modems
    domain_id: str | None     # ROS_DOMAIN_ID as set (environment first, then ~/.bashrc; None: unset = 0)
    expected_domain_id: int   # [ros] domain_id
    domain_ok: bool           # the domain id matches the settings
    distro: str | None        # ROS_DISTRO here (None: not set: no ROS 2 sourced)
    peer_distros: dict[str, str | None]  # by peer name: its ROS_DISTRO over SSH (None: unknown)
    distro_mismatch: list[str]  # peers whose ROS_DISTRO differs from ours
    client_mode: bool         # nodes here connect to the master in client mode (no router here)
    override: str | None      # ZENOH_CONFIG_OVERRIDE (None: not set)
    router_config: str | None  # the file ZENOH_ROUTER_CONFIG_URI names (None: not set)
    router_listen: list[str]  # listen endpoints of that file
    router_connect: list[str]  # connect endpoints of that file
    config_problems: list[str]  # what is wrong in the override or the router's config, in words
    warnings: list[str]       # localhost_only, discovery_localhost, dds_settings,
    #                           session_config (what was found; see the evidence)


class LocalRouter(TypedDict, total=False):
    reachable: bool           # a Zenoh session opened on this machine's router
    endpoint: str             # where it was looked for
    zid: str | None           # its Zenoh id
    version: str | None       # its Zenoh version (from its admin space)
    routers: list[str]        # ids of the routers it has sessions with (a member's: the master's)
    failure: str | None       # why no session opened


TlsProblem = Literal["missing", "unreadable", "foreign_ca", "wrong_name", "expired", "expiring"]
TlsHandshake = Literal["missing", "wrong_name", "master_foreign_ca", "rejected_expired",
                       "rejected_foreign", "no_tls", "unreachable"]


class FleetTls(TypedDict, total=False):
    problem: TlsProblem | None  # what is wrong with this component's fleet certificate
    cn: str                   # its Common Name
    sans: list[str]           # the names (and addresses) it carries
    not_after: str            # when it expires (ISO 8601, UTC)
    days_left: float          # days until then (warned at 30 and fewer)
    handshake: TlsHandshake | None  # why a TLS handshake failed (asked when no session opened)


class Ros2RouterData(TypedDict, total=False):
    role: Literal["master", "member"]  # this component's role
    endpoint: str             # the router dialled: tls/<master or relay>:<port> (tcp/: no mTLS)
    address: str | None       # the master's name resolved here (None: it does not resolve)
    reachable: bool           # a Zenoh session opened on the master's router
    failure: Literal["resolve", "refused", "timeout", "unreachable", "not_zenoh", "open"] | None  # why not reachable
    router_zid: str | None    # the master's router's Zenoh id
    router_version: str | None  # its Zenoh version (None: admin space off)
    locators: list[str]       # what it says it listens on
    listening: list[str]      # master: the addresses zenoh_port is listened on here (psutil)
    listen_problem: Literal["loopback", "ipv6_only", "not_running"] | None  # master: why the forward cannot reach it
    ipv6: bool                # this host has IPv6 (tcp/[::] needs it)
    remote_peers: list[str]   # sessions in *peer* mode attached to the master's router from
    #                           another machine (lone nodes that should be clients)
    local_router: LocalRouter  # this machine's own router (every component runs one)
    security: Literal["mtls", "firewall", "none"]  # [ros] security
    tls: FleetTls             # under mTLS: this component's fleet certificate


class GraphNode(TypedDict, total=False):
    name: str                 # the node's fully qualified name (/ns/name)
    zid: str                  # the Zenoh session it lives in
    component: str | None     # the component it runs on, when known (None: unknown)
    humble: bool              # its topics carry Humble's TypeHashNotSupported


class Ros2GraphData(TypedDict, total=False):
    nodes: list[GraphNode]    # the nodes seen from here (rosnet-tui's probes left out)
    topics: list[list[str]]   # [topic, type] of every publisher and subscription seen
    seen_from: list[str]      # where the graph was read: "here", then peers' names
    missing: list[str]        # components whose nodes (or probe node) are not seen from here
    probe_seen: dict[str, bool]  # by peer name: its probe node is seen here
    ours_seen: dict[str, bool]   # by peer name: our probe node is seen there
    mixed_hashes: bool        # Humble nodes (TypeHashNotSupported) next to Jazzy-or-later ones


Ros2Hop = Literal["our_router", "master_router", "peer_router", "peer_subscriber",
                  "our_subscriber", "data_dropped"]


class Ros2PubsubPeer(TypedDict, total=False):
    peer: str                 # the peer on the other side of the exchange
    ok: bool                  # the message arrived (with rmw_zenoh's attachment)
    failed_hop: Ros2Hop | None  # where it broke (None: it did not, or the peer side could not run)
    graph_seen: bool | None   # the receiving side saw the sender's publisher token
    detail: str | None        # the last thing seen at the failed hop


class Ros2PubsubData(Ros2PubsubPeer, total=False):
    # The keys above describe the worst peer's exchange ("" as peer when none could run).
    peers: dict[str, Ros2PubsubPeer]  # every peer's exchange, by peer name


# ---- step 4, both ROS versions: web clients (rosnet_tui/core/checks/rosbridge.py)
RosbridgeHop = Literal["name", "forward", "upgrade", "bridge", "rosapi", "round_trip"]


class RosRosbridgeData(TypedDict, total=False):
    host: str                 # the component running rosbridge ([rosbridge] host, else the master)
    url: str                  # what a browser opens: ws://<host>:<port>/
    address: str | None       # the host's name resolved here (None: it does not, or not tried)
    tcp: TcpKind | None       # how the TCP connection to the bridge's port went (None: not tried)
    upgraded: bool            # the HTTP upgrade to WebSocket was accepted (101)
    rosapi: bool              # call_service /rosapi/topics answered with a topic list
    topics: list[str]         # the topics it listed (rosnet-tui's probes left out; at most 200)
    round_trip: bool          # a publish through one WebSocket reached a subscribe on another
    round_trip_ms: float | None  # how long that took (None: it did not)
    failed_hop: RosbridgeHop | None  # where it broke (None: it did not, or it was skipped)
    detail: str | None        # what was seen at the failed hop


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
    result: str  # ROS 2: accepted, alert, closed, not_tls, server_cert, no_fleet_cert, refused
    detail: str  # the TLS alert, the verify message, or the error seen


class MasterCertData(TypedDict, total=False):
    names: list[str]  # the Common Name and subjectAltNames of the master's router certificate
    not_after: str    # its expiry (ISO 8601, UTC)
    expired: bool     # it has expired


OutsiderCause = Literal["security_off", "plain_open", "no_mtls", "no_fleet_cert", "foreign_ca",
                        "expired", "wrong_name", "unreachable", "refused", "firewall_missing",
                        "insider_blocked", "checker_unavailable"]


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
    "isp.internet": IspInternetData,
    "isp.public_ip": IspPublicIpData,
    "isp.cgnat": IspCgnatData,
    "router.local_ip": RouterLocalIpData,
    "router.port_free": RouterPortFreeData,
    "router.listener": RouterListenerData,
    "router.port_open": RouterPortOpenData,
    "router.upnp": RouterUpnpData,
    "linux.hosts": LinuxHostsData,
    "linux.resolve": LinuxResolveData,
    "linux.ping": LinuxPingData,
    "linux.ssh": LinuxSshData,
    "linux.chat_out": LinuxChatData,
    "linux.chat_in": LinuxChatData,
    "linux.firewall": LinuxFirewallData,
    "ros.env": RosEnvData,
    "ros.master": RosMasterData,
    "ros.node_uris": RosNodeUrisData,
    "ros.pubsub_out": RosPubsubData,
    "ros.pubsub_in": RosPubsubData,
    "ros2.env": Ros2EnvData,
    "ros2.router": Ros2RouterData,
    "relay.router": Ros2RouterData,   # the relay's router, as this component's router dials it
    "ros2.graph": Ros2GraphData,
    "ros2.pubsub_out": Ros2PubsubData,
    "ros2.pubsub_in": Ros2PubsubData,
    "ros.rosbridge": RosRosbridgeData,
    "security.ssh_auth": SecuritySshAuthData,
    "security.outsider": SecurityOutsiderData,
}


# --------------------------------------------------------------------------- the mechanism
class UndeclaredKeyError(Exception):
    """A consumer read, or a producer wrote, a key that the check's declaration does not have.

    Deliberately not a KeyError: ``Mapping.get`` would swallow that and return the default.
    """


_HINTS: dict[type, dict[str, Any]] = {}


def _hints(td: type) -> dict[str, Any]:
    if td not in _HINTS:
        _HINTS[td] = typing.get_type_hints(td)
    return _HINTS[td]


def declared_keys(check_id: str) -> frozenset[str]:
    """The keys *check_id* may report (empty for an unknown id)."""
    td = DATA.get(check_id)
    return frozenset(_hints(td)) if td is not None else frozenset()


def _strip(tp: Any) -> Any:
    """``X | None`` -> X; NotRequired/Required[X] -> X."""
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(args) == 1:
            return _strip(args[0])
    return tp


def _wrap(value: Any, tp: Any, where: str) -> Any:
    """Wrap nested dicts whose declared type is a TypedDict (directly, in a list, as dict values)."""
    tp = _strip(tp)
    if typing.is_typeddict(tp) and isinstance(value, dict):
        return CheckData(where, value, tp)
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if origin in (list, tuple) and args and isinstance(value, list):
        inner = _strip(args[0])
        if typing.is_typeddict(inner):
            return [CheckData(f"{where}[]", v, inner) if isinstance(v, dict) else v
                    for v in value]
    if origin is dict and len(args) == 2 and isinstance(value, dict):
        inner = _strip(args[1])
        if typing.is_typeddict(inner):
            return {k: CheckData(f"{where}[{k!r}]", v, inner) if isinstance(v, dict) else v
                    for k, v in value.items()}
    return value


class CheckData(Mapping[str, Any]):
    """A read-only view of one check's data that refuses keys its declaration lacks."""

    __slots__ = ("_where", "_data", "_td")

    def __init__(self, where: str, data: Mapping[str, Any] | None, td: type | None) -> None:
        self._where = where
        self._data = data if isinstance(data, Mapping) else {}
        self._td = td

    def _declared(self, key: str) -> Any:
        if self._td is None:
            raise UndeclaredKeyError(f"{self._where}: no data is declared for this check "
                                     f"(reading {key!r}); add it to rosnet_tui/core/checks/data.py")
        hints = _hints(self._td)
        if key not in hints:
            raise UndeclaredKeyError(f"{self._where}: {key!r} is not a declared key "
                                     f"({self._td.__name__}); declared: {', '.join(sorted(hints))}")
        return hints[key]

    def __getitem__(self, key: str) -> Any:
        tp = self._declared(key)
        return _wrap(self._data[key], tp, f"{self._where}.{key}")

    def get(self, key: str, default: Any = None) -> Any:
        tp = self._declared(key)
        if key not in self._data:
            return default
        return _wrap(self._data[key], tp, f"{self._where}.{key}")

    def __contains__(self, key: object) -> bool:
        if isinstance(key, str):
            self._declared(key)
        return key in self._data

    def __iter__(self) -> Iterator[str]:
        return iter(self._data)

    def __len__(self) -> int:
        return len(self._data)

    def __bool__(self) -> bool:
        return bool(self._data)

    def __repr__(self) -> str:
        return f"CheckData({self._where!r}, {dict(self._data)!r})"

    def raw(self) -> dict[str, Any]:
        """The plain dict underneath (for JSON output)."""
        return dict(self._data)


def view(check_id: str, data: Mapping[str, Any] | None) -> CheckData:
    """*data* of *check_id* as a declared, read-only view."""
    return CheckData(check_id, data, DATA.get(check_id))


def undeclared(check_id: str, data: Mapping[str, Any] | None) -> list[str]:
    """The keys (dotted paths for nested ones) in *data* that *check_id* does not declare."""
    td = DATA.get(check_id)
    if not data:
        return []
    if td is None:
        return [f"{check_id}: (no declaration)"]
    out: list[str] = []
    _collect(data, td, check_id, out)
    return out


def _collect(data: Mapping[str, Any], td: type, where: str, out: list[str]) -> None:
    hints = _hints(td)
    for key, value in data.items():
        if key not in hints:
            out.append(f"{where}.{key}")
            continue
        tp = _strip(hints[key])
        if typing.is_typeddict(tp) and isinstance(value, Mapping):
            _collect(value, tp, f"{where}.{key}", out)
            continue
        origin, args = typing.get_origin(tp), typing.get_args(tp)
        if origin in (list, tuple) and args and typing.is_typeddict(_strip(args[0])):
            for v in value if isinstance(value, list) else []:
                if isinstance(v, Mapping):
                    _collect(v, _strip(args[0]), f"{where}.{key}[]", out)
        elif origin is dict and len(args) == 2 and typing.is_typeddict(_strip(args[1])):
            for k, v in (value.items() if isinstance(value, Mapping) else []):
                if isinstance(v, Mapping):
                    _collect(v, _strip(args[1]), f"{where}.{key}[{k!r}]", out)
