"""Settings: the TOML file that describes this component, its peers and the probes.

The schema is part of the product (docs/SETTINGS.md). Loading never raises anything
but :class:`SettingsError`, which names the line and key at fault; saving is atomic and keeps the
comments and layout of a hand-edited file.
"""

from __future__ import annotations

import os
import re
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

from rosnet_tui.core.config.settings_model import (
    MAX_NESTING,
    MAX_SETTINGS_BYTES,
    ZENOH_PORT_DEFAULT,
    CheckSettings,
    FirewallSettings,
    Gap,
    LinkTopic,
    Peer,
    RelaySettings,
    RosbridgeSettings,
    Settings,
    SettingsError,
    SyncSettings,
    default_ros_version,
    shown,
)
from rosnet_tui.core.files import tempfiles
from rosnet_tui.core.files.regular_file import FileRefusedError, read_regular

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

# --------------------------------------------------------------------------- loading
_SCHEMA: dict[str, dict[str, type | tuple[type, ...]]] = {
    "this": {"name": str, "role": str, "connection": str, "profile": str, "local_ip": str,
             "public_ip": str, "interface": str, "office_ip": str, "portable_ip": str},
    "peer": {"name": str, "local_ip": str, "public_ip": str, "ssh_user": str, "ssh_port": int,
             "office_ip": str, "portable_ip": str, "sync_key": str},
    "ros": {"master": str, "port": int, "version": int, "zenoh_port": int, "domain_id": int,
            "security": str},
    "probe": {"port": int, "public_ip_urls": list, "port_check_url": str},
    "checks": {"timeout_s": (int, float), "keep_warm_s": (int, float)},
    "sync": {"store": str, "folder": str, "interval_s": (int, float), "dns_server": str,
             "zone": str, "tsig_key_file": str},
    "rosbridge": {"enabled": bool, "port": int, "host": str},
    "firewall": {"allow": list},
    "relay": {"host": str, "ssh_user": str, "ssh_port": int, "zenoh_port": int, "tunnels": dict},
    "link": {"topic": list},
    "link.topic": {"name": str, "bytes": int, "hz": (int, float), "max_hz": (int, float)},
}
_TYPE_WORDS = {str: "a string in quotes", int: "a whole number", list: "a list [ ... ]",
               (int, float): "a number", bool: "true or false",
               dict: "a table ([relay.tunnels], one name = port a line)"}
_SECTIONS = [s for s in _SCHEMA if "." not in s]


def _lines(text: str) -> list[str]:
    """The lines as TOML counts them: only LF ends a line (U+2028, VT, FF ... do not)."""
    return text.split("\n")


def _locate(text: str, table: str, key: str | None, index: int = 0) -> int | None:
    """Find the 1-based line of *key* in [table] (the *index*-th [[table]]), by a light scan."""
    current, seen = None, -1
    header = re.compile(r"^\s*(\[\[?)\s*([A-Za-z0-9_.-]+)\s*\]\]?")
    for n, line in enumerate(_lines(text), 1):
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
        ok = isinstance(value, want) and (want is bool or not isinstance(value, bool))
        if not ok:
            raise SettingsError(f"must be {_TYPE_WORDS[want]}", path=path,
                                line=_locate(text, table, key, index), key=full)


_HEADER_RE = re.compile(r"^\s*(\[\[?)\s*([A-Za-z0-9_.\"' -]+?)\s*\]\]?\s*(?:#.*)?$")
_KEY_RE = re.compile(r"^\s*([A-Za-z0-9_.\"' -]+?)\s*=")


def _key_at(text: str, lineno: int) -> str | None:
    """The dotted key (table.key) whose value is on line *lineno*, by a light scan."""
    table = None
    lines = _lines(text)
    for line in lines[:lineno - 1]:
        m = _HEADER_RE.match(line)
        if m:
            table = m.group(2).strip().strip("\"'")
    m = _KEY_RE.match(lines[lineno - 1]) if 0 < lineno <= len(lines) else None
    if not m:
        return table
    key = m.group(1).strip().strip("\"'")
    return f"{table}.{key}" if table else key


