"""Settings: the TOML file that describes this component, its peers and the probes.

The schema is part of the product (README, "The settings file"). Loading never raises anything
but :class:`SettingsError`, which names the line and key at fault; saving is atomic and keeps the
comments and layout of a hand-edited file.
"""

from __future__ import annotations

import ipaddress
import os
import re
import sys
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

ROLES = ("master", "member")
CONNECTIONS = ("corporate", "home", "telecom")
PROFILES = ("remote", "office", "portable")
PORT_MIN, PORT_MAX = 1024, 65000
DEFAULT_PUBLIC_IP_URLS = ("https://ifconfig.co/ip",)
DEFAULT_PORT_CHECK_URL = "https://ifconfig.co"

_NAME_RE = re.compile(r"^(?!-)[A-Za-z0-9-]{1,63}(?<!-)(\.(?!-)[A-Za-z0-9-]{1,63}(?<!-))*$")
_SSH_USER_RE = re.compile(r"^[a-z_][a-z0-9_.-]{0,31}$", re.IGNORECASE)


class SettingsError(Exception):
    """A settings file that cannot be used: says where (line, key) and why."""

    def __init__(self, message: str, *, path: Path | None = None, line: int | None = None,
                 key: str | None = None) -> None:
        self.message = message
        self.path = path
        self.line = line
        self.key = key
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


def shown(value: str, limit: int = 24) -> str:
    """*value* quoted for a message, cut to *limit* characters (a paste can be kilobytes)."""
    value = " ".join(str(value).split())
    return f"'{value}'" if len(value) <= limit else f"'{value[:limit - 3]}...'"


def validate_name(value: str) -> str | None:
    """Return why *value* is not a usable network name, or None when it is."""
    if not value:
        return "a name is required"
    if any(c.isspace() for c in value):
        return "a name cannot contain spaces"
    if len(value) > 253 or not _NAME_RE.match(value):
        return "use letters, digits and '-' only (like turtlebot or sami-laptop)"
    if value.replace(".", "").isdigit():
        return "a name cannot be only digits"
    low = value.lower()
    if low in RESERVED_NAMES or low.startswith(RESERVED_PREFIXES):
        return f"{shown(value)} is reserved for this machine itself in /etc/hosts: pick another"
    return None


def validate_ip(value: str, *, required: bool = True) -> str | None:
    """Return why *value* is not an IPv4 address, or None when it is (or is empty and optional)."""
    if not value:
        return "an IP address is required" if required else None
    try:
        addr = ipaddress.ip_address(value)
    except ValueError:
        return f"{shown(value)} is not an IP address (expected four numbers like 192.168.1.10)"
    if addr.version != 4:
        return "use an IPv4 address: the procedure's port forwarding is for IPv4"
    if addr.is_unspecified or addr.is_multicast or str(addr) == "255.255.255.255":
        return f"{value} cannot be a component's address"
    return None


def validate_port(value: int | str, *, lo: int = PORT_MIN, hi: int = PORT_MAX) -> str | None:
    """Return why *value* is not a port in lo..hi, or None when it is."""
    try:
        port = int(str(value).strip())
    except ValueError:
        return f"{shown(value)} is not a port number"
    if not lo <= port <= hi:
        return f"the port must be between {lo} and {hi}"
    return None


def validate_ssh_user(value: str) -> str | None:
    if value and not _SSH_USER_RE.match(value):
        return f"{shown(value)} is not a valid user name"
    return None


def validate_url(value: str) -> str | None:
    if not re.match(r"^https?://[^\s/]+", value or ""):
        return f"'{value}' is not an http:// or https:// URL"
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


@dataclass
class RosSettings:
    master: str = ""
    port: int = 11311


@dataclass
class ProbeSettings:
    port: int = 12345
    public_ip_urls: list[str] = field(default_factory=lambda: list(DEFAULT_PUBLIC_IP_URLS))
    port_check_url: str = DEFAULT_PORT_CHECK_URL


