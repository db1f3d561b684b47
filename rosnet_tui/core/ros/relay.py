"""The relay's own Zenoh router (issue 30): a public server every component's router dials out to
when no site can forward (carrier-grade NAT).

It listens with mutual TLS on ``tls/0.0.0.0:<zenoh_port>`` and takes only the fleet's
certificates (the fleet CA is its trust root); its own certificate, signed by the fleet CA on the
master, names the relay as the components dial it. TLS links only: no plain TCP at all. No ROS
is needed there: eclipse-zenoh in router mode is the real Zenoh router (``rosnet-tui relay
serve``), and rmw_zenohd or zenohd read the same file.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from rosnet_tui.core.config.paths import default_config_dir
from rosnet_tui.core.config.settings_model import ZENOH_PORT_DEFAULT
from rosnet_tui.core.files.regular_file import FileRefusedError, read_regular
from rosnet_tui.core.ros.fleet_tls import TlsPaths, tls_paths
from rosnet_tui.core.ros.ros2 import LEASE_MS, MANAGED_HEADER, config_value, loads_json5

CONFIG_NAME = "zenoh-relay.json5"


def default_relay_config_path() -> Path:
    """Where the relay's router config is written on the relay (`relay serve` reads it)."""
    return default_config_dir() / CONFIG_NAME


def relay_router_config(name: str, port: int = ZENOH_PORT_DEFAULT,
                        tls: TlsPaths | None = None) -> dict[str, Any]:
    """The relay's router configuration: mode router, mutual TLS on every IPv4 address of the
    relay at *port*, the fleet CA as trust root, the relay's key and certificate (naming
    *name*) from *tls* (default: this user's ~/.config/rosnet-tui/tls)."""
    p = tls or tls_paths(default_config_dir())
    return {
        "mode": "router",
        "connect": {"endpoints": []},
        # 0.0.0.0, not one address: an endpoint on an address that goes away is not re-bound.
        "listen": {"endpoints": [f"tls/0.0.0.0:{port}"]},
        "scouting": {"multicast": {"enabled": False},
                     "gossip": {"enabled": True, "multihop": False,
                                "target": {"router": ["router", "peer"], "peer": ["router"]},
                                "autoconnect": {"router": [], "peer": []}}},
        "timestamping": {"enabled": {"router": True, "peer": True, "client": True}},
        "routing": {"router": {"peers_failover_brokering": False}},
        "transport": {"link": {
            "protocols": ["tls"],
            "tx": {"lease": LEASE_MS, "keep_alive": 4},
            "tls": {"root_ca_certificate": str(p.ca_crt),
                    "listen_private_key": str(p.node_key),
                    "listen_certificate": str(p.node_crt),
                    "enable_mtls": True,
                    "verify_name_on_connect": True}}},
        "adminspace": {"enabled": True, "permissions": {"read": True, "write": False}},
    }


def render_relay_config(name: str, port: int = ZENOH_PORT_DEFAULT,
                        tls: TlsPaths | None = None) -> str:
    head = [MANAGED_HEADER + " (`rosnet-tui relay apply` on the master): the whole file is",
            "// rewritten; change [relay] in the master's settings instead of editing it.",
            f"// Zenoh router of the relay {name}: every component's router dials in here with",
            "// its fleet certificate (mutual TLS); nothing else gets a session.",
            "// Start it with: rosnet-tui relay serve (or zenohd / rmw_zenohd with this file)."]
    return "\n".join(head) + "\n" + json.dumps(relay_router_config(name, port, tls),
                                                indent=2) + "\n"


def tls_files(config: dict[str, Any]) -> dict[str, str]:
    """The TLS files a relay config names (CA, key, certificate), by what they are."""
    tls = ((config.get("transport") or {}).get("link") or {}).get("tls") or {}
    return {what: str(tls.get(key) or "") for what, key in (
        ("the fleet CA certificate", "root_ca_certificate"),
        ("the relay's private key", "listen_private_key"),
        ("the relay's certificate", "listen_certificate"))}


# --------------------------------------------------------------------------- relay serve
class RelayConfigError(Exception):
    """The relay's router cannot start from this config: a missing or unreadable file, not a
    router's config, a TLS file missing (the caller exits 2)."""


class RelayStartError(Exception):
    """Zenoh refused to start the router (the port taken, a certificate it cannot use)."""


def read_relay_config(path: Path) -> dict[str, Any]:
    """The relay's router config at *path*, checked before Zenoh reads it: a JSON5 object of a
    router that listens, and every TLS file it names present. Raises RelayConfigError."""
    try:
        text = read_regular(path, 1 << 20).decode("utf-8", "replace")
    except FileNotFoundError:
        raise RelayConfigError(f"no relay router config at {path} (the master's `rosnet-tui "
                               "relay apply` writes it there), or name one with "
                               "--router-config") from None
    except FileRefusedError:
        raise RelayConfigError(f"{path} is not a regular file of at most 1 MiB") from None
    except OSError as exc:
        raise RelayConfigError(f"cannot read {path}: {exc.strerror or exc}") from None
    try:
        config = loads_json5(text)
    except ValueError as exc:
        raise RelayConfigError(f"{path} is not valid JSON5: {exc}") from None
    if not isinstance(config, dict) or config.get("mode") != "router":
        raise RelayConfigError(f"{path} is not a Zenoh router's config (mode \"router\")")
    if not config_value(config, "listen/endpoints"):
        raise RelayConfigError(f"{path} listens on nothing: the relay's router must listen")
    for what, file in tls_files(config).items():
        if not file:
            raise RelayConfigError(f"{path} names no {what}: the relay takes fleet "
                                   "certificates only (mutual TLS)")
        if not Path(file).is_file():
            raise RelayConfigError(f"{what} is missing ({file}): the fleet CA on the master "
                                   "signs the relay's certificate (`rosnet-tui relay apply`)")
    return config


def listen_endpoints(path: Path) -> list[str]:
    """Where the relay's router at *path* listens (its config's listen/endpoints)."""
    return [str(e) for e in config_value(read_relay_config(path), "listen/endpoints") or []]


def open_relay(path: Path) -> Any:
    """The relay's router, started from the config at *path* (checked first): a router-mode
    Zenoh session, the real Rust router. Raises RelayConfigError, RelayStartError."""
    read_relay_config(path)
    try:
        import zenoh  # noqa: PLC0415 - only on the relay, when its router starts
    except ImportError as exc:
        raise RelayStartError(f"eclipse-zenoh cannot be loaded ({exc}): reinstall rosnet-tui "
                              "as the README says") from None
    try:
        return zenoh.open(zenoh.Config.from_file(str(path)))
    except Exception as exc:  # zenoh.ZError: the reason is in its text
        raise RelayStartError(str(exc).split(" at /", 1)[0].strip() or type(exc).__name__) \
            from None
