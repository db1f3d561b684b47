"""The settings model: this component, its peers, ROS, probes, checks, sync; and the validators
every layer (the loader, the set-up screen, the sync records) uses for names, addresses and ports.
"""

from __future__ import annotations

import ipaddress
import math
import os
import re
import sys
import unicodedata
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from typing import Any

from rosnet_tui.core.addresses import KIND_WORDS, address_kind, is_ipv4

if sys.version_info >= (3, 11):
    pass
else:  # pragma: no cover
    pass

ROLES = ("master", "member")
CONNECTIONS = ("corporate", "home", "telecom")
PROFILES = ("remote", "office", "portable")
PORT_MIN, PORT_MAX = 1024, 65000
ROS_VERSIONS = (1, 2)            # 1: ROS 1 (roscore); 2: ROS 2 over rmw_zenoh
ZENOH_PORT_DEFAULT = 7447        # rmw_zenoh's router port
ROSBRIDGE_PORT_DEFAULT = 9090    # rosbridge_server's WebSocket port
DOMAIN_ID_MAX = 232              # ROS_DOMAIN_ID: 0..232
DEFAULT_PUBLIC_IP_URLS = ("https://ifconfig.co/ip",)
DEFAULT_PORT_CHECK_URL = "https://ifconfig.co"

MAX_SETTINGS_BYTES = 1 << 20      # a settings file is a few KB: anything over 1 MiB is refused
MAX_NESTING = 32                  # arrays/inline tables inside each other (the schema needs 1)
SHOWN_VALUE_CHARS = 60            # a value quoted in a message is cut to this many characters

NAME_RE = re.compile(r"^(?!-)[A-Za-z0-9-]{1,63}(?<!-)(\.(?!-)[A-Za-z0-9-]{1,63}(?<!-))*$")
SSH_USER_RE = re.compile(r"^[a-z_][a-z0-9_.-]{0,31}$", re.IGNORECASE)


def shown(value: object, limit: int = SHOWN_VALUE_CHARS) -> str:
    """*value* as it may appear in a message: one line (control and separator characters
    escaped) and at most *limit* characters, with the full length said when cut."""
    text = str(value) if not isinstance(value, int) or abs(value) < 10**30 else "a huge number"
    out = []
    for c in text:
        if unicodedata.category(c) in ("Cc", "Cf", "Zl", "Zp", "Cs"):
            out.append(c.encode("unicode_escape").decode("ascii"))
        else:
            out.append(c)
    one = "".join(out)
    if len(one) > limit:
        return one[:limit] + f"... ({len(text)} characters)"
    return one


class SettingsError(Exception):
    """A settings file that cannot be used: says where (line, key) and why, in one short line."""

    def __init__(self, message: str, *, path: Path | None = None, line: int | None = None,
                 key: str | None = None) -> None:
        self.message = shown(message, 300)
        self.path = path
        self.line = line
        self.key = shown(key, 80) if key is not None else None
        super().__init__(str(self))

    def __str__(self) -> str:
        where = []
        if self.path is not None:
            where.append(str(self.path))
        if self.line is not None:
            where.append(f"line {self.line}")
        if self.key is not None:
            where.append(f"key '{self.key}'")
        return (": ".join([", ".join(where), self.message]) if where else self.message)


# --------------------------------------------------------------------------- validators
# Names /etc/hosts already gives to this machine itself: a component called so would be looked up
# as this machine (localhost, the ip6-* set of Debian-like systems).
RESERVED_NAMES = ("localhost", "localhost.localdomain", "broadcasthost")
RESERVED_PREFIXES = ("ip6-",)
FIELD_SHOWN_CHARS = 24            # a value echoed by a field's validator (one line at 80 columns)


def echoed(value: object) -> str:
    """*value* as a validator's message quotes it: one line, cut to FIELD_SHOWN_CHARS (a paste
    can be kilobytes; the reason must stay on the set-up screen's line)."""
    one = shown(value, 1 << 30)
    return one if len(one) <= FIELD_SHOWN_CHARS else one[:FIELD_SHOWN_CHARS - 3] + "..."


