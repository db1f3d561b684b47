"""ROS 2 over rmw_zenoh: what each role needs, as data the steps text, the checks and the writers
share.

One Zenoh router per component (``ros2 run rmw_zenoh_cpp rmw_zenohd``). The master's router
listens on an IPv4 address (``tcp/0.0.0.0:<zenoh_port>``: ``[::]``, the upstream default, fails
on hosts without IPv6) and its modem forwards TCP ``zenoh_port`` to it; every member's router
connects out to ``tcp/<master name>:<zenoh_port>`` (the hosts file maps the name to the master's
public IP, and address sync keeps that line right), so members need no forwarding. Nodes stay on
their local router (``tcp/localhost:7447``, rmw_zenoh's default); a lone node without a router
connects to the master in client mode.

Under a relay (``[relay] host``, both sites behind carrier NAT) every router, the master's
included, connects out to ``tls/<relay>:<relay zenoh_port>`` with its fleet certificate and
listens on loopback only; the relay's own router is :mod:`.relay`'s.
"""

from __future__ import annotations

import json
import os
import re
import shlex
from pathlib import Path
from typing import Any

from rosnet_tui.core.config.paths import default_config_dir
from rosnet_tui.core.config.settings_model import Settings
from rosnet_tui.core.jsonsafe import JsonInputError, loads_bounded
from rosnet_tui.core.ros.fleet_tls import TlsPaths, tls_paths

RMW_ZENOH = "rmw_zenoh_cpp"
NODE_ROUTER_PORT = 7447          # where rmw_zenoh's nodes look for their local router
# A dead link (issue 31). LEASE_MS: a link whose far end fell silent is dropped after this (and
# re-dialled), keep-alives every LEASE_MS / KEEP_ALIVE; Zenoh's own default, where rmw_zenohd's
# config has 60 s / 2 (for 100+ nodes starting at once), which leaves a dead link listed for a
# minute. CONNECT_RETRY: a member's router re-dials the master's 1 s after a loss, backing off
# to every 4 s, so data flows again within seconds of the link's return.
LEASE_MS = 10_000
KEEP_ALIVE = 4
CONNECT_RETRY = {"period_init_ms": 1000, "period_max_ms": 4000, "period_increase_factor": 2}
MANAGED_HEADER = "// Managed by rosnet-tui"
DISTROS_WITHOUT_OVERRIDE = ("humble",)   # rmw_zenoh < 0.1.2 ignores ZENOH_CONFIG_OVERRIDE
HUMBLE_HASH = "TypeHashNotSupported"     # what Humble's rmw_zenoh puts where a type hash goes
UPSTREAM_LISTEN = ("tcp/[::]:7447",)     # rmw_zenohd's own default listen endpoint


# --------------------------------------------------------------------------- endpoints
def mtls(s: Settings) -> bool:
    """Whether the link across the internet is mutual TLS ([ros] security = "mtls")."""
    return s.ros2 and s.ros.security == "mtls"


def master_endpoint(s: Settings) -> str:
    """``tls/<master name>:<zenoh_port>`` (``tcp/`` with security "none"): where every member's
    router (or lone node) connects."""
    return f"{'tls' if mtls(s) else 'tcp'}/{s.master_name or 'MASTER'}:{s.ros.zenoh_port}"


def relay_endpoint(s: Settings) -> str:
    """``tls/<relay host>:<relay zenoh_port>``: where every router dials under a relay."""
    return f"tls/{s.relay.host}:{s.relay.zenoh_port}"


def hub_endpoint(s: Settings) -> str:
    """Where this component's router (or a lone node) dials: the relay under a relay, else
    the master's router."""
    return relay_endpoint(s) if s.relayed else master_endpoint(s)


def hub_words(s: Settings) -> str:
    """The hub of *s* in words: "the relay's router" or "the master's router"."""
    return "the relay's router" if s.relayed else "the master's router"


def local_endpoint() -> str:
    """Where this machine's nodes find their local router (rmw_zenoh's default, IPv4 spelled out)."""
    return f"tcp/127.0.0.1:{NODE_ROUTER_PORT}"


