"""A warm process for `rosnet-tui check`: the second run of the checks starts where the first one
finished loading.

A cold `rosnet-tui check` spends most of its CPU before the first check starts: the interpreter,
the check modules, paramiko, requests, rich. After such a run (unless ``checks.keep_warm_s`` is 0
or ``ROSNET_TUI_WARM=0``), a process is left that has imported all of that and waits, for
``keep_warm_s`` seconds after its last use, on a Unix socket only this user can open. The next
`rosnet-tui check` hands it its arguments, environment, working directory and its own stdin,
stdout and stderr (the file descriptors themselves); the warm process forks a child, which runs
the command exactly as a cold process would (the settings are read anew, the SSH connections made
anew: nothing of one run is kept for the next) and tells the exit code back. Ctrl-C and other
signals to the command are passed on to the child, Ctrl-Z stops the child with the command; a
command that dies takes its child with it.

One warm process serves one user, in one set of namespaces (network, mounts, hostname, PIDs),
with one environment, one interpreter and one installed copy of rosnet-tui: any difference gives
another socket name, so a run is never served by a process that sees another machine, other files
or older code. Anything wrong on the way (no safe directory, a stale socket, a process that does
not answer) makes the command run cold, as before.
"""

from __future__ import annotations

import fcntl
import gc
import hashlib
import json
import os
import signal
import socket
import stat
import struct
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, fields
from pathlib import Path

from rosnet_tui.core.files.tempfiles import process_start
from rosnet_tui.core.jsonsafe import JsonInputError, loads_bounded

ENV_SWITCH = "ROSNET_TUI_WARM"      # "0": never use or leave a warm process
_LEN = struct.Struct("!I")
_MAX_REQUEST = 1 << 20
_SUN_PATH = 107                     # the longest path a Unix socket can be bound to
_ANSWER_S = 5.0                     # a warm process names its child within this, or we run cold
# Variables a shell changes as one moves about, which nothing here reads, and the switch (read
# before the key): not part of the key.
_UNKEYED = ("PWD", "OLDPWD", "_", "SHLVL", ENV_SWITCH)
_FORWARDED = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT)
# Namespaces told apart by their inode: a warm process keeps its own alive, so no other can have
# that number meanwhile. The mounts and the hostname are compared by what they are instead: a
# wrapper such as `ip netns exec` makes a new mount namespace for every command, alike each time.
_NAMESPACES = ("net", "pid", "user", "ipc")
_SERVER = "import sys; from rosnet_tui.cli import serve_warm; sys.exit(serve_warm(sys.argv[1:]))"

in_child = False                    # True in a child running a served command
_leave_after = False                # this (cold) run leaves a warm process when it ends
_server_pid = 0                     # the warm process (in it and its children)


@dataclass(frozen=True)
class Request:
    """What a command hands the warm process besides its stdin, stdout and stderr."""

    argv: list[str]              # the command line, after the program's name
    argv0: str
    cwd: str
    env: dict[str, str]
    umask: int

    def encode(self) -> bytes:
        return json.dumps(asdict(self)).encode("ascii")   # undecodable bytes as \udcXX escapes

    @classmethod
    def decode(cls, data: bytes) -> Request | None:
        """The request in *data*; None for anything else."""
        try:
            raw = loads_bounded(data.decode("utf-8", "surrogateescape"), max_depth=3)
        except JsonInputError:
            return None
        if not isinstance(raw, dict) or set(raw) != {f.name for f in fields(cls)}:
            return None
        r = cls(**raw)
        texts = isinstance(r.argv0, str) and isinstance(r.cwd, str) and isinstance(r.argv, list) \
            and all(isinstance(a, str) for a in r.argv)
        env = isinstance(r.env, dict) and all(isinstance(k, str) and isinstance(v, str)
                                              for k, v in r.env.items())
        mask = isinstance(r.umask, int) and not isinstance(r.umask, bool) and 0 <= r.umask <= 0o777
        return r if texts and env and mask else None


def enabled() -> bool:
    """Whether this process may use or leave a warm process (not switched off, not one's child)."""
    return os.environ.get(ENV_SWITCH, "1") != "0" and not in_child