def validate_name(value: str) -> str | None:
    """Return why *value* is not a usable network name, or None when it is."""
    if not value:
        return "a name is required"
    if any(c.isspace() for c in value):
        return "a name cannot contain spaces"
    if len(value) > 253 or not NAME_RE.fullmatch(value):
        return "use letters, digits and '-' only (like turtlebot or sami-laptop)"
    if value.replace(".", "").isdigit():
        return "a name cannot be only digits"
    low = value.lower()
    if low in RESERVED_NAMES or low.startswith(RESERVED_PREFIXES):
        return (f"'{echoed(value)}' is reserved for this machine itself in "
                "/etc/hosts: pick another")
    return None


SYNC_KEY_RE = re.compile(r"^ed25519:[A-Za-z0-9+/]{42}[AEIMQUYcgkosw048]=$")


def validate_sync_key(value: str) -> str | None:
    """Why *value* is not a sync record key (``ed25519:`` and 32 bytes in base64), or None
    (also when empty: not pinned yet)."""
    if not value or SYNC_KEY_RE.fullmatch(value):
        return None
    return ("not a sync key: copy the line `rosnet-tui sync key` prints on that component "
            "(ed25519:...)")


def validate_ip(value: str, *, required: bool = True) -> str | None:
    """Return why *value* is not an IPv4 address, or None when it is (or is empty and optional)."""
    if not value:
        return "an IP address is required" if required else None
    kind = address_kind(value)
    if kind == "invalid":
        return (f"'{echoed(value)}' is not an IP address (expected four "
                "numbers like 192.168.1.10)")
    if not is_ipv4(value):
        return "use an IPv4 address: the procedure's port forwarding is for IPv4"
    if kind in ("unspecified", "multicast", "broadcast"):
        return f"{value} cannot be a component's address ({KIND_WORDS[kind]})"
    return None


def validate_port(value: int | str, *, lo: int = PORT_MIN, hi: int = PORT_MAX) -> str | None:
    """Return why *value* is not a port in lo..hi, or None when it is."""
    if isinstance(value, bool):
        return "a port is a number, not true/false"
    try:
        port = value if isinstance(value, int) else int(str(value).strip())
    except ValueError:
        return f"'{echoed(value)}' is not a port number"
    if not lo <= port <= hi:
        return f"the port must be between {lo} and {hi}"
    return None


def validate_network(value: object) -> str | None:
    """Return why *value* is not an entry of [firewall] allow (an IPv4 or IPv6 address, or a
    network in CIDR form such as 203.0.113.0/24 or 2001:db8::/48), or None when it is."""
    if not isinstance(value, str) or not value.strip():
        return ("each entry is an address or a network in quotes, like \"203.0.113.7\" or "
                "\"203.0.113.0/24\"")
    text = value.strip()
    if "%" in text:
        return f"'{echoed(value)}': write the address without its zone (%interface)"
    try:
        net = ipaddress.ip_network(text)
    except ValueError:
        try:
            loose = ipaddress.ip_network(text, strict=False)
        except ValueError:
            return (f"'{echoed(value)}' is not an address or a network (like 203.0.113.7, "
                    "203.0.113.0/24 or 2001:db8::/48)")
        return (f"'{echoed(value)}' has bits set after the prefix: write the network {loose}, "
                "or the one address without a prefix")
    if net.prefixlen == 0:
        return f"'{echoed(value)}' is the whole internet: list the addresses that may get in"
    first = net.network_address
    if first.is_multicast or first.is_loopback or first.is_unspecified:
        return f"'{echoed(value)}' cannot be where a login comes from"
    return None


def validate_ssh_user(value: str) -> str | None:
    if value and not SSH_USER_RE.fullmatch(value):
        return f"'{echoed(value)}' is not a valid user name"
    return None


URL_RE = re.compile(r"https?://[^\s/]+(/\S*)?")


def validate_url(value: str) -> str | None:
    """Why *value* is not an http:// or https:// URL (a host, then any path; no spaces or control
    characters anywhere), or None."""
    if not isinstance(value, str) or not URL_RE.fullmatch(value) or not value.isprintable():
        return f"'{echoed(value)}' is not an http:// or https:// URL"
    return None


