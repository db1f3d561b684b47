"""The relay's side of `rosnet-tui relay apply`: a program the master feeds on stdin to the
interpreter of the rosnet-tui installed on the relay (over SSH, as the peers' programs), one
``ROSNET_RELAY {json}`` line out. Standard library only and nothing of rosnet-tui: the relay's
install may be another version.

- ``look [PATH...]``: where this user's rosnet-tui files are (the config folder, the TLS files,
  the relay's router config), the interpreter and package that run ``relay serve``, whether
  systemd runs here, and the text of the relay's files and of each PATH (None: absent).
- ``write JSON``: ``{"files": [{"path", "content" (None: remove), "mode", "expect"}]}``: each
  file's current digest must still be ``expect`` (the SHA-256 of what the master previewed, or
  "absent"; None: not checked), for all of them before any is written; then each is written
  atomically (temp file, fsync, rename) or removed.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import os
import pwd
import sys
from pathlib import Path

REPORT_MARK = "ROSNET_RELAY "
RELAY_CONFIG = "zenoh-relay.json5"
MAX_BYTES = 1 << 20
ABSENT = "absent"


def config_dir() -> Path:
    """This user's rosnet-tui config folder: the rule of core/config/paths.py, restated (this
    program imports nothing of rosnet-tui; tests/test_relay_apply.py holds the two equal)."""
    base = os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    return Path(base) / "rosnet-tui"


def digest(content: str | None) -> str:
    return ABSENT if content is None else hashlib.sha256(content.encode()).hexdigest()


def read(path: Path) -> str | None:
    """The text at *path* (None: absent); a file that is not a regular one of at most 1 MiB is
    refused (never waited on: a FIFO is opened without blocking)."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_NOFOLLOW)
    except FileNotFoundError:
        return None
    with os.fdopen(fd, "rb") as f:
        st = os.fstat(f.fileno())
        if not (st.st_mode & 0o170000 == 0o100000) or st.st_size > MAX_BYTES:
            raise OSError(f"{path} is not a regular file of at most 1 MiB")
        return f.read(MAX_BYTES).decode("utf-8", "replace")


def writable(path: Path) -> bool:
    """Whether this user may create or replace *path* (its nearest existing folder)."""
    d = path.parent
    while not d.exists() and d != d.parent:
        d = d.parent
    return os.access(d, os.W_OK | os.X_OK)


def look(extra: list[str]) -> dict:
    cfg = config_dir()
    tls = cfg / "tls"
    spec = importlib.util.find_spec("rosnet_tui")
    root = str(Path(spec.origin).resolve().parent.parent) if spec and spec.origin else ""
    paths = {"config_dir": str(cfg), "relay_config": str(cfg / RELAY_CONFIG),
             "ca_crt": str(tls / "ca.crt"), "node_key": str(tls / "node.key"),
             "node_crt": str(tls / "node.crt")}
    files = {}
    for p in [paths["relay_config"], paths["ca_crt"], paths["node_crt"], *extra]:
        files[p] = read(Path(p))
    return {**paths, "python": sys.executable, "package_root": root,
            "user": _user(), "home": str(Path.home()),
            "systemd": os.path.isdir("/run/systemd/system"),
            "node_key_exists": Path(paths["node_key"]).is_file(),
            "files": files, "writable": {p: writable(Path(p)) for p in extra}}


def _user() -> str:
    try:
        return pwd.getpwuid(os.geteuid()).pw_name
    except KeyError:
        return str(os.geteuid())


def _atomic(path: Path, data: bytes, mode: int) -> None:
    path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}-{os.urandom(4).hex()}")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, mode)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, mode)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise


def write(spec: dict) -> dict:
    files = spec.get("files") or []
    changed = [f["path"] for f in files
               if f.get("expect") is not None and digest(read(Path(f["path"]))) != f["expect"]]
    if changed:
        return {"error": "changed on the relay since the preview: " + ", ".join(changed),
                "changed": changed}
    done = []
    for f in files:
        path = Path(f["path"])
        if f.get("content") is None:
            try:
                path.unlink()
            except FileNotFoundError:
                pass
        else:
            _atomic(path, str(f["content"]).encode(), int(f.get("mode") or 0o644))
        done.append(str(path))
    return {"written": done}


def main(argv: list[str]) -> int:
    cmd, rest = (argv[0], argv[1:]) if argv else ("", [])
    try:
        if cmd == "look":
            out = look(rest)
        elif cmd == "write" and len(rest) == 1:
            out = write(json.loads(rest[0]))
        else:
            print("usage: look [PATH...] | write JSON", file=sys.stderr)
            return 2
    except (OSError, ValueError, KeyError, TypeError, RecursionError) as exc:
        out = {"error": str(exc) or type(exc).__name__}
    print(REPORT_MARK + json.dumps(out), flush=True)
    return 1 if "error" in out else 0


if __name__ == "__main__":   # fed on stdin to the relay's installed interpreter
    sys.exit(main(sys.argv[1:]))