def socket_dir() -> Path | None:
    """This user's directory for warm sockets: made if missing, and used only when it is a real
    directory of this user's that nobody else can enter (None otherwise)."""
    uid = os.geteuid()
    runtime = os.environ.get("XDG_RUNTIME_DIR", "")
    base = Path(runtime) if runtime.startswith("/") else Path("/tmp")
    path = base / (f"rosnet-tui-{uid}" if base == Path("/tmp") else "rosnet-tui")
    try:
        os.mkdir(path, 0o700)
    except FileExistsError:
        pass
    except OSError:
        return None
    try:
        st = os.lstat(path)
    except OSError:
        return None
    if not stat.S_ISDIR(st.st_mode) or st.st_uid != uid or st.st_mode & 0o077:
        return None
    return path


def key(env: dict[str, str] | None = None) -> str:
    """What a warm process must share with the command it serves, hashed: the user, the
    namespaces, the interpreter, rosnet-tui's installed files and the environment."""
    env = dict(os.environ if env is None else env)
    h = hashlib.sha256()
    # sys.path[0] is the script's folder (or the working one): where rosnet-tui itself comes from
    # is in the code stamp.
    search = sys.path if sys.flags.safe_path else sys.path[1:]
    parts: list[object] = [os.geteuid(), os.getegid(), sys.executable, sys.version, search,
                           sys.flags]
    for ns in _NAMESPACES:
        try:
            parts.append(os.readlink(f"/proc/self/ns/{ns}"))
        except OSError:
            parts.append(None)
    parts.append(os.uname())
    parts.append(_mounts())
    parts.append(_code_stamp())
    parts.append(sorted((k, v) for k, v in env.items() if k not in _UNKEYED))
    h.update(repr(parts).encode("utf-8", "surrogateescape"))
    return h.hexdigest()[:24]


def _mounts() -> str:
    """What is mounted where (/proc/self/mountinfo without the mounts' own numbers), namespace
    handles left out: `ip netns add` and `del` mount and unmount one under /run/netns, which
    changes no file a check reads (a key that followed them missed its warm process whenever
    a network namespace came or went meanwhile: seen in CI beside the lab's tests)."""
    try:
        with open("/proc/self/mountinfo", encoding="utf-8", errors="replace") as f:
            lines = f.read().splitlines()
    except OSError:
        return ""
    return "\n".join(line.split(" ", 2)[-1] for line in lines
                     if line.partition(" - ")[2].split(" ", 1)[0] != "nsfs")


def _code_stamp() -> tuple[str, int, int]:
    """rosnet-tui's package folder, its file count and newest change: a new install or an edit
    gives a new stamp."""
    root = Path(__file__).resolve().parents[1]
    count, newest = 0, 0
    for folder, dirs, files in os.walk(root):
        dirs[:] = [d for d in dirs if d != "__pycache__"]
        for name in files:
            if name.endswith(".py"):
                try:
                    newest = max(newest, os.stat(os.path.join(folder, name)).st_mtime_ns)
                except OSError:
                    continue
                count += 1
    return str(root), count, newest


def socket_path() -> Path | None:
    """This command's warm socket; None where there is no safe folder, or its name would be too
    long for a Unix socket (108 bytes, with the name it is readied under)."""
    folder = socket_dir()
    if folder is None or len(os.fsencode(folder)) > _SUN_PATH - 60:
        return None
    return folder / f"warm-{key()}.sock"


# ------------------------------------------------------------------------------------ the client

def run_through(argv: list[str]) -> int | None:
    """Run *argv* in this user's warm process: its exit code, or None when there is none to use
    (the caller runs the command itself, nothing having been said or done, and leaves one when
    it ends: :func:`after_run`)."""
    global _leave_after
    path = socket_path()
    if path is None:
        return None
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        code = _ask(sock, path, argv)
        _leave_after = code is None
        return code
    except KeyboardInterrupt:       # before the child was named: it ends with our socket
        print("interrupted", file=sys.stderr)
        return 130
    finally:
        sock.close()