@dataclass
class CheckSettings:
    timeout_s: float = 3.0


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
class Settings:
    this: ThisComponent = field(default_factory=ThisComponent)
    peers: list[Peer] = field(default_factory=list)
    ros: RosSettings = field(default_factory=RosSettings)
    probe: ProbeSettings = field(default_factory=ProbeSettings)
    checks: CheckSettings = field(default_factory=CheckSettings)
    sync: SyncSettings = field(default_factory=SyncSettings)
    # Whether the file had a [sync] table (so saving does not add one the user never asked for).
    has_sync: bool = field(default=False, compare=False, repr=False)

    def peer(self, name: str) -> Peer | None:
        return next((p for p in self.peers if p.name == name), None)

    @property
    def is_master(self) -> bool:
        return self.this.role == "master"

    @property
    def master_name(self) -> str:
        return self.ros.master or (self.this.name if self.is_master else "")

    def problems(self) -> list[tuple[str, str]]:
        """Everything that keeps these settings from being complete: (key, reason) pairs."""
        out: list[tuple[str, str]] = []

        def add(key: str, why: str | None) -> None:
            if why:
                out.append((key, why))

        t = self.this
        add("this.name", validate_name(t.name))
        add("this.role", None if t.role in ROLES else f"must be one of {', '.join(ROLES)}")
        add("this.connection", None if t.connection in CONNECTIONS
            else f"must be one of {', '.join(CONNECTIONS)}")
        add("this.profile", None if t.profile in PROFILES
            else f"must be one of {', '.join(PROFILES)}")
        add("this.local_ip", validate_ip(t.local_ip, required=False))
        add("this.public_ip", validate_ip(t.public_ip, required=False))
        add("this.office_ip", validate_ip(t.office_ip, required=False))
        add("this.portable_ip", validate_ip(t.portable_ip, required=False))
        names = {t.name}
        folded = {t.name.lower(): "this component"}
        for i, p in enumerate(self.peers):
            k = f"peer[{i + 1}]"
            add(f"{k}.name", validate_name(p.name))
            if p.name.lower() in folded:  # names are looked up without regard to case
                same = folded[p.name.lower()]
                add(f"{k}.name", f"{shown(p.name)} is this component's own name"
                    if same == "this component" else
                    f"the name {shown(p.name)} is used twice (names ignore case)")
            folded.setdefault(p.name.lower(), p.name)
            names.add(p.name)
            add(f"{k}.local_ip", validate_ip(p.local_ip, required=False))
            add(f"{k}.public_ip", validate_ip(p.public_ip, required=False))
            add(f"{k}.office_ip", validate_ip(p.office_ip, required=False))
            add(f"{k}.portable_ip", validate_ip(p.portable_ip, required=False))
            if not p.local_ip and not p.public_ip:
                add(f"{k}.public_ip", "give the peer a local IP, a public IP, or both")
            add(f"{k}.ssh_user", validate_ssh_user(p.ssh_user))
            add(f"{k}.ssh_port", validate_port(p.ssh_port, lo=1, hi=65535))
        if self.ros.master:
            add("ros.master", validate_name(self.ros.master))
            if self.ros.master not in names:
                add("ros.master", f"'{self.ros.master}' is neither this component nor a peer")
            elif t.role == "master" and self.ros.master != t.name:
                add("ros.master", "this component is the master, so ros.master must be its own name")
            elif t.role == "member" and self.ros.master == t.name:
                add("ros.master", "this component is a member, so ros.master must name a peer")
        elif t.role == "member":
            add("ros.master", "a member needs the name of the master")
        add("ros.port", validate_port(self.ros.port, lo=1, hi=65535))
        add("probe.port", validate_port(self.probe.port))
        for url in self.probe.public_ip_urls:
            add("probe.public_ip_urls", validate_url(url))
        add("probe.port_check_url", validate_url(self.probe.port_check_url))
        if not 0.1 <= float(self.checks.timeout_s) <= 120:
            add("checks.timeout_s", "must be between 0.1 and 120 seconds")
        y = self.sync
        add("sync.store", None if y.store in SYNC_STORES
            else f"must be one of {', '.join(SYNC_STORES)}")
        if not 1 <= float(y.interval_s) <= 86400:
            add("sync.interval_s", "must be between 1 and 86400 seconds")
        if y.dns_server:
            add("sync.dns_server", validate_ip(y.dns_server))
        if y.zone:
            zone = y.zone.rstrip(".")
            add("sync.zone", validate_name(zone) if zone else "a zone name is required")
        return out

    @property
    def complete(self) -> bool:
        return not self.problems()


# --------------------------------------------------------------------------- paths
def default_config_path() -> Path:
    base = os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    return Path(base) / "rosnet-tui" / "config.toml"


def default_state_dir() -> Path:
    base = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    return Path(base) / "rosnet-tui"


# --------------------------------------------------------------------------- loading
_SCHEMA: dict[str, dict[str, type | tuple[type, ...]]] = {
    "this": {"name": str, "role": str, "connection": str, "profile": str, "local_ip": str,
             "public_ip": str, "interface": str, "office_ip": str, "portable_ip": str},
    "peer": {"name": str, "local_ip": str, "public_ip": str, "ssh_user": str, "ssh_port": int,
             "office_ip": str, "portable_ip": str},
    "ros": {"master": str, "port": int},
    "probe": {"port": int, "public_ip_urls": list, "port_check_url": str},
    "checks": {"timeout_s": (int, float)},
    "sync": {"store": str, "folder": str, "interval_s": (int, float), "dns_server": str,
             "zone": str, "tsig_key_file": str},
}
_TYPE_WORDS = {str: "a string in quotes", int: "a whole number", list: "a list [ ... ]",
               (int, float): "a number"}