def listen_endpoints(s: Settings) -> list[str]:
    """What this component's router listens on: IPv4 everywhere, the forwarded port on the master
    (plus 7447 on loopback for its own nodes when the forwarded port is another one); under a
    relay, loopback only (every router dials out, none takes connections from the internet)."""
    if s.relayed:
        return [local_endpoint()]
    if s.is_master and mtls(s):
        # TLS for the forward, plain TCP on loopback for this machine's nodes. Both on one port
        # cannot be (a wildcard listener takes loopback too): on rmw_zenoh's port the TLS
        # listener binds the LAN address the modem forwards to.
        same = s.ros.zenoh_port == NODE_ROUTER_PORT
        host = (s.this.local_ip or "0.0.0.0") if same else "0.0.0.0"
        eps = [f"tls/{host}:{s.ros.zenoh_port}"]
        if not (same and host == "0.0.0.0"):
            eps.append(f"tcp/127.0.0.1:{NODE_ROUTER_PORT}")
        return eps
    if s.is_master:
        eps = [f"tcp/0.0.0.0:{s.ros.zenoh_port}"]
        if s.ros.zenoh_port != NODE_ROUTER_PORT:
            eps.append(f"tcp/127.0.0.1:{NODE_ROUTER_PORT}")
        return eps
    return [f"tcp/0.0.0.0:{NODE_ROUTER_PORT}"]


def connect_endpoints(s: Settings) -> list[str]:
    """What this component's router connects to: nothing on the master, the master on a member;
    the relay on every component under a relay."""
    if s.relayed:
        return [relay_endpoint(s)]
    return [] if s.is_master else [master_endpoint(s)]


def client_override(s: Settings, tls: TlsPaths | None = None) -> str:
    """ZENOH_CONFIG_OVERRIDE of a lone node (no router here): client mode, straight to the master
    (with its certificate under mTLS)."""
    out = f'mode="client";connect/endpoints={json.dumps([hub_endpoint(s)])}'
    for key, value in tls_settings(s, tls, listen=False).items():
        out += f";transport/link/tls/{key}={json.dumps(value)}"
    return out


def tls_settings(s: Settings, tls: TlsPaths | None = None, *, listen: bool) -> dict[str, Any]:
    """``transport/link/tls`` of a config under mTLS ({} otherwise): the fleet CA, and this
    component's key and certificate to listen with (*listen*, the master) or connect with."""
    if not mtls(s):
        return {}
    p = tls or tls_paths(default_config_dir())
    out: dict[str, Any] = {"root_ca_certificate": str(p.ca_crt)}
    if listen:
        out.update(listen_private_key=str(p.node_key), listen_certificate=str(p.node_crt),
                   enable_mtls=True)
    else:
        out.update(connect_private_key=str(p.node_key), connect_certificate=str(p.node_crt),
                   enable_mtls=True)   # a connector sends its certificate only with this on
    out["verify_name_on_connect"] = True
    return out


# --------------------------------------------------------------------------- files and paths
def default_router_config_path() -> Path:
    """Where ``ros apply`` writes the router's config (ZENOH_ROUTER_CONFIG_URI points to it)."""
    return default_config_dir() / "zenoh-router.json5"


def default_session_config_path() -> Path:
    """A lone node's session config on Humble, which has no ZENOH_CONFIG_OVERRIDE before 0.1.2."""
    return default_config_dir() / "zenoh-session.json5"


def router_config(s: Settings, tls: TlsPaths | None = None) -> dict[str, Any]:
    """The router's configuration for this component's role (rmw_zenohd reads it whole); under
    mTLS the TLS files under *tls* (default: this user's ~/.config/rosnet-tui/tls)."""
    link: dict[str, Any] = {"tx": {"lease": LEASE_MS, "keep_alive": KEEP_ALIVE}}
    if mtls(s):
        link["tls"] = tls_settings(s, tls, listen=s.is_master and not s.relayed)
    return {**downsampling(s),
        "mode": "router",
        "connect": {"endpoints": connect_endpoints(s), "retry": dict(CONNECT_RETRY)},
        "listen": {"endpoints": listen_endpoints(s)},
        "scouting": {"multicast": {"enabled": False},
                     "gossip": {"enabled": True, "multihop": False,
                                "target": {"router": ["router", "peer"], "peer": ["router"]},
                                "autoconnect": {"router": [], "peer": ["router", "peer"]}}},
        "timestamping": {"enabled": {"router": True, "peer": True, "client": True}},
        "queries_default_timeout": 600000,
        "routing": {"router": {"peers_failover_brokering": False}},
        "transport": {"link": link},
        "adminspace": {"enabled": True, "permissions": {"read": True, "write": False}},
        # Echoed in the admin space: the master's ros2.router names the linked members by it.
        "metadata": {"name": s.this.name, "role": "master" if s.is_master else "member"},
    }


