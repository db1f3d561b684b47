"""Step 4, ROS 1, ROS 2 over rmw_zenoh and rosbridge: what their checks report in ``data``.

One TypedDict per check id; the comment on each key is its documentation (see
:mod:`rosnet_tui.core.checks.data`)."""

from __future__ import annotations

from typing import Literal, TypedDict

from rosnet_tui.core.checks.data.kinds import TcpKind


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


class MemberRouter(TypedDict, total=False):
    zid: str                  # its Zenoh id
    name: str | None          # the component: its config's metadata name, else the peer whose
    #                           public IP it came from (None: neither tells)
    version: str | None       # its Zenoh version (from its admin space; None: not told)
    address: str | None       # the address and port it came from, as the master's router sees
    #                           it (the member's modem, its public side)


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
    member_routers: list[MemberRouter]  # master: the members' routers linked to it right now
    version_skew: list[str]   # master: those running another Zenoh release (name, else id and
    #                           address), which can drop data silently
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


class LinkPeer(TypedDict, total=False):
    """One peer's link, in ros.link (ROS 1, over TCPROS) and ros2.link (through the routers)."""

    rtt_ms: float | None      # round trip of a small message, median of a few pings (None: none came back)
    rtt_spread_ms: float | None  # the slowest ping's round trip minus the fastest one's
    out_bps: int | None       # bits per second delivered from this component to the peer (None: not measured)
    in_bps: int | None        # ... from the peer to this component
    largest_out: int          # bytes of the largest message delivered whole to the peer (0: none)
    largest_in: int           # ... from the peer
    tried_out: int            # bytes of the largest message tried to the peer (0: none: no time)
    tried_in: int             # ... from the peer


class LinkData(TypedDict, total=False):
    peers: dict[str, LinkPeer]  # every peer's link, by peer name
    need_bps: float           # what the [[link.topic]] tables need, bits per second (0: none given)


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


DATA: dict[str, type] = {
    "ros.env": RosEnvData,
    "ros.master": RosMasterData,
    "ros.node_uris": RosNodeUrisData,
    "ros.pubsub_out": RosPubsubData,
    "ros.pubsub_in": RosPubsubData,
    "ros.link": LinkData,
    "ros2.env": Ros2EnvData,
    "ros2.router": Ros2RouterData,
    "ros2.graph": Ros2GraphData,
    "ros2.pubsub_out": Ros2PubsubData,
    "ros2.pubsub_in": Ros2PubsubData,
    "ros2.link": LinkData,
    "ros.rosbridge": RosRosbridgeData,
}