def _locate(text: str, table: str, key: str | None, index: int = 0) -> int | None:
    """Find the 1-based line of *key* in [table] (the *index*-th [[table]]), by a light scan."""
    current, seen = None, -1
    header = re.compile(r"^\s*(\[\[?)\s*([A-Za-z0-9_.-]+)\s*\]\]?")
    for n, line in enumerate(text.splitlines(), 1):
        m = header.match(line)
        if m:
            current = m.group(2)
            if current == table:
                seen += 1
                if key is None and seen == index:
                    return n
            continue
        if current == table and seen == index and key is not None:
            if re.match(rf"^\s*{re.escape(key)}\s*=", line):
                return n
    return None


def _check_table(text: str, path: Path | None, table: str, data: Any, index: int = 0) -> None:
    if not isinstance(data, dict):
        raise SettingsError(f"[{table}] must be a table", path=path,
                            line=_locate(text, table, None, index), key=table)
    schema = _SCHEMA[table]
    for key, value in data.items():
        full = f"{table}.{key}"
        if key not in schema:
            known = ", ".join(schema)
            raise SettingsError(f"unknown key (known keys in [{table}]: {known})", path=path,
                                line=_locate(text, table, key, index), key=full)
        want = schema[key]
        ok = isinstance(value, want) and not (want is int and isinstance(value, bool))
        if not ok:
            raise SettingsError(f"must be {_TYPE_WORDS[want]}", path=path,
                                line=_locate(text, table, key, index), key=full)


def parse_settings(text: str, path: Path | None = None) -> Settings:
    """Parse and validate the text of a settings file. Raises SettingsError only."""
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        line = getattr(exc, "lineno", None)
        msg = getattr(exc, "msg", None) or str(exc)
        if line is None:
            m = re.search(r"line (\d+)", str(exc))
            line = int(m.group(1)) if m else None
        raise SettingsError(f"not valid TOML: {msg}", path=path, line=line) from None
    for top in raw:
        if top not in _SCHEMA:
            raise SettingsError(f"unknown section (known: {', '.join('[' + s + ']' for s in _SCHEMA)})",
                                path=path, line=_locate(text, top, None), key=top)
    s = Settings()
    if "this" in raw:
        _check_table(text, path, "this", raw["this"])
        s.this = replace(s.this, **raw["this"])
    peers = raw.get("peer", [])
    if not isinstance(peers, list):
        raise SettingsError("peers are written as [[peer]] tables", path=path,
                            line=_locate(text, "peer", None), key="peer")
    for i, p in enumerate(peers):
        _check_table(text, path, "peer", p, i)
        if "name" not in p:
            raise SettingsError("each [[peer]] needs a name", path=path,
                                line=_locate(text, "peer", None, i), key="peer.name")
        s.peers.append(Peer(**p))
    if "ros" in raw:
        _check_table(text, path, "ros", raw["ros"])
        s.ros = replace(s.ros, **raw["ros"])
    if "probe" in raw:
        _check_table(text, path, "probe", raw["probe"])
        urls = raw["probe"].get("public_ip_urls", s.probe.public_ip_urls)
        if not all(isinstance(u, str) for u in urls):
            raise SettingsError("must be a list of URL strings", path=path,
                                line=_locate(text, "probe", "public_ip_urls"),
                                key="probe.public_ip_urls")
        s.probe = replace(s.probe, **raw["probe"])
    if "checks" in raw:
        _check_table(text, path, "checks", raw["checks"])
        s.checks = replace(s.checks, **raw["checks"])
    if "sync" in raw:
        _check_table(text, path, "sync", raw["sync"])
        s.sync = replace(s.sync, **raw["sync"])
        s.has_sync = True

    for key, why in s.problems():
        # Incomplete is fine (the wizard fills it in); wrong is not.
        if why.endswith("is required") or why.startswith("a member needs"):
            continue
        table, _, rest = key.partition(".")
        index = 0
        m = re.match(r"peer\[(\d+)\]", table)
        if m:
            table, index = "peer", int(m.group(1)) - 1
        line = _locate(text, table, rest.split(".")[-1], index)
        raise SettingsError(why, path=path, line=line, key=f"{table}.{rest}")
    return s


def load_settings(path: Path) -> Settings | None:
    """Load the settings file at *path*; None when it does not exist yet."""
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        return None
    except UnicodeDecodeError:
        raise SettingsError("the file is not UTF-8 text", path=path) from None
    except OSError as exc:
        raise SettingsError(f"cannot read the file: {exc.strerror}", path=path) from None
    return parse_settings(text, path)


