"""rosnet-tui installed on a lab computer the README's way (issue 21).

The README's first command, ``pipx install --force .``, puts rosnet-tui (and eclipse-zenoh) in a
virtual environment of its own made from the distribution's Python, at
``~/.local/share/pipx/venvs/rosnet-tui``, and links the launcher into ``~/.local/bin``; the
distribution's ``python3`` has no eclipse-zenoh. :func:`install` gives a lab computer's home that
very layout (pipx itself is not packaged here, so: ``/usr/bin/python3 -m venv`` and a real
``pip install`` of this checkout, which is what pipx runs).

Installing takes seconds, so one virtual environment is built per source tree (keyed by a hash of
pyproject.toml and the package's files, cached under /var/cache/rosnet-tui-lab with pip's wheel
cache beside it, built under a lock so parallel pytest processes share it). Each home gets its own
copy: hard links (the same file system) or copies, with the launchers' interpreter lines and
pyvenv.cfg rewritten for the new place (the ``#!/bin/sh`` form pip writes when the path is too
long for a ``#!`` line), so no file of the cache is ever changed through a copy.

A lab serves the home to SSH sessions with sshd's ``SetEnv HOME=<home>`` and a PATH without the
development interpreter (topology.sshd_config, topology.SSH_SESSION_PATH).
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import hashlib
import os
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
SYSTEM_PYTHON = "/usr/bin/python3"   # Debian 12's 3.11: externally managed, no eclipse-zenoh
CACHE = Path(os.environ.get("ROSNET_LAB_INSTALL_CACHE", "/var/cache/rosnet-tui-lab"))
VENV = Path(".local/share/pipx/venvs/rosnet-tui")   # pipx's default PIPX_HOME, under a home
LAUNCHER = Path(".local/bin/rosnet-tui")            # pipx's default PIPX_BIN_DIR, under a home
KEEP = 3                  # cached builds kept (the newest), so old trees do not pile up
PRUNE_GRACE_S = 3600.0    # a build used (installed from) more recently is never pruned
PREFIX_FILE = ".rosnet-lab-prefix"   # in a cached build: the path it was built at
_SHEBANG_MAX = 127        # longer interpreter lines: pip writes the /bin/sh form


def source_key() -> str:
    """A hash of what the installation is made from: pyproject.toml, the package's files and
    the system Python's version."""
    h = hashlib.sha256()
    h.update(subprocess.run([SYSTEM_PYTHON, "-c", "import sys; print(sys.version)"],
                            capture_output=True, check=True, timeout=30).stdout)
    files = [REPO / "pyproject.toml"]
    files += sorted(p for p in (REPO / "rosnet_tui").rglob("*")
                    if p.is_file() and "__pycache__" not in p.parts)
    for p in files:
        h.update(str(p.relative_to(REPO)).encode() + b"\0" + p.read_bytes() + b"\0")
    return h.hexdigest()[:16]


