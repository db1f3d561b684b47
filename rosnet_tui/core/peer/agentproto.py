"""The round's peer agent: one program per peer and round that runs every probe the checks ask of
that peer, so the peer starts one interpreter per round instead of one per check.

Stdlib only and a single file, like the probe programs it serves (``core/peer/rosproto.py``,
``core/peer/zenohproto.py``): the master feeds it over SSH on stdin (:data:`BOOT` reads it: a line
with its length, then the source compressed by zlib), then speaks JSON lines on the same channel:

- master -> agent: ``{"load": NAME, "src": SOURCE, "entry": FUNCTION or null, "base": NAME
  (optional)}`` (a probe program, compiled and run once here as a module: its imports are then
  warm; with "base", on a copy of that program's names, as zenohlink on zenohproto's), ``{"run": NAME,
  "id": N, "argv": [...], "ni": [TEXT, STATUS] (optional)}`` (start it; with "ni", when the agent
  was started as the fallback for a peer without rosnet-tui installed (``no-install`` after its
  life bound), the run needs the install: TEXT is its output and STATUS its exit status, as the
  install finder's own report), ``{"kill": N}`` (stop it), ``{"loadz": LENGTH}`` (LENGTH bytes
  follow: requests as JSON lines compressed by zlib, the programs' loads at the start: on a
  64 kbit/s line the agent's start then carries about 20 kB instead of 58);
- agent -> master: ``{"ready": 1}`` once, then per run ``{"id": N, "o": TEXT}`` (its stdout),
  ``{"id": N, "e": TEXT}`` (its stderr), ``{"id": N, "x": STATUS}`` (it ended). Every line ends
  with ``#<its number>`` so the master can wait for the next whole line.

Each run is a child process forked from the agent (no new interpreter: the fork shares the
loaded programs), with its own stdout and stderr, running ``FUNCTION(argv)`` (or the program as
``__main__`` with ``sys.argv``); runs are concurrent. Every probe bounds itself; the agent also
kills a run when asked, every run when its stdin ends (the master closed the channel: sshd does
not kill a command without a terminal), and everything after its hard maximum (``argv[1]``
seconds). Python 3.8+ syntax, no imports from rosnet_tui.
"""
# ruff: noqa: UP006, UP035

from __future__ import annotations

import codecs
import json
import os
import select
import signal
import sys
import threading
import warnings
import zlib

BOOT = ("import sys,zlib;i=sys.stdin.buffer;"
        "exec(compile(zlib.decompress(i.read(int(i.readline()))),'rosnet-tui-agent','exec'))")
"""What ``python -c`` runs on the peer: the agent's source (zlib) arrives on stdin after its
length."""
LOADZ_MAX = 1 << 20     # bytes a "loadz" frame may hold (compressed), and 8 times that unpacked
READY = "ready"
MAX_S = 600.0     # the hard maximum when none is given


