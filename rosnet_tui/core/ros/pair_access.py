"""A member's way in to the master for pairing: one line in the master's
``~/.ssh/authorized_keys`` whose forced command can only sign that member's request.

``restrict,command="<python> -I -m rosnet_tui ros pair --serve NAME [--config FILE]" <key>
rosnet-tui-pair:NAME``: whatever the member asks for, sshd runs that command (no shell, no
terminal, no forwarding); it reads the request on stdin and signs it only when it names NAME and
NAME is a member in the master's settings. ``ros pair --remove NAME`` deletes NAME's lines.

The file is rewritten atomically (the lines we do not own kept as they are, its mode kept).
"""

from __future__ import annotations

import os
import re
import shlex
import sys
from pathlib import Path

from rosnet_tui.core.files.managed_write import atomic_write
from rosnet_tui.core.files.regular_file import read_regular

TAG = "rosnet-tui-pair:"
KEY_TYPES = ("ssh-ed25519", "ecdsa-sha2-nistp256", "ecdsa-sha2-nistp384", "ecdsa-sha2-nistp521",
             "ssh-rsa", "sk-ssh-ed25519@openssh.com", "sk-ecdsa-sha2-nistp256@openssh.com")
_B64 = re.compile(r"^[A-Za-z0-9+/]+={0,2}$")


MAX_KEYS_BYTES = 1 << 20    # an authorized_keys file far bigger than any real one is refused


class AccessError(ValueError):
    """A public key or a name that cannot be admitted: says why."""


def authorized_keys_path(home: Path | None = None) -> Path:
    return Path(home if home is not None else Path.home()) / ".ssh" / "authorized_keys"


def parse_public_key(text: str) -> tuple[str, str]:
    """(type, base64) of one OpenSSH public key line (``ssh-ed25519 AAAA... comment``)."""
    words = text.strip().split()
    if len(words) < 2 or words[0] not in KEY_TYPES or not _B64.match(words[1]) \
            or len(words[1]) > 4096:
        raise AccessError("that is not one OpenSSH public key (like `ssh-ed25519 AAAA... "
                          "comment`, the .pub file)")
    return words[0], words[1]


def forced_line(name: str, public_key: str, config: Path | None = None,
                python: str | None = None) -> str:
    """The authorized_keys line letting *public_key* ask for *name*'s certificate, nothing else."""
    ktype, b64 = parse_public_key(public_key)
    cmd = [python or sys.executable, "-I", "-m", "rosnet_tui", "ros", "pair", "--serve", name]
    if config is not None:
        cmd += ["--config", str(Path(config).absolute())]
    command = " ".join(shlex.quote(c) for c in cmd)
    if '"' in command or "\\" in command or "\n" in command:
        raise AccessError("the interpreter's or the settings' path holds a quote, a backslash "
                          "or a line break: it cannot be written in authorized_keys")
    return f'restrict,command="{command}" {ktype} {b64} {TAG}{name.lower()}'


def _owned_by(line: str, name: str) -> bool:
    words = line.split()
    return bool(words) and words[-1] == TAG + name.lower()


def _read(path: Path) -> list[str]:
    """authorized_keys' lines: a regular file only (a FIFO there is refused, not waited on)."""
    try:
        data = read_regular(path, MAX_KEYS_BYTES)
    except FileNotFoundError:
        return []
    except OSError as exc:
        raise AccessError(f"cannot read {path}: {exc.strerror or exc}") from None
    return data.decode("utf-8", errors="surrogateescape").splitlines()


def _write(path: Path, lines: list[str]) -> None:
    path.parent.mkdir(mode=0o700, exist_ok=True)
    try:
        mode = os.stat(path, follow_symlinks=False).st_mode & 0o7777
    except FileNotFoundError:
        mode = 0o600
    data = "".join(x + "\n" for x in lines).encode("utf-8", errors="surrogateescape")
    try:
        atomic_write(path, data, create_mode=0o600, mode=mode)
    except OSError as exc:
        raise AccessError(f"cannot write {path}: {exc.strerror or exc}") from None


def admit(name: str, public_key: str, *, path: Path, config: Path | None = None,
          python: str | None = None) -> str:
    """Give *public_key* the pairing line for *name* (replacing any earlier one); the line."""
    line = forced_line(name, public_key, config, python)
    _, b64 = parse_public_key(public_key)
    lines = [x for x in _read(path) if not _owned_by(x, name)]
    if any(b64 in x.split() for x in lines):
        raise AccessError(f"that key already has a line in {path} (sshd would take that one: a "
                          "shell, or another member's pairing): a pairing key must be a key of "
                          "its own")
    _write(path, [*lines, line])
    return line


def revoke(name: str, *, path: Path) -> int:
    """Delete every pairing line of *name*; how many there were."""
    lines = _read(path)
    keep = [x for x in lines if not _owned_by(x, name)]
    if len(keep) != len(lines):
        _write(path, keep)
    return len(lines) - len(keep)


def other_keys(path: Path) -> int:
    """How many keys in *path* are not pairing lines (ways in that `--remove` cannot judge)."""
    return sum(1 for x in _read(path)
               if x.strip() and not x.lstrip().startswith("#") and TAG not in x)