def _ask(sock: socket.socket, path: Path, argv: list[str]) -> int | None:
    sock.settimeout(_ANSWER_S)
    try:
        sock.connect(str(path))
    except ConnectionRefusedError:      # its process is gone
        _sweep(path.parent)
        return None
    except OSError:
        return None
    try:
        cwd = os.getcwd()
    except OSError:
        return None
    request = Request(argv, sys.argv[0], cwd, dict(os.environ), _umask()).encode()
    fds, spare = _stdio_fds()
    try:
        socket.send_fds(sock, [_LEN.pack(len(request))], fds)
        sock.sendall(request)
        reader = sock.makefile("rb")
        first = reader.readline(64)
    except OSError:
        return None
    finally:
        for fd in spare:
            os.close(fd)
    if not first.startswith(b"P") or not first[1:].strip().isdigit():
        return None
    sock.settimeout(None)
    return _wait_for(int(first[1:]), reader)


def _wait_for(child: int, reader) -> int:
    """Pass this process's signals on to *child* until it says its exit code; a child ended by
    one of them ends this process the same way."""
    forwarded: list[int] = []

    def tell(signum: int) -> None:
        try:
            os.kill(child, signum)
        except OSError:
            pass

    def forward(signum: int, _frame: object) -> None:
        forwarded.append(signum)
        tell(signum)

    def pause(_signum: int, _frame: object) -> None:
        # Ctrl-Z: the child stops first (it writes to our terminal), then this process, as the
        # shell expects; when the shell continues this process, the child goes on too. In an
        # orphaned process group the kernel does not stop us (nobody could continue us): the
        # child then goes on at once.
        tell(signal.SIGSTOP)
        signal.signal(signal.SIGTSTP, signal.SIG_DFL)
        os.kill(os.getpid(), signal.SIGTSTP)
        signal.signal(signal.SIGTSTP, pause)
        tell(signal.SIGCONT)

    for sig in _FORWARDED:
        signal.signal(sig, forward)
    signal.signal(signal.SIGTSTP, pause)
    line = reader.readline(64)
    if line.startswith(b"E") and line[1:].strip().lstrip(b"-").isdigit():
        return int(line[1:])
    if forwarded:
        signal.signal(forwarded[-1], signal.SIG_DFL)
        os.kill(os.getpid(), forwarded[-1])
    print("rosnet-tui: the check process ended before it finished", file=sys.stderr)
    return 1


def _stdio_fds() -> tuple[list[int], list[int]]:
    """This process's stdin, stdout and stderr; /dev/null for one that is closed (the second
    list: ours to close)."""
    fds, spare = [], []
    for fd in (0, 1, 2):
        try:
            os.fstat(fd)
            fds.append(fd)
        except OSError:
            null = os.open(os.devnull, os.O_RDWR)
            fds.append(null)
            spare.append(null)
    return fds, spare


def _umask() -> int:
    mask = os.umask(0o077)
    os.umask(mask)
    return mask


def _unlink(path: Path) -> None:
    try:
        path.unlink()
    except OSError:
        pass


def after_run(keep_s: float) -> None:
    """A command's run is over and the settings say *keep_s* (``checks.keep_warm_s``): a cold run
    leaves a warm process; a served one with *keep_s* 0 stops the warm process."""
    if in_child:
        if keep_s <= 0 and _server_pid and os.getppid() == _server_pid:
            os.kill(_server_pid, signal.SIGTERM)
    elif _leave_after:
        start(keep_s)


def start(keep_s: float) -> None:
    """Leave a warm process for the next run of this user's commands here (unless one is there
    or warm processes are off). Its socket is named anew, not taken from the run's start: the
    process checks the name against what it sees a moment later, the run's end."""
    if keep_s <= 0 or not enabled():
        return
    path = socket_path()
    if path is None or path.exists() or _locked(_lock_path(path)):
        return
    import subprocess

    try:
        subprocess.Popen([sys.executable, "-c", _SERVER, str(path), str(keep_s)],
                         stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                         stderr=subprocess.DEVNULL, cwd="/", start_new_session=True,
                         close_fds=True)
    except OSError:
        pass


def _lock_path(path: Path) -> Path:
    return path.with_suffix(".lock")


def _locked(lock: Path) -> bool:
    """Whether a warm process holds *lock* (starting, or serving)."""
    try:
        fd = os.open(lock, os.O_RDONLY | os.O_NOFOLLOW)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except OSError:
        return True
    finally:
        os.close(fd)
    return False