# --------------------------------------------------------------------------- model
@dataclass
class ThisComponent:
    name: str = ""
    role: str = "master"
    connection: str = "home"
    profile: str = "remote"
    local_ip: str = ""
    public_ip: str = ""
    interface: str = ""
    office_ip: str = ""      # this component's address on the office LAN (profile "office")
    portable_ip: str = ""    # ... and on the portable hotspot's LAN (profile "portable")


@dataclass
class Peer:
    name: str
    local_ip: str = ""
    public_ip: str = ""
    ssh_user: str = ""
    ssh_port: int = 22
    office_ip: str = ""      # the peer's address on the office LAN (default: local_ip)
    portable_ip: str = ""    # the peer's address on the portable LAN (default: local_ip)
    sync_key: str = ""       # its sync records' public key, "ed25519:BASE64" (`sync key` there)


def default_ros_version(env: dict[str, str] | None = None) -> int:
    """The ROS version a new settings file starts with: ROS_VERSION of the environment (what a
    sourced ROS setup sets), else 1."""
    value = (os.environ if env is None else env).get("ROS_VERSION", "").strip()
    return 2 if value == "2" else 1


def validate_ros_version(value: int | str) -> str | None:
    """Return why *value* is not a ROS version this product knows (1 or 2), or None."""
    if str(value).strip() in ("1", "2"):
        return None
    return "must be 1 (ROS 1, roscore) or 2 (ROS 2 over rmw_zenoh)"


def validate_domain_id(value: int | str) -> str | None:
    """Return why *value* is not a ROS_DOMAIN_ID (0-232), or None."""
    try:
        n = int(str(value).strip())
    except ValueError:
        return f"'{echoed(value)}' is not a whole number"
    return None if 0 <= n <= DOMAIN_ID_MAX else f"must be between 0 and {DOMAIN_ID_MAX}"


SECURITY_CHOICES = ("mtls", "firewall", "none")


def default_security(version: int) -> str:
    """Who may reach the forwarded ports unless the settings say otherwise: ROS 2, only the
    fleet's certificates (mutual TLS); ROS 1, only the peers' addresses (firewall)."""
    return "mtls" if version == 2 else "firewall"


def validate_security(value: str, version: int) -> str | None:
    """Return why *value* is not a [ros] security choice for ROS *version*, or None."""
    if value not in SECURITY_CHOICES:
        return "must be \"mtls\" (ROS 2), \"firewall\" (ROS 1) or \"none\""
    if value == "mtls" and version != 2:
        return "mutual TLS is for ROS 2 (rmw_zenoh); ROS 1 uses \"firewall\" or \"none\""
    return None


class _DefaultSecurity(str):
    """The version's default, as read from settings that chose none (``dataclasses.replace``
    passes it back; it stays "not chosen", so a changed version changes the default too)."""


class _SecurityChoice:
    """``RosSettings.security``: the value set, or (when none was) the default of the ROS version,
    so readers always see the effective choice and files that do not say follow their version."""

    STORED = "_security_set"       # the value set ("": none); __init__ always sets it

    def __get__(self, obj: Any, owner: type | None = None) -> str:
        if obj is None:
            return ""        # the dataclass default: not chosen
        return getattr(obj, self.STORED) or _DefaultSecurity(default_security(obj.version))

    def __set__(self, obj: Any, value: str) -> None:
        setattr(obj, self.STORED, "" if isinstance(value, _DefaultSecurity) else str(value))


@dataclass
class RosSettings:
    master: str = ""
    port: int = 11311                    # ROS 1: the master's port
    version: int = 1                     # 1 or 2 (a file without it: the environment's ROS_VERSION)
    zenoh_port: int = ZENOH_PORT_DEFAULT  # ROS 2: the master's Zenoh router port (TCP)
    domain_id: int = 0                   # ROS 2: ROS_DOMAIN_ID
    # "mtls" | "firewall" | "none"; unset: default_security(version)
    security: str = _SecurityChoice()  # type: ignore[assignment]

    def security_chosen(self) -> bool:
        """Whether security was set explicitly (not just the version's default)."""
        return not isinstance(self.security, _DefaultSecurity)


