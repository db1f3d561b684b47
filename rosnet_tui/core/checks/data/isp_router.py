"""Steps 1 and 2, ISP and Router/modem: what their checks report in ``data``.

One TypedDict per check id; the comment on each key is its documentation (see
:mod:`rosnet_tui.core.checks.data`)."""

from __future__ import annotations

from typing import Literal, TypedDict


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
    via: str                # who tested: "peer:<name>" over SSH, "echoip" (the port checker), or "here" (the relay's port, from this component)
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
    zenoh_port: int         # the master's Zenoh router port (under a relay: the relay's)
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


DATA: dict[str, type] = {
    "isp.internet": IspInternetData,
    "isp.public_ip": IspPublicIpData,
    "isp.cgnat": IspCgnatData,
    "router.local_ip": RouterLocalIpData,
    "router.port_free": RouterPortFreeData,
    "router.listener": RouterListenerData,
    "router.port_open": RouterPortOpenData,
    "router.upnp": RouterUpnpData,
}
