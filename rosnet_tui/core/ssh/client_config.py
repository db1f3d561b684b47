"""The technician's way through the relay: a marked block in ``~/.ssh/config`` with one ``Host``
per component that has a tunnel, so plain ``ssh turtlebot`` jumps through the relay as
rosnet-tui does (:mod:`.connection`), the host key checked under the component's own name.

The block goes at the top of the file (OpenSSH takes the first value it finds, so a later
``Host *`` cannot override it) and ends with ``Match all``, so the lines after it apply to the
hosts they applied to before. It is written with the managed-file writer: preview, backup,
undo, atomic.
"""

from __future__ import annotations

import os
from pathlib import Path

from rosnet_tui.core.config.settings_model import Settings
from rosnet_tui.core.files import managed_file as mf
from rosnet_tui.core.files import managed_text as mt
from rosnet_tui.core.files import managed_write as mw
from rosnet_tui.core.ssh.known_hosts import host_key_name
from rosnet_tui.core.ssh.options import relay_route


def default_ssh_config_path() -> Path:
    return Path(os.path.expanduser("~")) / ".ssh" / "config"


def jump_hosts_block(s: Settings) -> list[str]:
    """The block's lines: a ``Host`` for each other component with a tunnel on the relay
    (empty without a relay or tunnels)."""
    route = relay_route(s.relay)
    if route is None:
        return []
    jump = f"{route.user}@{route.host}" + (f":{route.port}" if route.port != 22 else "")
    lines = [f"# Components behind carrier NAT, through the relay {route.host} "
             "(rosnet-tui relay tunnel runs on each)"]
    for name, port in route.tunnels:
        if name == s.this.name:
            continue
        peer = s.peer(name)
        lines += [f"Host {name}", "    HostName 127.0.0.1", f"    Port {port}"]
        if peer is not None and peer.ssh_user:
            lines.append(f"    User {peer.ssh_user}")
        lines += [f"    ProxyJump {jump}",
                  f"    HostKeyAlias {host_key_name(name, peer.ssh_port if peer else 22)}"]
    if len(lines) == 1:
        return []
    return [*lines, "Match all"]


def preview_ssh_config(s: Settings, path: Path | None = None, *,
                       state_dir: Path | None = None) -> mf.Preview | None:
    """The preview of our block in *path* (default ``~/.ssh/config``). When the settings give
    no component to jump to ([relay] or the tunnels removed), the preview takes out a block an
    earlier apply wrote, every other line kept; None when there is none (nothing to write)."""
    body = jump_hosts_block(s)
    path = Path(path) if path is not None else default_ssh_config_path()
    if not body:
        return _preview_removal(path, state_dir)
    old = mw.read_bytes(path, state_dir=state_dir)
    if old is None and not path.parent.is_dir():
        raise mt.ManagedFileError(f"{path.parent} does not exist: make it first "
                                  f"(mkdir -m 700 {path.parent})")
    return mf.preview_block(path, body, position="top",
                            label=f"SSH through the relay in {path.name}", new_mode=0o600,
                            current=old, use_current=True)


def _preview_removal(path: Path, state_dir: Path | None) -> mf.Preview | None:
    """Our stale block taken out of *path* (None: the file has none, or is not there)."""
    if not path.parent.is_dir():
        return None
    old = mw.read_bytes(path, state_dir=state_dir)
    text = mt.decode(old) if old is not None else None
    if text is None or mt.extract_block(text) is None:
        return None
    return mf.Preview(path, old, mt.encode(mt.remove_block(text)),
                      f"no SSH through the relay any more: its block out of {path.name}", (),
                      0o600)


def ssh_config_previews(s: Settings, path: Path | None = None, *,
                        state_dir: Path | None = None) -> tuple[list[mf.Preview], list[str]]:
    """What ``ros apply`` and the ROS step add for the relay: the ``~/.ssh/config`` preview (none
    without components to jump to) and a note when it cannot be made (the rest is written)."""
    try:
        p = preview_ssh_config(s, path, state_dir=state_dir)
    except mt.ManagedFileError as exc:
        return [], [f"~/.ssh/config is left alone: {exc}"]
    return ([p] if p is not None else []), []