@dataclass
class ProbeSettings:
    port: int = 12345
    public_ip_urls: list[str] = field(default_factory=lambda: list(DEFAULT_PUBLIC_IP_URLS))
    port_check_url: str = DEFAULT_PORT_CHECK_URL


@dataclass
class CheckSettings:
    timeout_s: float = 3.0
    # Seconds a warm process stays after `rosnet-tui check` to run the next one without loading
    # anew (rosnet_tui.cli.warm); 0: none.
    keep_warm_s: float = 900.0


@dataclass
class RosbridgeSettings:
    enabled: bool = False            # check the browser's path (rosbridge over WebSocket)
    port: int = ROSBRIDGE_PORT_DEFAULT  # the bridge's TCP port on its host
    host: str = ""                   # the component running the bridge ("": the master)


@dataclass
class FirewallSettings:
    # ROS 1's peers-only firewall: more addresses or networks (IPv4/IPv6, CIDR) that may reach
    # SSH (port 22), such as an administrator's office; the peers and this machine's LAN get in
    # anyway (rosnet_tui.core.exposure.firewall).
    allow: list[str] = field(default_factory=list)


SYNC_STORES = ("folder", "dns")


@dataclass
class SyncSettings:
    store: str = "folder"            # "folder" | "dns"
    folder: str = ""                 # folder store: the shared folder
    interval_s: float = 60           # public-IP poll interval
    dns_server: str = ""             # dns store: the server taking RFC 2136 updates
    zone: str = ""                   # dns store: the zone holding NAME.ZONE A records
    tsig_key_file: str = ""          # dns store: BIND-style TSIG key file


@dataclass
class RelaySettings:
    # ROS 2 with both sites behind carrier NAT: a public server every component's router dials
    # out to (docs/SETTINGS.md "A relay"); host "" means no relay.
    host: str = ""                   # the relay's name (DNS or hosts file), also its certificate's
    ssh_user: str = ""               # the account on the relay ("": the user running rosnet-tui)
    ssh_port: int = 22               # the relay's sshd
    zenoh_port: int = ZENOH_PORT_DEFAULT  # the relay router's TCP port (mutual TLS)
    # component name -> the relay's loopback port at which that component's sshd is reached
    tunnels: dict[str, int] = field(default_factory=dict)

    @property
    def enabled(self) -> bool:
        """A relay is in use (its checks run): [relay] host is set."""
        return bool(self.host)


@dataclass
class LinkTopic:
    """A topic the link must carry ([[link.topic]]): its messages' size and rate; ``max_hz``
    (ROS 2): the rate it is cut down to on the WAN link, which the need then counts."""

    name: str = ""                   # the topic's name (/camera/image/compressed)
    bytes: int = 0                   # bytes of one message
    hz: float = 0.0                  # messages per second
    max_hz: float | None = None      # optional: the rate on the WAN link (ROS 2 downsampling)

    @property
    def bps(self) -> float:
        """Bits per second this topic needs on the link (at max_hz when it is lower)."""
        rate = min(self.hz, self.max_hz) if self.max_hz is not None else self.hz
        return float(self.bytes) * float(rate) * 8.0

    @property
    def full_bps(self) -> float:
        """Bits per second at its full rate (ROS 1: nothing on the link cuts it down)."""
        return float(self.bytes) * float(self.hz) * 8.0


@dataclass
class LinkSettings:
    topics: list[LinkTopic] = field(default_factory=list)   # [[link.topic]]: what the link carries

    def need_bps(self, downsampled: bool = True) -> float:
        """Bits per second every [[link.topic]] needs together (with *downsampled* False, each
        at its full rate: max_hz is ROS 2's)."""
        return sum(t.bps if downsampled else t.full_bps for t in self.topics)


IP_FIELDS = ("local_ip", "public_ip", "office_ip", "portable_ip")    # of this component and a peer