@contextlib.contextmanager
def locked(shared: bool):
    CACHE.mkdir(parents=True, exist_ok=True)
    with open(CACHE / ".lock", "a+") as f:
        fcntl.flock(f, fcntl.LOCK_SH if shared else fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


def built_venv(timeout: float = 600) -> Path:
    """The cached virtual environment for this source tree, built (pip install .) if missing."""
    key = source_key()
    done = CACHE / f"venv-{key}"
    if (done / PREFIX_FILE).is_file():
        return done
    with locked(shared=False):
        if (done / PREFIX_FILE).is_file():
            return done
        work = CACHE / f"build-{key}-{os.getpid()}"
        shutil.rmtree(work, ignore_errors=True)
        env = {k: v for k, v in os.environ.items()
               if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV", "PIP_USER")}
        env["PIP_CACHE_DIR"] = str(CACHE / "pip")
        try:
            subprocess.run([SYSTEM_PYTHON, "-m", "venv", str(work)], check=True, timeout=120,
                           env=env, capture_output=True)
            r = subprocess.run([str(work / "bin" / "python"), "-m", "pip", "install", "-q",
                                "--no-input", str(REPO)], env=env, capture_output=True,
                               text=True, timeout=timeout)
            if r.returncode != 0:
                raise RuntimeError(f"pip install of {REPO} failed: {r.stderr[-3000:]}")
            r = subprocess.run([str(work / "bin" / "python"), "-c",
                                "import zenoh, rosnet_tui; print(rosnet_tui.__version__)"],
                               env=env, capture_output=True, text=True, timeout=60)
            if r.returncode != 0:
                raise RuntimeError(f"the built environment does not import: {r.stderr[-2000:]}")
            (work / PREFIX_FILE).write_text(str(work))
            shutil.rmtree(done, ignore_errors=True)
            work.rename(done)
        finally:
            shutil.rmtree(work, ignore_errors=True)
        prune(keep=done)
    return done


def prune(keep: Path) -> None:
    """Remove all but the newest KEEP cached builds (called under the exclusive lock), except
    any used within PRUNE_GRACE_S: another source tree's pytest may be installing from it (its
    install() marks it used under the shared lock, see there)."""
    builds = sorted((p for p in CACHE.glob("venv-*") if p != keep),
                    key=lambda p: p.stat().st_mtime, reverse=True)
    for old in builds[KEEP - 1:]:
        if time.time() - old.stat().st_mtime >= PRUNE_GRACE_S:
            shutil.rmtree(old, ignore_errors=True)
    for stale in CACHE.glob("build-*"):   # a build killed half-way (its process is gone)
        pid = stale.name.rsplit("-", 1)[-1]
        if pid.isdigit() and not Path(f"/proc/{pid}").exists():
            shutil.rmtree(stale, ignore_errors=True)


def _link_tree(src: Path, dst: Path) -> None:
    """*src* at *dst*: directories made, symlinks kept, files hard-linked (copied across file
    systems)."""
    for root, dirs, files in os.walk(src):
        rel = Path(root).relative_to(src)
        (dst / rel).mkdir(parents=True, exist_ok=True)
        for name in dirs + files:
            s, d = Path(root) / name, dst / rel / name
            if s.is_symlink():
                d.symlink_to(os.readlink(s))
                if name in dirs:
                    dirs.remove(name)
            elif name in files:
                try:
                    os.link(s, d)
                except OSError as exc:
                    if exc.errno not in (errno.EXDEV, errno.EPERM, errno.EMLINK):
                        raise
                    shutil.copy2(s, d)


def _replace(path: Path, data: bytes) -> None:
    """New content for *path* in a new inode (never through a hard link into the cache)."""
    mode = path.stat().st_mode & 0o7777
    tmp = path.with_name(path.name + ".rnl-tmp")
    tmp.write_bytes(data)
    os.chmod(tmp, mode)
    os.replace(tmp, path)


def _shebang(python: str) -> bytes:
    """The interpreter line(s) pip writes for *python* (the /bin/sh form for long paths)."""
    if len(python) + 2 <= _SHEBANG_MAX and " " not in python:
        return f"#!{python}\n".encode()
    return f"#!/bin/sh\n'''exec' \"{python}\" \"$0\" \"$@\"\n' '''\n".encode()


def _relocate(venv: Path, old: str) -> None:
    """Point *venv*'s launchers and pyvenv.cfg at *venv* instead of *old*."""
    new = str(venv)
    for f in (venv / "bin").iterdir():
        if f.is_symlink() or not f.is_file():
            continue
        data = f.read_bytes()
        if not data.startswith(b"#!"):
            continue
        first, _, rest = data.partition(b"\n")
        if first.startswith(b"#!/bin/sh") and rest.startswith(b"'''exec'"):
            line2, _, rest = rest.partition(b"\n")
            _, _, rest = rest.partition(b"\n")          # the closing "' '''" line
            first = b"#!" + line2.split(b'"')[1]
        if old.encode() not in first:
            if old.encode() in data:
                _replace(f, data.replace(old.encode(), new.encode()))
            continue
        python = first[2:].decode().strip().replace(old, new)
        _replace(f, _shebang(python) + rest)
    cfg = venv / "pyvenv.cfg"
    _replace(cfg, cfg.read_bytes().replace(old.encode(), new.encode()))


def install(home: Path) -> Path:
    """rosnet-tui installed in *home* as the README's pipx line leaves it; the launcher's path
    (``<home>/.local/bin/rosnet-tui``). Replaces an earlier install there."""
    built = built_venv()
    venv = home / VENV
    if (venv / PREFIX_FILE).is_file() and (venv / PREFIX_FILE).read_text() == built.name \
            and (home / LAUNCHER).exists():
        return home / LAUNCHER                           # this very build is installed there
    uninstall(home)
    venv.parent.mkdir(parents=True, exist_ok=True)
    # The build is linked under the shared lock, so no prune (exclusive lock) runs meanwhile;
    # a prune between built_venv() and here may have removed it: then it is built again.
    for _ in range(3):
        with locked(shared=True):
            if not (built / PREFIX_FILE).is_file():
                built = None
            else:
                os.utime(built)                 # in use: pruned no sooner than PRUNE_GRACE_S
                old = (built / PREFIX_FILE).read_text()
                work = Path(tempfile.mkdtemp(prefix=".rosnet-tui-", dir=venv.parent))
                try:
                    _link_tree(built, work / "v")
                    _replace(work / "v" / PREFIX_FILE, built.name.encode())   # which build
                    (work / "v").rename(venv)
                finally:
                    shutil.rmtree(work, ignore_errors=True)
                break
        built = built_venv()
    else:
        raise RuntimeError(f"the cached build under {CACHE} kept vanishing")
    _relocate(venv, old)
    launcher = home / LAUNCHER
    launcher.parent.mkdir(parents=True, exist_ok=True)
    launcher.symlink_to(venv / "bin" / "rosnet-tui")     # pipx links it, as here
    return launcher


def uninstall(home: Path) -> None:
    """What ``pipx uninstall rosnet-tui`` leaves: no venv, no launcher."""
    (home / LAUNCHER).unlink(missing_ok=True)
    shutil.rmtree(home / VENV, ignore_errors=True)


def installed(home: Path) -> bool:
    return (home / LAUNCHER).exists()


__all__ = ["KEEP", "LAUNCHER", "PREFIX_FILE", "PRUNE_GRACE_S", "VENV", "built_venv", "install",
           "installed", "locked", "prune", "uninstall"]