def _sweep(folder: Path) -> None:
    """Remove what warm processes that were killed left in *folder*: a socket or lock whose lock
    nobody holds, a socket being readied by a process that is gone."""
    try:
        names = os.listdir(folder)
    except OSError:
        return
    for name in names:
        path = folder / name
        if name.startswith("warm-") and name.endswith((".sock", ".lock")):
            lock = _lock_path(path)
            if not _locked(lock):
                if path.suffix == ".sock":
                    _unlink(path)
                _unlink(lock)
        elif name.startswith(".warm-") and name.rsplit(".", 1)[-1].isdigit():
            try:
                os.kill(int(name.rsplit(".", 1)[-1]), 0)
            except ProcessLookupError:
                _unlink(path)
            except OSError:
                pass


# ------------------------------------------------------------------------------------ the server

class _Stop(Exception):
    pass


Runner = Callable[[list[str]], int]


def serve(path: Path, keep_s: float, run: Runner, preload: Callable[[], None]) -> int:
    """Load what a run of the checks loads, then serve runs on *path* until *keep_s* seconds pass
    without one: each in a child, by *run* (the command line's main). *preload* imports what a
    run imports. Returns when done (the socket is removed)."""
    if path.name != f"warm-{key()}.sock" or path.parent != socket_dir():
        return 2        # started for another interpreter, code or environment than this one
    lock = _lock_path(path)
    lock_fd = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o600)
    try:
        fcntl.flock(lock_fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(lock_fd)
        return 0        # another one is starting or serving
    _sweep(path.parent)
    preload()
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    global _server_pid
    me = _server_pid = os.getpid()
    staging = path.with_name(f".{path.name}.{me}")
    _unlink(staging)
    listener.bind(str(staging))
    os.chmod(staging, 0o600)
    inode = os.lstat(staging).st_ino
    listener.listen(16)

    def stop(_signum: int, _frame: object) -> None:
        raise _Stop()
    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGHUP, stop)
    signal.signal(signal.SIGCHLD, signal.SIG_IGN)     # children are not waited for
    try:
        os.rename(staging, path)      # ready: clients find a socket that answers, or none
        gc.freeze()                   # what the children share stays shared
        _serve_until_idle(listener, (path, inode, lock_fd), keep_s, run)
    except _Stop:
        pass
    finally:
        if os.getpid() == me:
            listener.close()
            _unlink(staging)
            if _is(path, inode):
                _unlink(path)
            _unlink(lock)
            os.close(lock_fd)
    return 0


def _serve_until_idle(listener: socket.socket, mine: tuple[Path, int, int], keep_s: float,
                      run: Runner) -> None:
    """Fork a child for each command that connects, until *keep_s* pass without one and no
    child is left, or the socket's name is no longer ours (*mine*: the socket's path and inode,
    and the lock)."""
    path, inode, lock_fd = mine
    deadline = time.monotonic() + keep_s
    children: dict[int, tuple[str | None, int, str | None]] = {}  # pid: start, its command's
    listener.settimeout(1.0)
    while time.monotonic() < deadline or children:
        _mind(children)
        if not _is(path, inode):
            return                    # removed, or another process took the name
        try:
            conn, _ = listener.accept()
        except TimeoutError:
            continue
        with conn:
            creds = conn.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED,
                                    struct.calcsize("3i"))
            pid, uid, _gid = struct.unpack("3i", creds)
            if uid != os.geteuid():
                continue
            child = os.fork()
            if child == 0:
                listener.close()
                os.close(lock_fd)
                sys.exit(_child(conn, run))
            children[child] = (process_start(child), pid, process_start(pid))
        deadline = time.monotonic() + keep_s


def _mind(children: dict[int, tuple[str | None, int, str | None]]) -> None:
    """Forget the children that ended; continue those whose command is gone. A command killed
    while Ctrl-Z had it stopped (``kill -9 %1``) leaves its child stopped, where nothing of the
    child can see that: continued, it sees the command's socket closed and ends."""
    for child, (born, pid, started) in list(children.items()):
        if born is None or process_start(child) != born:   # ended (reaped: SIGCHLD ignored)
            del children[child]
            continue
        if started is None or process_start(pid) != started:
            try:
                os.kill(child, signal.SIGCONT)
            except OSError:
                pass