# --------------------------------------------------------------------------- saving
_HEADER = """\
# rosnet-tui settings. Edit by hand or with the wizard (rosnet-tui); the wizard keeps your
# comments. Schema: see "The settings file" in the README.
"""


def _table_values(s: Settings) -> dict[str, dict[str, Any]]:
    t = s.this
    this = {"name": t.name, "role": t.role, "connection": t.connection, "profile": t.profile}
    for k in ("local_ip", "public_ip", "interface", "office_ip", "portable_ip"):
        if getattr(t, k):
            this[k] = getattr(t, k)
    ros: dict[str, Any] = {"master": s.ros.master or s.master_name, "port": s.ros.port}
    probe = {"port": s.probe.port, "public_ip_urls": list(s.probe.public_ip_urls),
             "port_check_url": s.probe.port_check_url}
    y = s.sync
    sync: dict[str, Any] = {"store": y.store, "interval_s": y.interval_s}
    for k in ("folder", "dns_server", "zone", "tsig_key_file"):
        if getattr(y, k):
            sync[k] = getattr(y, k)
    return {"this": this, "ros": ros, "probe": probe, "checks": {"timeout_s": s.checks.timeout_s},
            "sync": sync}


def _peer_values(p: Peer) -> dict[str, Any]:
    out: dict[str, Any] = {"name": p.name}
    for k in ("local_ip", "public_ip", "ssh_user", "office_ip", "portable_ip"):
        if getattr(p, k):
            out[k] = getattr(p, k)
    if p.ssh_port != 22:
        out["ssh_port"] = p.ssh_port
    return out


def render_settings(s: Settings, previous_text: str | None = None) -> str:
    """Render *s* as TOML, keeping the comments and order of *previous_text* when given."""
    import tomlkit  # only when saving: reading needs tomllib alone

    try:
        doc = tomlkit.parse(previous_text) if previous_text else None
    except Exception:
        doc = None
    if doc is None:
        doc = tomlkit.parse(_HEADER)
    values = _table_values(s)
    for name in ("this",):
        _merge_table(doc, name, values[name])
    peers = tomlkit.aot()
    old = doc.get("peer")
    old_by_name = {}
    if isinstance(old, list):
        old_by_name = {t.get("name"): t for t in old if hasattr(t, "get")}
    for p in s.peers:
        tbl = old_by_name.get(p.name)
        new_values = _peer_values(p)
        if tbl is None:
            tbl = tomlkit.table()
        for k in list(tbl.keys()):
            if k not in new_values:
                del tbl[k]
        for k, v in new_values.items():
            tbl[k] = v
        peers.append(tbl)
    if "peer" in doc:
        del doc["peer"]
    for name in ("ros", "probe", "checks"):
        _merge_table(doc, name, values[name])
    if s.has_sync or s.sync != SyncSettings():
        _merge_table(doc, "sync", values["sync"])
    if s.peers:
        # Keep peers before [ros] when writing fresh, as in the documented example.
        body = doc.as_string()
        peer_doc = tomlkit.document()
        peer_doc["peer"] = peers
        peer_text = peer_doc.as_string()
        marker = "\n[ros]"
        if marker in body:
            head, _, tail = body.partition(marker)
            return head.rstrip("\n") + "\n\n" + peer_text.strip("\n") + "\n" + marker + tail
        return body.rstrip("\n") + "\n\n" + peer_text
    return doc.as_string()


def _merge_table(doc: Any, name: str, values: dict[str, Any]) -> None:
    import tomlkit

    tbl = doc.get(name)
    if tbl is None:
        tbl = tomlkit.table()
        doc[name] = tbl
    for k in list(tbl.keys()):
        if k not in values:
            del tbl[k]
    for k, v in values.items():
        if tbl.get(k) != v:
            tbl[k] = v


def atomic_write_text(path: Path, text: str, mode: int | None = None) -> None:
    """Write *text* to *path* atomically: a temp file in the same folder, fsync, rename."""
    path.parent.mkdir(parents=True, exist_ok=True)
    # An unpredictable name, created exclusively and never through a link.
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}-{os.urandom(4).hex()}")
    if mode is None:
        try:
            mode = path.stat().st_mode & 0o7777
        except FileNotFoundError:
            mode = 0o600
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, mode)
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    try:
        dfd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)
    except OSError:
        pass


def save_settings(s: Settings, path: Path) -> None:
    """Save *s* to *path* atomically, keeping a hand-edited file's comments.

    Refuses (SettingsError) to overwrite an existing file that does not parse: the user's text is
    never replaced without their say-so.
    """
    try:
        previous = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        previous = None
    if previous is not None:
        parse_settings(previous, path)  # raises on a malformed file: never clobber it
    atomic_write_text(path, render_settings(s, previous))