def downsampling(s: Settings) -> dict[str, Any]:
    """The [[link.topic]] tables with max_hz as Zenoh downsampling rules on what leaves this
    router over its TLS link, the router-to-router link across the internet (local nodes use
    plain TCP on loopback, so they keep every message); {} when none has max_hz. Without mutual
    TLS the WAN link cannot be told from the local ones: nothing is written."""
    rules = [{"key_expr": f"{s.ros.domain_id}/{t.name.strip('/')}/**", "freq": float(t.max_hz)}
             for t in s.link.topics if t.max_hz is not None]
    if not rules or not mtls(s):
        return {}
    return {"downsampling": [{"id": "wan_max_hz", "link_protocols": ["tls"], "flows": ["egress"],
                              "messages": ["put"], "rules": rules}]}


def session_config(s: Settings, tls: TlsPaths | None = None) -> dict[str, Any]:
    """A lone node's session configuration: client mode, connected to the master's router (with
    this component's certificate under mTLS)."""
    out: dict[str, Any] = {"mode": "client", "connect": {"endpoints": [hub_endpoint(s)]},
                           "scouting": {"multicast": {"enabled": False}}}
    if mtls(s):
        out["transport"] = {"link": {"tls": tls_settings(s, tls, listen=False)}}
    return out


def _role_words(s: Settings) -> str:
    if s.relayed:
        return (f"{s.this.name}, {'the ROS 2 master' if s.is_master else 'a member'}: connects "
                f"out to the relay's router {relay_endpoint(s)} (nothing forwarded, nothing "
                "listening on the internet)")
    if s.is_master:
        return (f"{s.this.name}, the ROS 2 master: listens on TCP {s.ros.zenoh_port} for every "
                "member (its modem forwards that port here)")
    return (f"{s.this.name}, a member: connects out to the master's router {master_endpoint(s)} "
            "(no forwarding needed here)")


def render_json5(data: dict[str, Any], comment: list[str]) -> str:
    """JSON (which is JSON5) after a ``//`` comment header that marks the file as ours."""
    head = [MANAGED_HEADER + " (`rosnet-tui ros apply`): the whole file is rewritten; change the",
            "// settings ([ros] in config.toml) instead of editing it.", *[f"// {c}" for c in comment]]
    return "\n".join(head) + "\n" + json.dumps(data, indent=2) + "\n"


def render_router_config(s: Settings, tls: TlsPaths | None = None) -> str:
    return render_json5(router_config(s, tls), [
        f"Zenoh router (rmw_zenohd) of {_role_words(s)}.",
        "Start it with: ros2 run rmw_zenoh_cpp rmw_zenohd (ZENOH_ROUTER_CONFIG_URI names this file)."])


def render_session_config(s: Settings, tls: TlsPaths | None = None) -> str:
    return render_json5(session_config(s, tls), [
        f"ROS 2 nodes of {s.this.name} without a router of their own: client mode, straight to "
        f"{hub_words(s)} {hub_endpoint(s)}."])


def is_managed(text: str | None) -> bool:
    """True for a config file rosnet-tui wrote (or no file at all)."""
    return text is None or text.lstrip().startswith(MANAGED_HEADER)