def _is(path: Path, inode: int) -> bool:
    """Whether *path* is still the socket with *inode* (ours)."""
    try:
        st = os.lstat(path)
    except OSError:
        return False
    return stat.S_ISSOCK(st.st_mode) and st.st_ino == inode


def _child(conn: socket.socket, run: Runner) -> int:
    """In the forked child: become the command's process, run it, say its exit code."""
    global in_child
    in_child = True
    for sig in (signal.SIGTERM, signal.SIGHUP, signal.SIGCHLD):
        signal.signal(sig, signal.SIG_DFL)
    conn.settimeout(_ANSWER_S)
    try:
        request, fds = _receive(conn)
        conn.sendall(b"P%d\n" % os.getpid())
    except (OSError, ValueError):
        return 2                    # the command runs itself
    conn.settimeout(None)
    done: list[bool] = []
    _watch(conn, done)
    try:
        code = _run_as(request, fds, run)
    except KeyboardInterrupt:       # Ctrl-C before the command's own handling began
        print("interrupted", file=sys.stderr)
        code = 130
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except OSError:
            pass
    done.append(True)
    try:
        conn.sendall(b"E%d\n" % code)
    except OSError:
        pass
    # The command's pipes see their end now, not after this interpreter's own.
    null = os.open(os.devnull, os.O_RDWR)
    for fd in (0, 1, 2):
        os.dup2(null, fd)
    os.close(null)
    gc.freeze()
    return code


def _run_as(request: Request, fds: list[int], run: Runner) -> int:
    """Take on the command's stdin, stdout, stderr, directory, umask, environment and arguments,
    and run it."""
    for target, fd in zip((0, 1, 2), fds, strict=True):
        os.dup2(fd, target)
    for fd in fds:
        if fd > 2:
            os.close(fd)
    for stream in (sys.stdout, sys.stderr):
        stream.reconfigure(line_buffering=stream.isatty())
    try:
        os.chdir(request.cwd)
    except OSError as exc:
        print(f"rosnet-tui: cannot work in {request.cwd}: {exc.strerror}", file=sys.stderr)
        return 2
    os.umask(request.umask)
    os.environ.clear()
    os.environ.update(request.env)
    sys.argv = [request.argv0, *request.argv]
    try:
        return run(list(request.argv))
    except SystemExit as exc:     # argparse's refusals, as in a cold run
        if exc.code is None or isinstance(exc.code, int):
            return exc.code or 0
        print(exc.code, file=sys.stderr)
        return 1


def _receive(conn: socket.socket) -> tuple[Request, list[int]]:
    """The request on *conn* and the three file descriptors it came with (ValueError: none)."""
    head, fds, _flags, _addr = socket.recv_fds(conn, _LEN.size, 3)
    try:
        if len(head) != _LEN.size or len(fds) != 3:
            raise ValueError("a request without its length or its three file descriptors")
        (size,) = _LEN.unpack(head)
        if size > _MAX_REQUEST:
            raise ValueError("a request too long")
        data = b""
        while len(data) < size:
            chunk = conn.recv(size - len(data))
            if not chunk:
                raise ValueError("a request cut short")
            data += chunk
        request = Request.decode(data)
        if request is None:
            raise ValueError("not a request of rosnet-tui's")
    except (OSError, ValueError):
        for fd in fds:
            os.close(fd)
        raise
    return request, fds


def _watch(conn: socket.socket, done: list[bool]) -> None:
    """The command's end of the socket closing before the command is *done* (it was killed)
    ends this child too."""
    def watch() -> None:
        try:
            while conn.recv(64):
                pass
        except OSError:
            pass
        if not done:
            os.kill(os.getpid(), signal.SIGTERM)
    threading.Thread(target=watch, name="warm-watch", daemon=True).start()


def main(argv: list[str], run: Runner, preload: Callable[[], None]) -> int:
    """The warm process's own command line: SOCKET KEEP_S."""
    if len(argv) != 2:
        print("usage: serve_warm SOCKET KEEP_S (started by rosnet-tui check)", file=sys.stderr)
        return 2
    try:
        keep_s = float(argv[1])
    except ValueError:
        print(f"rosnet-tui warm: not a number of seconds: {argv[1]!r}", file=sys.stderr)
        return 2
    return serve(Path(argv[0]), keep_s, run, preload)