class Gap(str, Enum):
    """A problem that is a value not given yet, rather than a wrong one."""

    BLANK = "blank"            # a name the wizard asks for is empty (this one's, a peer's, the master's)
    NO_ADDRESS = "no_address"  # a peer with neither a local nor a public IP


@dataclass
class Settings:
    this: ThisComponent = field(default_factory=ThisComponent)
    peers: list[Peer] = field(default_factory=list)
    ros: RosSettings = field(default_factory=RosSettings)
    probe: ProbeSettings = field(default_factory=ProbeSettings)
    checks: CheckSettings = field(default_factory=CheckSettings)
    sync: SyncSettings = field(default_factory=SyncSettings)
    rosbridge: RosbridgeSettings = field(default_factory=RosbridgeSettings)
    firewall: FirewallSettings = field(default_factory=FirewallSettings)
    relay: RelaySettings = field(default_factory=RelaySettings)
    link: LinkSettings = field(default_factory=LinkSettings)
    # Whether the file had a [sync] table (so saving does not add one the user never asked for).
    has_sync: bool = field(default=False, compare=False, repr=False)
    # When the settings file holding these values was saved (its modification time, seconds since
    # the epoch; None: not loaded from or saved to a file). linux.resolve reports it as the age
    # of the peers' addresses (entered or learned then).
    saved_at: float | None = field(default=None, compare=False, repr=False)

    def peer(self, name: str) -> Peer | None:
        return next((p for p in self.peers if p.name == name), None)

    @property
    def is_master(self) -> bool:
        return self.this.role == "master"

    @property
    def ros2(self) -> bool:
        """True when this network runs ROS 2 over rmw_zenoh ([ros] version = 2)."""
        return self.ros.version == 2

    @property
    def relayed(self) -> bool:
        """True when every component's router dials the relay ([relay] host set; ROS 2 only)."""
        return bool(self.relay.host)

    @property
    def tunnelled(self) -> bool:
        """True when the peers reach this component's sshd through its tunnel on the relay too
        (ROS 2 with a relay, this component under [relay.tunnels]): no peer then uses its public
        address for anything."""
        return self.ros2 and self.relayed and self.this.name in self.relay.tunnels

    @property
    def master_name(self) -> str:
        return self.ros.master or (self.this.name if self.is_master else "")

    @property
    def rosbridge_host(self) -> str:
        """The component running rosbridge: [rosbridge] host, else the master."""
        return self.rosbridge.host or self.master_name

    @property
    def hosts_rosbridge(self) -> bool:
        """True when rosbridge is enabled and runs on this component."""
        return self.rosbridge.enabled and bool(self.this.name) and \
            self.rosbridge_host.lower() == self.this.name.lower()

    def problems(self) -> list[tuple[str, str]]:
        """Everything that keeps these settings from being complete: (key, reason) pairs."""
        return [(key, why) for key, why, _gap in self._checked()]

    def errors(self, *, allow: tuple[Gap, ...] = ()) -> list[tuple[str, str]]:
        """The problems but the gaps in *allow*: what is wrong, not merely not filled in yet
        (a loader accepts a file the wizard will complete)."""
        return [(key, why) for key, why, gap in self._checked() if gap not in allow]

    def _checked(self) -> list[tuple[str, str, Gap | None]]:
        out: list[tuple[str, str, Gap | None]] = []

        def add(key: str, why: str | None, gap: Gap | None = None) -> None:
            if why:
                out.append((key, why, gap))

        t = self.this
        add("this.name", validate_name(t.name), None if t.name else Gap.BLANK)
        add("this.role", None if t.role in ROLES else f"must be one of {', '.join(ROLES)}")
        add("this.connection", None if t.connection in CONNECTIONS
            else f"must be one of {', '.join(CONNECTIONS)}")
        add("this.profile", None if t.profile in PROFILES
            else f"must be one of {', '.join(PROFILES)}")
        for f in IP_FIELDS:
            add(f"this.{f}", validate_ip(getattr(t, f), required=False))
        names = {t.name}
        seen = {t.name.lower()}           # host names do not differ by case
        for i, p in enumerate(self.peers):
            k = f"peer[{i + 1}]"
            add(f"{k}.name", validate_name(p.name), None if p.name else Gap.BLANK)
            if not p.name:                # not a name yet (the gap above says so): no twin
                pass
            elif p.name.lower() == t.name.lower():
                add(f"{k}.name", f"the name '{shown(p.name)}' is this component's own name "
                                 "(used twice; names ignore case)")
            elif p.name.lower() in seen:
                add(f"{k}.name", f"the name '{shown(p.name)}' is used twice (names ignore case)")
            names.add(p.name)
            seen.add(p.name.lower())
            for f in IP_FIELDS:
                add(f"{k}.{f}", validate_ip(getattr(p, f), required=False))
            add(f"{k}.sync_key", validate_sync_key(p.sync_key))
            if not p.local_ip and not p.public_ip:
                add(f"{k}.public_ip", "give the peer a local IP, a public IP, or both",
                    Gap.NO_ADDRESS)
            add(f"{k}.ssh_user", validate_ssh_user(p.ssh_user))
            add(f"{k}.ssh_port", validate_port(p.ssh_port, lo=1, hi=65535))
        if self.ros.master:
            add("ros.master", validate_name(self.ros.master))
            if self.ros.master not in names:
                add("ros.master",
                    f"'{shown(self.ros.master)}' is neither this component nor a peer")
            elif t.role == "master" and self.ros.master != t.name:
                add("ros.master", "this component is the master, so ros.master must be its own name")
            elif t.role == "member" and self.ros.master == t.name:
                add("ros.master", "this component is a member, so ros.master must name a peer")
        elif t.role == "member":
            add("ros.master", "a member needs the name of the master", Gap.BLANK)
        add("ros.port", validate_port(self.ros.port, lo=1, hi=65535))
        add("ros.version", validate_ros_version(self.ros.version))
        add("ros.zenoh_port", validate_port(self.ros.zenoh_port))
        add("ros.domain_id", validate_domain_id(self.ros.domain_id))
        add("ros.security", validate_security(self.ros.security, self.ros.version))
        add("probe.port", validate_port(self.probe.port))
        if self.probe.port == self.ros.port and not validate_port(self.probe.port):
            add("probe.port", f"must differ from ros.port ({self.ros.port}): the test port is "
                              "open to anyone on the internet, the ROS master's port is not")
        for url in self.probe.public_ip_urls:
            add("probe.public_ip_urls", validate_url(url))
        add("probe.port_check_url", validate_url(self.probe.port_check_url))
        if not number_within(self.checks.timeout_s, 0.1, 120):
            add("checks.timeout_s", "must be between 0.1 and 120 seconds")
        if not number_within(self.checks.keep_warm_s, 0, 86400):
            add("checks.keep_warm_s", "must be between 0 (no warm process) and 86400 seconds")
        b = self.rosbridge
        if not isinstance(b.enabled, bool):
            add("rosbridge.enabled", "must be true or false")
        add("rosbridge.port", validate_port(b.port, lo=1, hi=65535))
        if b.host:
            add("rosbridge.host", validate_name(b.host))
            if b.host.lower() not in seen:
                add("rosbridge.host", f"'{shown(b.host)}' is neither this component nor a peer")
        for entry in self.firewall.allow:
            add("firewall.allow", validate_network(entry))
        out.extend(self._relay_checked(seen))
        out.extend(_link_checked(self.link))
        y = self.sync
        add("sync.store", None if y.store in SYNC_STORES
            else f"must be one of {', '.join(SYNC_STORES)}")
        if not number_within(y.interval_s, 1, 86400):
            add("sync.interval_s", "must be between 1 and 86400 seconds")
        if y.dns_server:
            add("sync.dns_server", validate_ip(y.dns_server))
        if y.zone:
            zone = y.zone.rstrip(".")
            add("sync.zone", validate_name(zone) if zone else "a zone name is required",
                None if zone else Gap.BLANK)
        return out

    def _relay_checked(self, components: set[str]) -> list[tuple[str, str, Gap | None]]:
        """What is wrong with [relay]: nothing when the section is left out."""
        r = self.relay
        if r == RelaySettings():
            return []
        out: list[tuple[str, str, Gap | None]] = []

        def add(key: str, why: str | None) -> None:
            if why:
                out.append((key, why, None))

        if self.ros.version != 2:
            add("relay.host", "a relay carries ROS 2 only (ROS 1 nodes connect to each other "
                              "directly, both ways, which one relay port cannot carry): set "
                              "[ros] version = 2, or remove [relay]")
            return out
        if not r.host:
            add("relay.host", "the relay's name is required with the other [relay] keys")
        else:
            add("relay.host", validate_name(r.host))
            if r.host.lower() in components:
                add("relay.host", f"'{shown(r.host)}' is a component's name: the relay is a "
                                  "server of its own, with a name of its own")
        if self.ros.security != "mtls":
            add("ros.security", "a relay on the internet takes only fleet certificates: "
                                "security must be \"mtls\" with [relay]")
        add("relay.ssh_user", validate_ssh_user(r.ssh_user))
        add("relay.ssh_port", validate_port(r.ssh_port, lo=1, hi=65535))
        add("relay.zenoh_port", validate_port(r.zenoh_port))
        if not isinstance(r.tunnels, dict):
            add("relay.tunnels", "must be a table of component name = port")
            return out
        ports: dict[int, str] = {}
        for name, port in r.tunnels.items():
            key = f"relay.tunnels.{name}"
            why = validate_name(name)
            if not why and name.lower() not in components:
                why = f"'{shown(name)}' is neither this component nor a peer"
            add(key, why)
            why = validate_port(port, hi=65535)         # from PORT_MIN: not a privileged port
            if not why and port in ports:
                why = f"port {port} is {shown(ports[port])}'s too: one port per component"
            add(key, why)
            if isinstance(port, int):
                ports.setdefault(port, name)
        return out

    @property
    def complete(self) -> bool:
        return not self.problems()


