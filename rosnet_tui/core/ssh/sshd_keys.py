"""This machine's sshd host keys, from where its sshd takes them: ``sshd -T``'s ``hostkey`` lines
when this process may run it (root: sshd loads the private keys before it prints), else the
``HostKey`` lines of sshd_config and of the files it Includes, else sshd's default key files.
An sshd that keeps its keys outside /etc/ssh is known by them too (relay.tunnel compares the key
answering at this component's tunnel port with these).

The public half is read from ``<key>.pub``, as sshd itself looks for it.
"""

from __future__ import annotations

import base64
import glob
import os
import re
import shlex
import shutil
import subprocess
from dataclasses import dataclass, field
from pathlib import Path

from rosnet_tui.core.files.regular_file import read_regular
from rosnet_tui.core.ssh.known_hosts import key_fingerprint

SSHD_DIR = Path("/etc/ssh")
# sshd's own list when sshd_config names no HostKey (OpenSSH's servconf.c)
DEFAULT_KEYS = ("ssh_host_rsa_key", "ssh_host_ecdsa_key", "ssh_host_ed25519_key")
MAX_INCLUDE_DEPTH = 16       # as sshd's ReadConfig
MAX_CONFIG_BYTES = 1 << 20
SSHD_T_TIMEOUT_S = 3.0
_KEYWORD = re.compile(r"^\s*([A-Za-z]+)(?:\s*=\s*|\s+)(.*)$")


@dataclass
class OwnKeys:
    """The host keys found, where their names came from, and the key files named whose public
    half could not be read."""

    keys: dict[bytes, Path] = field(default_factory=dict)   # key blob -> its .pub file
    source: str = ""
    unread: list[Path] = field(default_factory=list)

    def words(self) -> str:
        """One line for a check's evidence: which keys, from where."""
        got = ", ".join(f"{p} ({key_fingerprint(b)})" for b, p in self.keys.items()) or "none"
        miss = f"; not readable: {', '.join(str(p) for p in self.unread)}" if self.unread else ""
        return f"this machine's sshd host keys ({self.source}): {got}{miss}"


def _sshd() -> str | None:
    return shutil.which("sshd") or next(
        (p for p in ("/usr/sbin/sshd", "/usr/local/sbin/sshd") if os.access(p, os.X_OK)), None)


def _from_sshd_t(config: Path) -> list[Path] | None:
    """``sshd -T -f CONFIG``'s hostkey files (None: sshd absent, or it would not say)."""
    sshd = _sshd()
    if sshd is None:
        return None
    try:
        out = subprocess.run([sshd, "-T", "-f", str(config)], capture_output=True, text=True,
                             timeout=SSHD_T_TIMEOUT_S, stdin=subprocess.DEVNULL)
    except (OSError, subprocess.SubprocessError):
        return None
    if out.returncode != 0:
        return None
    keys = [Path(line.split(None, 1)[1].strip()) for line in out.stdout.splitlines()
            if line.lower().startswith("hostkey ") and line.split(None, 1)[1].strip()]
    return keys or None


def _words(text: str) -> tuple[str, list[str]] | None:
    m = _KEYWORD.match(text)
    if m is None:
        return None
    try:
        args = shlex.split(m.group(2), comments=True)
    except ValueError:
        return None
    return m.group(1).lower(), args


def _config_lines(path: Path, sshd_dir: Path, depth: int, out: list[Path]) -> None:
    """Collect the HostKey files of *path* and what it Includes into *out* (sshd's order)."""
    text = read_regular(path, MAX_CONFIG_BYTES).decode("utf-8", "replace")
    for line in text.splitlines():
        kw = _words(line)
        if kw is None:
            continue
        key, args = kw
        if key == "hostkey" and args and args[0].lower() != "none":
            p = Path(os.path.expanduser(args[0]))
            out.append(p if p.is_absolute() else Path("/") / p)   # sshd's working folder
        elif key == "include" and depth < MAX_INCLUDE_DEPTH:
            for pattern in args:
                pattern = os.path.expanduser(pattern)
                if not os.path.isabs(pattern):
                    pattern = str(sshd_dir / pattern)
                for inc in sorted(glob.glob(pattern)):
                    try:
                        _config_lines(Path(inc), sshd_dir, depth + 1, out)
                    except OSError:
                        continue


def _from_config(config: Path, sshd_dir: Path) -> list[Path] | None:
    """The HostKey files sshd_config and its Include files name (None: unreadable or none)."""
    out: list[Path] = []
    try:
        _config_lines(config, sshd_dir, 0, out)
    except OSError:
        return None
    return out or None


def own_host_keys(sshd_dir: Path = SSHD_DIR, *, ask_sshd: bool | None = None) -> OwnKeys:
    """The public host keys of this machine's sshd, whose config is ``sshd_dir/sshd_config``.
    *ask_sshd* (default: when root) runs ``sshd -T`` first."""
    config = sshd_dir / "sshd_config"
    if ask_sshd is None:
        ask_sshd = os.geteuid() == 0
    files, source = (_from_sshd_t(config), f"`sshd -T -f {config}`") if ask_sshd else (None, "")
    if files is None:
        files, source = _from_config(config, sshd_dir), f"the HostKey lines of {config}"
    defaults = files is None
    if files is None:
        files = [sshd_dir / n for n in DEFAULT_KEYS]
        source = f"sshd's default keys in {sshd_dir}: {config} names none"
    found = OwnKeys(source=source)
    for key in dict.fromkeys(files):
        pub = Path(f"{key}.pub")
        try:
            fields = read_regular(pub, 1 << 16).decode("ascii", "replace").split()
            found.keys.setdefault(base64.b64decode(fields[1], validate=True), pub)
        except FileNotFoundError:
            if not defaults:            # a default key type this machine lacks is no news
                found.unread.append(pub)
        except (OSError, IndexError, ValueError):
            found.unread.append(pub)
    return found