def _nesting(text: str, limit: int = MAX_NESTING) -> int | None:
    """The line where arrays/inline tables nest deeper than *limit* (None: they do not).

    Checked before parsing: the parser recurses once per level, and a few hundred brackets
    would exhaust Python's stack. Strings and comments are skipped."""
    depth, line, i, n = 0, 1, 0, len(text)
    at_line_start = True
    while i < n:
        c = text[i]
        if c == "\n":
            line += 1
            at_line_start = True
            i += 1
            continue
        if c in " \t":
            i += 1
            continue
        if c == "#":
            j = text.find("\n", i)
            i = n if j < 0 else j
            continue
        if text.startswith(('"""', "'''"), i):
            end = text.find(text[i:i + 3], i + 3)
            end = n if end < 0 else end + 3
            line += text.count("\n", i, end)
            i = end
            at_line_start = False
            continue
        if c in "\"'":
            j = i + 1
            while j < n and text[j] != c and text[j] != "\n":
                j += 2 if c == '"' and text[j] == "\\" else 1
            i = j + 1 if j < n and text[j] == c else j
            at_line_start = False
            continue
        if c in "[{" and not (at_line_start and depth == 0 and c == "["):
            depth += 1
            if depth > limit:
                return line
        elif c in "]}" and depth > 0:
            depth -= 1
        elif at_line_start and depth == 0 and c == "[":
            j = text.find("\n", i)       # a table header: skip it whole
            i = n if j < 0 else j
            continue
        at_line_start = False
        i += 1
    return None


_TWICE_RE = re.compile(r"Cannot (?:declare|overwrite|mutate)[^()]*\(([^)]*)\)")


def _toml_problem(text: str, exc: tomllib.TOMLDecodeError, path: Path | None) -> SettingsError:
    """A TOML syntax error in words: the line, and for the usual slips what to write instead."""
    line = getattr(exc, "lineno", None)
    msg = getattr(exc, "msg", None) or str(exc)
    if line is None:
        m = re.search(r"line (\d+)", str(exc))
        line = int(m.group(1)) if m else None
    for n, ln in enumerate(_lines(text), 1):
        m = _HEADER_RE.match(ln)
        if m and m.group(1) == "[" and m.group(2).strip() == "peer":
            return SettingsError("peers are written as [[peer]] (two brackets), one table per "
                                 "peer", path=path, line=n, key="peer")
    m = _TWICE_RE.search(msg)
    if m:
        name = ".".join(x.strip().strip("'\"") for x in m.group(1).split(",") if x.strip())
        if name:
            return SettingsError(f"[{name}] or its key is written twice: each table and key "
                                 "once (peers: one [[peer]] table each)", path=path, line=line,
                                 key=name)
    return SettingsError(f"not valid TOML: {msg}", path=path, line=line)