# --------------------------------------------------------------------------- the shell
def env_lines(s: Settings, *, client: bool = False, router_config_path: Path | None = None,
              session_config_path: Path | None = None, distro: str = "") -> list[str]:
    """The ``export`` lines of this component's ROS 2 environment.

    Always RMW_IMPLEMENTATION and ROS_DOMAIN_ID; the router's config file (components with a
    router); for a lone *client* node its override (on Humble, a session config file instead).
    """
    # Every value shell-quoted: a path or an override holding ' or $(..) stays one word
    q = shlex.quote
    lines = [f"export RMW_IMPLEMENTATION={q(RMW_ZENOH)}",
             f"export ROS_DOMAIN_ID={q(str(s.ros.domain_id))}"]
    if client and not s.is_master:
        if distro.lower() in DISTROS_WITHOUT_OVERRIDE:
            path = session_config_path or default_session_config_path()
            lines.append(f"export ZENOH_SESSION_CONFIG_URI={q(str(path))}")
        else:
            lines.append(f"export ZENOH_CONFIG_OVERRIDE={q(client_override(s))}")
    else:
        path = router_config_path or default_router_config_path()
        lines.append(f"export ZENOH_ROUTER_CONFIG_URI={q(str(path))}")
    return lines


# --------------------------------------------------------------------------- reading configuration
_OVERRIDE_KEY = re.compile(r"^[A-Za-z0-9_/\-]+$")


def parse_override(text: str) -> tuple[dict[str, Any], list[str]]:
    """ZENOH_CONFIG_OVERRIDE (``key/path=json5;key2=json5``): (values by key path, problems)."""
    out: dict[str, Any] = {}
    problems: list[str] = []
    for part in _split_outside_quotes(text, ";"):
        part = part.strip()
        if not part:
            continue
        key, sep, value = part.partition("=")
        key = key.strip()
        if not sep or not _OVERRIDE_KEY.match(key):
            problems.append(f"'{part}' is not key/path=value")
            continue
        try:
            out[key] = loads_json5(value)
        except ValueError as exc:
            problems.append(f"{key}: {exc}")
    return out, problems


def _split_outside_quotes(text: str, sep: str) -> list[str]:
    parts, cur, quote = [], [], ""
    for ch in text:
        if quote:
            cur.append(ch)
            if ch == quote:
                quote = ""
        elif ch in "\"'":
            quote = ch
            cur.append(ch)
        elif ch == sep:
            parts.append("".join(cur))
            cur = []
        else:
            cur.append(ch)
    parts.append("".join(cur))
    return parts


_TOKEN = re.compile(r"""
    (?P<ws>\s+) | (?P<line>//[^\n]*) | (?P<block>/\*.*?\*/)
  | (?P<dq>"(?:\\.|[^"\\])*") | (?P<sq>'(?:\\.|[^'\\])*')
  | (?P<punct>[{}\[\]:,]) | (?P<word>[A-Za-z_$][A-Za-z0-9_$]*) | (?P<num>[-+]?[0-9.][0-9a-fA-FxX.eE+\-]*)
""", re.VERBOSE | re.DOTALL)


def loads_json5(text: str) -> Any:
    """Parse the JSON5 that Zenoh configs use (comments, unquoted keys, single quotes, trailing
    commas) into Python values. Raises ValueError with a short reason."""
    out: list[str] = []
    pos = 0
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if not m:
            raise ValueError(f"unexpected {text[pos:pos + 12]!r} at character {pos}")
        pos = m.end()
        kind, tok = m.lastgroup, m.group()
        if kind in ("ws", "line", "block"):
            continue
        if kind == "sq":
            tok = json.dumps(tok[1:-1].replace("\\'", "'"))
        elif kind == "word":
            if tok not in ("true", "false", "null"):
                nxt = _next_significant(text, pos)
                if nxt != ":":
                    raise ValueError(f"unexpected word {tok!r}")
                tok = json.dumps(tok)
        elif kind == "punct" and tok in "]}":
            while out and out[-1] == ",":
                out.pop()
        elif kind == "num":
            tok = tok.lstrip("+")
        out.append(tok)
    try:   # bounded depth: a config nested thousands deep is refused, not a RecursionError
        return loads_bounded("".join(out), unique_keys=False)
    except JsonInputError as exc:
        raise ValueError(str(exc).removeprefix("not valid JSON (").rstrip(")")) from None


def _next_significant(text: str, pos: int) -> str:
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if not m:
            return text[pos]
        if m.lastgroup not in ("ws", "line", "block"):
            return m.group()[0]
        pos = m.end()
    return ""


def config_value(config: Any, path: str) -> Any:
    """``listen/endpoints`` of a parsed config (None when absent)."""
    cur = config
    for part in path.split("/"):
        if not isinstance(cur, dict) or part not in cur:
            return None
        cur = cur[part]
    return cur