TOPIC_NAME = re.compile(r"^/?[A-Za-z_~{][A-Za-z0-9_~{}]*(?:/[A-Za-z_{][A-Za-z0-9_{}]*)*$")
MAX_TOPIC_BYTES = 1 << 30           # a message of at most 1 GiB
MAX_TOPIC_HZ = 100_000.0


def _link_checked(link: LinkSettings) -> list[tuple[str, str, Gap | None]]:
    """What is wrong with the [[link.topic]] tables (the keys: link.topic[N].KEY)."""
    out: list[tuple[str, str, Gap | None]] = []
    for i, tp in enumerate(link.topics):
        k = f"link.topic[{i + 1}]"
        if not isinstance(tp.name, str) or not TOPIC_NAME.match(tp.name):
            out.append((f"{k}.name", f"'{shown(tp.name)}' is not a ROS topic name (letters, "
                                     "digits, _ and / as in /camera/image/compressed)", None))
        if isinstance(tp.bytes, bool) or not isinstance(tp.bytes, int) or \
                not 1 <= tp.bytes <= MAX_TOPIC_BYTES:
            out.append((f"{k}.bytes", f"must be a whole number of bytes, 1 to {MAX_TOPIC_BYTES}",
                        None))
        if not number_within(tp.hz, 0, MAX_TOPIC_HZ) or tp.hz == 0:
            out.append((f"{k}.hz", "must be a rate above 0, in messages per second (at most "
                                   f"{MAX_TOPIC_HZ:g})", None))
        if tp.max_hz is not None and (not number_within(tp.max_hz, 0, MAX_TOPIC_HZ)
                                      or tp.max_hz == 0):
            out.append((f"{k}.max_hz", "must be a rate above 0, in messages per second (leave "
                                       "it out for no limit)", None))
    return out


def number_within(value: Any, lo: float, hi: float) -> bool:
    """A real number (not true/false, not NaN or infinite, any size of int) in lo..hi."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return False
    if isinstance(value, float) and not math.isfinite(value):
        return False
    return lo <= value <= hi


def new_settings(env: dict[str, str] | None = None) -> Settings:
    """Settings for a component that has no settings file yet (ROS version from the environment)."""
    return Settings(ros=RosSettings(version=default_ros_version(env)))