def parse_settings(text: str, path: Path | None = None) -> Settings:
    """Parse and validate the text of a settings file. Raises SettingsError only."""
    if text.startswith("\ufeff"):
        raise SettingsError("the file starts with a byte-order mark (U+FEFF): save it as UTF-8 "
                            "without one", path=path, line=1)
    deep = _nesting(text)
    if deep is not None:
        raise SettingsError(f"values nested more than {MAX_NESTING} levels deep", path=path,
                            line=deep, key=_key_at(text, deep))
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise _toml_problem(text, exc, path) from None
    except RecursionError:
        raise SettingsError("values nested too deeply", path=path) from None
    except ValueError as exc:  # an integer of more than 4,300 digits
        m = re.search(r"[0-9_]{300,}", text)
        line = text.count("\n", 0, m.start()) + 1 if m else None
        raise SettingsError(f"a value cannot be read ({shown(exc, 80)})", path=path, line=line,
                            key=_key_at(text, line) if line else None) from None
    for top in raw:
        if top not in _SECTIONS:
            raise SettingsError(f"unknown section (known: {', '.join('[' + s + ']' for s in _SECTIONS)})",
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
    if "version" not in raw.get("ros", {}):
        s.ros.version = default_ros_version()  # files from before ROS 2 keep working
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
    if "rosbridge" in raw:
        _check_table(text, path, "rosbridge", raw["rosbridge"])
        s.rosbridge = replace(s.rosbridge, **raw["rosbridge"])
    if "firewall" in raw:
        _check_table(text, path, "firewall", raw["firewall"])
        s.firewall = replace(s.firewall, **raw["firewall"])
    if "relay" in raw:
        _check_table(text, path, "relay", raw["relay"])
        tunnels = raw["relay"].get("tunnels", {})
        for name, port in tunnels.items():
            if not isinstance(port, int) or isinstance(port, bool):
                raise SettingsError("must be a port number (the relay's loopback port for "
                                    "this component's sshd)", path=path,
                                    line=_locate(text, "relay.tunnels", name),
                                    key=f"relay.tunnels.{name}")
        s.relay = replace(s.relay, **raw["relay"])
        s.relay.tunnels = dict(tunnels)
    if "link" in raw:
        s.link.topics = _link_topics(text, path, raw["link"])

    for key, why in s.errors(allow=(Gap.BLANK,)):   # incomplete is fine (the wizard fills it in)
        table, _, rest = key.partition(".")
        index = 0
        m = re.match(r"peer\[(\d+)\]", table)
        if m:
            table, index = "peer", int(m.group(1)) - 1
        if key.startswith("relay.tunnels."):
            table, rest = "relay.tunnels", key[len("relay.tunnels."):]
        m = re.match(r"link\.topic\[(\d+)\]\.(\w+)$", key)
        if m:
            table, index, rest = "link.topic", int(m.group(1)) - 1, m.group(2)
        line = _locate(text, table, rest if table == "relay.tunnels" else rest.split(".")[-1],
                       index)
        raise SettingsError(why, path=path, line=line, key=f"{table}.{rest}")
    return s


def _link_topics(text: str, path: Path | None, link: Any) -> list[LinkTopic]:
    """The [[link.topic]] tables of [link] (each with name, bytes and hz; max_hz optional)."""
    topics = link.get("topic", []) if isinstance(link, dict) else []
    if not isinstance(topics, list) or not all(isinstance(t, dict) for t in topics):
        raise SettingsError("topics are written as [[link.topic]] tables", path=path,
                            line=_locate(text, "link.topic", None), key="link.topic")
    _check_table(text, path, "link", link)
    out = []
    for i, tp in enumerate(topics):
        _check_table(text, path, "link.topic", tp, i)
        for need in ("name", "bytes", "hz"):
            if need not in tp:
                raise SettingsError(f"each [[link.topic]] needs {need} (name, bytes of one "
                                    "message, hz: messages per second)", path=path,
                                    line=_locate(text, "link.topic", None, i),
                                    key=f"link.topic.{need}")
        out.append(LinkTopic(**tp))
    return out


def read_settings_text(path: Path) -> str | None:
    """The text of the settings file at *path*, None when it does not exist. Bounded: anything
    but a regular file (a FIFO, a device such as /dev/zero behind a link, a folder) is refused
    without reading, and so is a file over MAX_SETTINGS_BYTES. Raises SettingsError."""
    try:
        data = read_regular(path, MAX_SETTINGS_BYTES)
    except FileNotFoundError:
        return None
    except FileRefusedError as exc:
        if exc.kind != "big":
            raise SettingsError("not a regular file (a folder, a FIFO or a device?): a settings "
                                "file is a text file", path=path) from None
        try:
            size = os.stat(path).st_size
        except OSError:
            size = 0
        if size > MAX_SETTINGS_BYTES:
            raise SettingsError(f"too big ({size} bytes; a settings file is a few KB, at "
                                f"most {MAX_SETTINGS_BYTES})", path=path) from None
        raise SettingsError(f"too big (over {MAX_SETTINGS_BYTES} bytes)", path=path) from None
    except OSError as exc:
        raise SettingsError(f"cannot read the file: {exc.strerror}", path=path) from None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise SettingsError("the file is not UTF-8 text", path=path) from None


def load_settings(path: Path) -> Settings | None:
    """Load the settings file at *path*; None when it does not exist yet."""
    text = read_settings_text(path)
    if text is None:
        return None
    s = parse_settings(text, path)
    s.saved_at = _mtime(path)
    return s


def _mtime(path: Path) -> float | None:
    try:
        return os.stat(path).st_mtime
    except OSError:
        return None


# --------------------------------------------------------------------------- saving
_HEADER = """\
# rosnet-tui settings. Edit by hand or with the wizard (rosnet-tui); the wizard keeps your
# comments. Schema: see docs/SETTINGS.md.
"""


def _table_values(s: Settings) -> dict[str, dict[str, Any]]:
    t = s.this
    this = {"name": t.name, "role": t.role, "connection": t.connection, "profile": t.profile}
    for k in ("local_ip", "public_ip", "interface", "office_ip", "portable_ip"):
        if getattr(t, k):
            this[k] = getattr(t, k)
    ros: dict[str, Any] = {"version": s.ros.version, "master": s.ros.master or s.master_name,
                           "port": s.ros.port}
    if s.ros2 or s.ros.zenoh_port != ZENOH_PORT_DEFAULT or s.ros.domain_id:
        ros.update(zenoh_port=s.ros.zenoh_port, domain_id=s.ros.domain_id)
    if s.ros2 or s.ros.security_chosen():
        ros["security"] = str(s.ros.security)
    probe = {"port": s.probe.port, "public_ip_urls": list(s.probe.public_ip_urls),
             "port_check_url": s.probe.port_check_url}
    y = s.sync
    sync: dict[str, Any] = {"store": y.store, "interval_s": y.interval_s}
    for k in ("folder", "dns_server", "zone", "tsig_key_file"):
        if getattr(y, k):
            sync[k] = getattr(y, k)
    b = s.rosbridge
    rosbridge: dict[str, Any] = {"enabled": b.enabled, "port": b.port}
    if b.host:
        rosbridge["host"] = b.host
    r = s.relay
    relay: dict[str, Any] = {"host": r.host}
    if r.ssh_user:
        relay["ssh_user"] = r.ssh_user
    relay.update(ssh_port=r.ssh_port, zenoh_port=r.zenoh_port)
    checks: dict[str, Any] = {"timeout_s": s.checks.timeout_s}
    if s.checks.keep_warm_s != CheckSettings.keep_warm_s:
        checks["keep_warm_s"] = s.checks.keep_warm_s
    return {"this": this, "ros": ros, "probe": probe, "checks": checks,
            "sync": sync, "rosbridge": rosbridge, "firewall": {"allow": list(s.firewall.allow)},
            "relay": relay}


def _peer_values(p: Peer) -> dict[str, Any]:
    out: dict[str, Any] = {"name": p.name}
    for k in ("local_ip", "public_ip", "ssh_user", "office_ip", "portable_ip", "sync_key"):
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
    if "keep_warm_s" in (doc.get("checks") or {}):    # the user's line, kept even at its default
        values["checks"]["keep_warm_s"] = s.checks.keep_warm_s
    for name in ("ros", "probe", "checks"):
        _merge_table(doc, name, values[name])
    if s.has_sync or s.sync != SyncSettings():
        _merge_table(doc, "sync", values["sync"])
    if "rosbridge" in doc or s.rosbridge != RosbridgeSettings():
        _merge_table(doc, "rosbridge", values["rosbridge"])
    if "firewall" in doc or s.firewall != FirewallSettings():
        _merge_table(doc, "firewall", values["firewall"])
    if "relay" in doc or s.relay != RelaySettings():
        _merge_relay(doc, values["relay"], s.relay.tunnels)
    _merge_link(doc, s)
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


def with_peer_values(text: str, name: str, **values: str) -> str:
    """*text* with *values* set in the ``[[peer]]`` table named *name* (names compare without
    case); every other byte as it was (comments, layout): a key already there is changed in its
    place, a new one goes right after the table's last key. Raises SettingsError."""
    import tomlkit

    try:
        doc = tomlkit.parse(text)
    except Exception as exc:  # noqa: BLE001 - tomlkit raises several kinds
        raise SettingsError(f"the settings do not parse: {exc}") from None
    tables = [t for t in (doc.get("peer") or []) if hasattr(t, "get")]
    index = next((i for i, t in enumerate(tables)
                  if str(t.get("name", "")).lower() == name.lower()), None)
    if index is None:
        raise SettingsError(f"no [[peer]] named {name} in the settings")
    tbl = tables[index]
    for k in [k for k in values if k in tbl]:
        tbl[k] = values.pop(k)
    text = doc.as_string()
    if not values:
        return text
    header = _locate(text, "peer", None, index)
    lines = text.split("\n")
    if header is None:
        raise SettingsError(f"cannot find the [[peer]] table of {name}")
    last, n = header - 1, header
    key_line = re.compile(r"^(\s*)[A-Za-z0-9_\"'.-]+\s*=")
    while n < len(lines) and not re.match(r"^\s*\[", lines[n]):
        if key_line.match(lines[n]):
            last = n
        n += 1
    indent = key_line.match(lines[last]).group(1) if key_line.match(lines[last]) else ""
    new = [f"{indent}{k} = {tomlkit.item(v).as_string()}" for k, v in values.items()]
    return "\n".join(lines[:last + 1] + new + lines[last + 1:])


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


def _merge_relay(doc: Any, values: dict[str, Any], tunnels: dict[str, int]) -> None:
    """[relay], and under it [relay.tunnels] (a table of its own) when any tunnel is set."""
    import tomlkit

    tbl = doc.get("relay")
    if tbl is None:
        tbl = tomlkit.table()
        doc["relay"] = tbl
    for k in list(tbl.keys()):
        if k not in values and k != "tunnels":
            del tbl[k]
    for k, v in values.items():
        if tbl.get(k) != v:
            tbl[k] = v
    if not tunnels:
        if "tunnels" in tbl:
            del tbl["tunnels"]
        return
    old = tbl.get("tunnels")
    if not isinstance(old, dict):
        if old is not None:
            del tbl["tunnels"]
        old = tomlkit.table()
        tbl["tunnels"] = old
    for k in list(old.keys()):
        if k not in tunnels:
            del old[k]
    for k, v in tunnels.items():
        if old.get(k) != v:
            old[k] = v


def _merge_link(doc: Any, s: Settings) -> None:
    """[[link.topic]]: left as written (comments) when the values are the same, else rewritten."""
    import tomlkit

    want = [{k: v for k, v in (("name", t.name), ("bytes", t.bytes), ("hz", t.hz),
                               ("max_hz", t.max_hz)) if v is not None} for t in s.link.topics]
    old = doc.get("link")
    have = [dict(t) for t in (old.get("topic") or [])] if isinstance(old, dict) else None
    if have == want or (have is None and not want):
        return
    if "link" in doc:
        del doc["link"]
    if want:
        topics = tomlkit.aot()
        for w in want:
            tbl = tomlkit.table()
            tbl.update(w)
            topics.append(tbl)
        link = tomlkit.table(is_super_table=True)
        link["topic"] = topics
        doc["link"] = link


def atomic_write_text(path: Path, text: str, mode: int | None = None,
                      owner: tuple[int, int] | None = None) -> None:
    """Write *text* (UTF-8) to *path* atomically (:func:`~.managed_write.atomic_write`); a new
    file gets *mode* (default: the file's mode now, or 0600), the umask applying; *owner*:
    handed to that user (root writing a user's file: on the new file's descriptor)."""
    from rosnet_tui.core.files.managed_write import atomic_write

    path.parent.mkdir(parents=True, exist_ok=True)
    # What a killed writer of an earlier version left (its temp-file naming): removed too.
    tempfiles.sweep(path.parent, tempfiles.ATOMIC_TMP, path.name)
    if mode is None:
        try:
            mode = path.stat().st_mode & 0o7777
        except FileNotFoundError:
            mode = 0o600
    atomic_write(path, text.encode("utf-8"), create_mode=mode,
                 uid=owner[0] if owner else None, gid=owner[1] if owner else None)


def save_settings(s: Settings, path: Path, owner: tuple[int, int] | None = None) -> None:
    """Save *s* to *path* atomically, keeping a hand-edited file's comments.

    Refuses (SettingsError) to overwrite an existing file that does not parse: the user's text is
    never replaced without their say-so.
    """
    previous = read_settings_text(path)
    if previous is not None:
        parse_settings(previous, path)  # raises on a malformed file: never clobber it
    atomic_write_text(path, render_settings(s, previous), owner=owner)
    s.saved_at = _mtime(path)