def endpoints_of(value: Any, mode: str) -> list[str]:
    """Endpoints from a config value: a list, or a per-mode dict ``{router: [...], peer: [...]}``."""
    if isinstance(value, dict):
        value = value.get(mode, [])
    return [str(v) for v in value] if isinstance(value, list) else []


def ipv6_available() -> bool:
    """Whether this host can listen on IPv6 (``tcp/[::]:7447``, rmw_zenoh's default, needs it)."""
    try:
        if Path("/proc/sys/net/ipv6/conf/all/disable_ipv6").read_text().strip() == "1":
            return False
        return bool(Path("/proc/net/if_inet6").read_text().strip())
    except OSError:
        return False


def listen_problem(endpoint: str, ipv6: bool) -> str | None:
    """Why a router listening on *endpoint* cannot be reached through the forward (None: fine)."""
    host = endpoint.split("/", 1)[-1].rsplit(":", 1)[0].split("#")[0]
    if host in ("127.0.0.1", "localhost", "[::1]") or host.startswith("127."):
        return "loopback"
    if host in ("[::]", "::") and not ipv6:
        return "ipv6_only"
    return None


def override_problems(s: Settings, values: dict[str, Any]) -> list[str]:
    """What is wrong with a parsed ZENOH_CONFIG_OVERRIDE for this component's role."""
    eps = endpoints_of(values.get("connect/endpoints"), str(values.get("mode") or "peer"))
    remote = [e for e in eps if listen_problem(e, True) != "loopback"]
    if values.get("mode") == "peer" and remote:
        return [f"nodes here are peers connected straight to {', '.join(remote)}: a router does "
                "not pass data between two peers, so they see the graph but get no data; use "
                f"client mode (mode=\"client\") or run a router here"]
    if values.get("mode") != "client":
        return []
    if s.is_master and not s.relayed:
        return ["ZENOH_CONFIG_OVERRIDE puts the master's nodes in client mode; the master runs "
                "the router the others connect to"]
    if hub_endpoint(s) not in eps:
        return [f"client mode connects to {', '.join(eps) or 'nothing'}, not {hub_words(s)} "
                f"{hub_endpoint(s)} (by name, so address sync keeps it right)"]
    return []


def router_config_problems(s: Settings, listen: list[str], connect: list[str],
                           ipv6: bool) -> list[str]:
    """What keeps a router with these endpoints from doing this component's job."""
    port = s.ros.zenoh_port
    if s.relayed:
        if relay_endpoint(s) not in connect:
            return [f"this router connects to {', '.join(connect) or 'nothing'}; under a relay it "
                    f"must connect to the relay's router {relay_endpoint(s)}"]
        return []
    if not s.is_master:
        if master_endpoint(s) not in connect:
            return [f"this member's router connects to {', '.join(connect) or 'nothing'}; it must "
                    f"connect to the master's router {master_endpoint(s)}"]
        return []
    on_port = [e for e in listen if e.rsplit(":", 1)[-1] == str(port)]
    kinds = [listen_problem(e, ipv6) for e in on_port]
    if not on_port:
        return [f"the router does not listen on TCP {port}, the port the modem forwards"]
    if None in kinds:
        return []
    if "ipv6_only" in kinds:
        return [f"the router listens on tcp/[::]:{port}, but this host has no IPv6: rmw_zenohd "
                f"fails to start; listen on tcp/0.0.0.0:{port}"]
    return [f"the router listens on loopback only ({', '.join(on_port)}): the forward cannot "
            f"reach it; listen on tcp/0.0.0.0:{port}"]


# --------------------------------------------------------------------------- the writer
def writer_problems(s: Settings) -> list[tuple[str, str]]:
    """Why the ROS 2 configuration cannot be written from *s* (empty: it can)."""
    relevant = re.compile(r"^(this\.(name|role)|ros\.(master|version|zenoh_port|domain_id)|"
                          r"peer\[\d+\]\.name|relay\..+)$")
    out = [(k, why) for k, why in s.problems() if relevant.match(k)]
    if not out and not s.master_name:
        out.append(("ros.master", "the name of the master (the hub every router links to) is "
                                  "not set"))
    return out