class Agent:
    def __init__(self, out, max_s: float, no_install: bool = False) -> None:
        self.out = out
        self.no_install = no_install
        self.lock = threading.Lock()
        self.seq = 0
        self.programs = {}   # name -> (code, namespace, entry)
        self.children = {}   # run id -> pid
        self.max_s = max_s

    def send(self, obj) -> None:
        with self.lock:
            self.seq += 1
            data = (json.dumps(obj) + f"#{self.seq}\n").encode()
            try:
                self.out.write(data)
                self.out.flush()
            except OSError:
                pass

    def load(self, name: str, src: str, entry, base=None) -> None:
        code = compile(src, name, "exec")
        ns = dict(self.programs[base][1]) if base in self.programs else {}
        ns["__name__"] = "rosnet_agent_" + name
        if entry:
            exec(code, ns)   # the module's imports and definitions, once for every run
        self.programs[name] = (code, ns, entry)

    def run(self, rid, name: str, argv, needs_install=None) -> None:
        if self.no_install and needs_install:
            self.send({"id": rid, "o": str(needs_install[0])})
            self.send({"id": rid, "x": int(needs_install[1])})
            return
        if name not in self.programs:
            self.send({"id": rid, "e": f"no program {name!r} loaded\n"})
            self.send({"id": rid, "x": 2})
            return
        ro, wo = os.pipe()
        re_, we = os.pipe()
        pid = os.fork()
        if pid == 0:
            self._child(name, list(argv), wo, we, (ro, re_))
        os.close(wo)
        os.close(we)
        self.children[rid] = pid
        threading.Thread(target=self._relay, args=(rid, pid, ro, re_), daemon=True).start()

    def _child(self, name, argv, wo, we, others) -> None:
        code = 1
        try:
            for fd in others:
                os.close(fd)
            null = os.open(os.devnull, os.O_RDONLY)
            os.dup2(null, 0)
            os.dup2(wo, 1)
            os.dup2(we, 2)
            for fd in (null, wo, we):
                os.close(fd)
            sys.stdin = open(0, closefd=False)
            sys.stdout = open(1, "w", encoding="utf-8", errors="replace", closefd=False)
            sys.stderr = open(2, "w", encoding="utf-8", errors="replace", closefd=False)
            signal.signal(signal.SIGALRM, signal.SIG_DFL)
            signal.alarm(int(self.max_s) + 1)   # bounded even if the agent is killed
            prog, ns, entry = self.programs[name]
            if entry:
                code = ns[entry](argv)
            else:
                sys.argv = ["-", *argv]
                exec(prog, {"__name__": "__main__"})
                code = 0
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
        except BaseException:  # noqa: BLE001 - the run's stderr says what happened
            import traceback

            traceback.print_exc()
            code = 1
        finally:
            for stream in (sys.stdout, sys.stderr):
                try:
                    stream.flush()
                except Exception:  # noqa: BLE001, S110
                    pass
            os._exit(code if isinstance(code, int) else 0)

    def _relay(self, rid, pid: int, ro: int, re_: int) -> None:
        decoders = {ro: codecs.getincrementaldecoder("utf-8")("replace"),
                    re_: codecs.getincrementaldecoder("utf-8")("replace")}
        keys = {ro: "o", re_: "e"}
        open_fds = [ro, re_]
        while open_fds:
            ready, _, _ = select.select(open_fds, [], [])
            for fd in ready:
                data = os.read(fd, 65536)
                if not data:
                    open_fds.remove(fd)
                    os.close(fd)
                text = decoders[fd].decode(data, final=not data)
                if text:
                    self.send({"id": rid, keys[fd]: text})
        _, status = os.waitpid(pid, 0)
        self.children.pop(rid, None)
        code = (os.WEXITSTATUS(status) if os.WIFEXITED(status)
                else 128 + os.WTERMSIG(status) if os.WIFSIGNALED(status) else 1)
        self.send({"id": rid, "x": code})

    def kill(self, rid) -> None:
        pid = self.children.get(rid)
        if pid is not None:
            try:
                os.kill(pid, signal.SIGKILL)
            except OSError:
                pass

    def end(self) -> None:
        for rid in list(self.children):
            self.kill(rid)
        os._exit(0)

    def serve(self, inp) -> None:
        timer = threading.Timer(self.max_s, self.end)
        timer.daemon = True
        timer.start()
        self.send({READY: 1, "pid": os.getpid()})
        for line in iter(inp.readline, b""):
            self.handle(line, inp)
        self.end()

    def handle(self, line: bytes, inp=None) -> None:
        """One request line (*inp*: where a "loadz" frame's bytes follow; None inside one)."""
        try:
            msg = json.loads(line)
        except (ValueError, RecursionError):     # not a request of ours: said, skipped
            msg = None
        if not isinstance(msg, dict) or not ({"load", "run", "kill", "loadz"} & set(msg)):
            self.send({"id": None, "e": "agent: a line that is not a request\n"})
            return
        try:
            if "loadz" in msg and inp is not None:
                n = int(msg["loadz"])
                if not 0 < n <= LOADZ_MAX:
                    raise ValueError(f"a loadz frame of {n} bytes")
                unz = zlib.decompressobj()
                text = unz.decompress(inp.read(n), 8 * LOADZ_MAX)
                if unz.unconsumed_tail:
                    raise ValueError("a loadz frame too large unpacked")
                for inner in text.splitlines():
                    self.handle(inner)
            elif "load" in msg:
                self.load(msg["load"], msg["src"], msg.get("entry"), msg.get("base"))
            elif "run" in msg:
                self.run(msg.get("id"), msg["run"], msg.get("argv") or [], msg.get("ni"))
            elif "kill" in msg:
                self.kill(msg["kill"])
        except Exception as exc:  # noqa: BLE001 - a bad request is said, the agent goes on
            rid = msg.get("id")
            self.send({"id": rid, "e": f"agent: {type(exc).__name__}: {exc}\n"})
            if rid is not None and "run" in msg:
                self.send({"id": rid, "x": 2})


def main() -> None:
    warnings.simplefilter("ignore", DeprecationWarning)   # fork() in a threaded process: ours
    try:
        max_s = float(sys.argv[1]) if len(sys.argv) > 1 else MAX_S
    except ValueError:
        max_s = MAX_S
    no_install = sys.argv[2:3] == ["no-install"]
    Agent(sys.stdout.buffer, max(1.0, min(max_s, 3600.0)), no_install).serve(sys.stdin.buffer)


if __name__ == "__main__":
    main()