def bashrc_block(s: Settings, *, client: bool = False, router_config_path: Path | None = None,
                 session_config_path: Path | None = None, distro: str = "") -> list[str]:
    """The lines of our ~/.bashrc block under ROS 2 (between the markers)."""
    lone = client and not s.is_master
    if s.relayed and not lone:
        who = (f"{s.this.name}'s router connects out to the relay {relay_endpoint(s)}; nothing "
               "is forwarded or listens on the internet here")
    elif s.relayed:
        who = (f"{s.this.name} runs no router: its nodes connect to the relay "
               f"{relay_endpoint(s)} in client mode")
    elif s.is_master:
        who = (f"{s.this.name} is the master: its router is the hub, listening on TCP "
               f"{s.ros.zenoh_port} (forwarded by its modem)")
    elif lone:
        who = (f"{s.this.name} runs no router: its nodes connect to {master_endpoint(s)} in "
               "client mode")
    else:
        who = (f"{s.this.name} is a member: its router connects to {master_endpoint(s)}; no "
               "forwarding needed here")
    lines = ["# Managed by rosnet-tui: edits inside this block are replaced.",
             f"# ROS 2 over rmw_zenoh: {who}"]
    if not lone:
        lines.append("# Start the router with: ros2 run rmw_zenoh_cpp rmw_zenohd")
    return lines + env_lines(s, client=lone, router_config_path=router_config_path,
                             session_config_path=session_config_path, distro=distro)


def preview_whole_file(path: Path, text: str, label: str, state_dir: Path | None = None) -> Any:
    """A preview replacing *path* with *text*, refused when the file exists and is not ours."""
    from rosnet_tui.core.files import managed_file as mf
    from rosnet_tui.core.files import managed_text as mt
    from rosnet_tui.core.files import managed_write as mw

    old = mw.read_bytes(path, state_dir=state_dir)
    if old is not None and not is_managed(mt.decode(old)):
        raise mt.ManagedFileError(f"{path} exists and was not written by rosnet-tui: move it "
                                  "away (or point the setting at another file), then try again")
    return mf.Preview(Path(path), old, mt.encode(text), label, (), 0o644)


def previews(s: Settings, bashrc_path: Path, *, client: bool = False,
             router_config_path: Path | None = None, session_config_path: Path | None = None,
             distro: str | None = None, state_dir: Path | None = None) -> list[Any]:
    """What ``ros apply`` writes under ROS 2, as managed-file previews (one undo restores all):
    the ~/.bashrc block, and the router's config (or, for a lone client node on Humble, the
    session config)."""
    from rosnet_tui.core.files import managed_file as mf
    from rosnet_tui.core.files import managed_write as mw
    from rosnet_tui.core.files.hosts import WriterSettingsError

    problems = writer_problems(s)
    if problems:
        raise WriterSettingsError(problems)
    distro = os.environ.get("ROS_DISTRO", "") if distro is None else distro
    lone = client and not s.is_master
    rc_path = router_config_path or default_router_config_path()
    sc_path = session_config_path or default_session_config_path()
    body = bashrc_block(s, client=lone, router_config_path=rc_path,
                        session_config_path=sc_path, distro=distro)
    old = mw.read_bytes(Path(bashrc_path), state_dir=state_dir)
    out = [mf.preview_block(bashrc_path, body, position="end",
                            label=f"ROS 2 environment in {Path(bashrc_path).name}",
                            new_mode=0o644, current=old, use_current=True)]
    if not lone:
        out.append(preview_whole_file(rc_path, render_router_config(s),
                                      f"Zenoh router config {rc_path.name}", state_dir))
    elif distro.lower() in DISTROS_WITHOUT_OVERRIDE:
        out.append(preview_whole_file(sc_path, render_session_config(s),
                                      f"Zenoh session config {sc_path.name}", state_dir))
    return out


def shell_lines(s: Settings, *, client: bool = False, distro: str | None = None) -> list[str]:
    """The lines for the current shell (``eval "$(rosnet-tui ros export)"``)."""
    from rosnet_tui.core.files.hosts import WriterSettingsError

    problems = writer_problems(s)
    if problems:
        raise WriterSettingsError(problems)
    distro = os.environ.get("ROS_DISTRO", "") if distro is None else distro
    return env_lines(s, client=client and not s.is_master, distro=distro)
