"""Step 3, Linux: hosts file, names resolve, ping, SSH and a TCP chat by name, both ways.

The peer's side runs over SSH (:mod:`rosnet_tui.core.ssh`) as small stdlib-only ``python3``
programs (nothing to install on the peer), with ``nc`` as the fallback when there is no python3.
"""

from __future__ import annotations

import asyncio
import contextlib
import re
import secrets
import shutil
import socket
import time
from collections.abc import Awaitable, Callable
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from rosnet_tui.core.checks import CheckContext, check
from rosnet_tui.core.checks.probes import (
    budget,
    chat_ros2,
    each_peer,
    python_command,
    shq,
    ssh_peers,
)
from rosnet_tui.core.connect import kind_from_text, tcp_failure_kind
from rosnet_tui.core.hosts import HostsEntry, hosts_entries
from rosnet_tui.core.listener import ECHO, GREETING
from rosnet_tui.core.managed_text import ManagedFileError
from rosnet_tui.core.managed_write import read_text
from rosnet_tui.core.procedure import is_ip, is_loopback
from rosnet_tui.core.results import Outcome, Status
from rosnet_tui.core.settings import Peer
from rosnet_tui.core.ssh.connection import SshResult, resolve_ipv4
from rosnet_tui.core.ssh.session import ssh_run, ssh_session


def _is_loopback_ip(ip: str) -> bool:
    """A loopback IP address (names such as localhost do not count: hosts files hold addresses)."""
    return is_ip(ip) and is_loopback(ip)


def _plural(n: int, word: str) -> str:
    return f"{n} {word}{'' if n == 1 else 's'}"


# --------------------------------------------------------------------------- linux.hosts
def parse_hosts(text: str) -> list[tuple[int, str, list[str]]]:
    """(line number, address, names) for every entry of a hosts file."""
    out = []
    for n, line in enumerate(text.splitlines(), 1):
        fields = line.split("#", 1)[0].split()
        if len(fields) >= 2:
            out.append((n, fields[0], fields[1:]))
    return out


def audit_hosts(text: str, expected: list[HostsEntry]) -> dict[str, Any]:
    """Compare a hosts file's text with the entries this component needs (see linux.hosts data)."""
    entries = parse_hosts(text)
    missing: list[str] = []
    wrong: list[dict[str, str]] = []
    duplicates: list[str] = []
    loopback: list[str] = []
    lines: dict[str, list[tuple[int, str]]] = {}
    for e in expected:
        found = [(n, ip) for n, ip, names in entries
                 if e.name.lower() in (x.lower() for x in names) and ":" not in ip]
        lines[e.name] = found
        if not found:
            missing.append(e.name)
            continue
        distinct = list(dict.fromkeys(ip for _, ip in found))
        if len(distinct) > 1:
            # The resolver may return any of them (glibc even sorts 127.0.1.1 first).
            duplicates.append(e.name)
        if any(_is_loopback_ip(ip) for ip in distinct) and not _is_loopback_ip(e.ip):
            loopback.append(e.name)
        other = next((ip for ip in distinct if ip != e.ip and not _is_loopback_ip(ip)), None)
        if other is not None:
            wrong.append({"name": e.name, "found": other, "expected": e.ip})
    return {"missing": missing, "wrong": wrong, "duplicates": duplicates, "loopback": loopback,
            "lines": {k: [f"line {n}: {ip}" for n, ip in v] for k, v in lines.items()}}


@check("linux.hosts", "linux", "The hosts file maps every name to the right address", 1.0)
async def check_hosts(ctx: CheckContext) -> Outcome:
    expected = hosts_entries(ctx.settings)
    path = Path(ctx.hosts_path)
    base: dict[str, Any] = {"missing": [], "wrong": [], "duplicates": [], "loopback": []}
    if not expected:
        return Outcome(Status.SKIP, "no names with known addresses in the settings yet", data=base)
    try:
        # Through the managed-file reader: a write of ours cut short is completed first.
        text = read_text(path, state_dir=ctx.state_dir, errors="replace",
                         wait_s=ctx.timeout_s / 2)
        why = f"cannot read {path}: No such file or directory"
    except ManagedFileError as exc:   # its message names the file and why
        text, why = None, str(exc)
    if text is None:
        base["missing"] = [e.name for e in expected]
        return Outcome(Status.FAIL, why, data=base)
    audit = audit_hosts(text, expected)
    evidence = [f"expected {e.ip} {e.name} ({e.why}); {path} has: "
                + (", ".join(audit["lines"][e.name]) or "nothing") for e in expected]
    data = {k: audit[k] for k in base}
    problems = []
    if audit["missing"]:
        problems.append("missing: " + ", ".join(audit["missing"]))
    if audit["wrong"]:
        problems.append("wrong address: " + ", ".join(
            f"{w['name']} -> {w['found']} (should be {w['expected']})" for w in audit["wrong"]))
    if audit["loopback"]:
        problems.append("on a loopback address: " + ", ".join(audit["loopback"])
                        + " (ROS would advertise 127.x, which no peer can reach)")
    if audit["duplicates"]:
        problems.append(", ".join(audit["duplicates"]) + " on several lines with different "
                        "addresses (the resolver may pick any)")
    if problems:
        return Outcome(Status.FAIL, f"{path}: " + "; ".join(problems), evidence, data)
    return Outcome(Status.PASS, f"{path} has all {_plural(len(expected), 'name')} right",
                   evidence, data)


# --------------------------------------------------------------------------- linux.resolve
_DATED_BY = {"settings": "the settings file saved", "sync": "its own sync record"}


def _iso(ts: float) -> str:
    return datetime.fromtimestamp(ts, tz=timezone.utc).replace(microsecond=0).isoformat()


def address_dates(ctx: CheckContext, expected: list[HostsEntry]) -> dict[str, list[dict[str, Any]]]:
    """For each peer in *expected*: what says when its address was last confirmed, newest first
    (see linux.resolve's ``dated``): the time the settings file holding it was saved, and the
    peer's own address record that sync applied here (remote profile: its public IP)."""
    s, now = ctx.settings, time.time()
    records: dict[str, Any] = {}
    if s.this.profile == "remote":
        try:
            from rosnet_tui.core.sync.applied import load_applied  # lazy: the sync package is big

            records = load_applied(ctx.state_dir)
        except Exception:   # dating is a bonus: never let it cost the verdict
            records = {}
    out: dict[str, list[dict[str, Any]]] = {}
    for e in expected:
        if e.name.lower() == s.this.name.lower():
            continue
        rows = []
        if s.saved_at is not None:
            rows.append((e.ip, "settings", s.saved_at))
        rec = records.get(e.name.lower())
        if rec is not None and rec.public_ip:
            rows.append((rec.public_ip, "sync", rec.timestamp))
        out[e.name] = [{"ip": ip, "by": by, "at": _iso(ts), "age_s": round(max(now - ts, 0.0), 1)}
                       for ip, by, ts in sorted(rows, key=lambda r: -r[2])]
    return out


@check("linux.resolve", "linux", "Each name resolves to the expected address", 1.0)
async def check_resolve(ctx: CheckContext) -> Outcome:
    expected = hosts_entries(ctx.settings)
    data: dict[str, Any] = {"names": {}, "wrong": [], "loopback": []}
    if not expected:
        return Outcome(Status.SKIP, "no names with known addresses in the settings yet", data=data)
    t = budget(ctx, "linux.resolve") * 0.8
    got, dated = await asyncio.gather(asyncio.gather(*(resolve_ipv4(e.name, t) for e in expected)),
                                      asyncio.to_thread(address_dates, ctx, expected))
    evidence = []
    for e, (addrs, err) in zip(expected, got, strict=True):
        resolved = addrs[0] if addrs else None
        data["names"][e.name] = {"resolved": resolved, "expected": e.ip}
        if e.name in dated:
            data["names"][e.name]["dated"] = dated[e.name]
            evidence += [f"{e.name}: {d['ip']} per {_DATED_BY[d['by']]} of {d['at']}"
                         for d in dated[e.name]]
        if resolved is None:
            data["wrong"].append(e.name)
            evidence.append(f"{e.name}: {err} (expected {e.ip})")
            continue
        evidence.append(f"{e.name} -> {', '.join(addrs)} (expected {e.ip})")
        if _is_loopback_ip(resolved) and not _is_loopback_ip(e.ip):
            data["loopback"].append(e.name)
        elif resolved != e.ip:
            data["wrong"].append(e.name)
    bad = [n for n in data["wrong"]] + data["loopback"]
    if not bad:
        return Outcome(Status.PASS, "every name resolves as expected ("
                       + ", ".join(f"{e.name} -> {e.ip}" for e in expected) + ")", evidence, data)
    parts = []
    for n in data["wrong"]:
        r = data["names"][n]
        parts.append(f"{n} -> {r['resolved']} (expected {r['expected']})" if r["resolved"]
                     else f"{n} does not resolve")
    for n in data["loopback"]:
        parts.append(f"{n} -> {data['names'][n]['resolved']} (loopback)")
    return Outcome(Status.FAIL, "; ".join(parts), evidence, data)


# --------------------------------------------------------------------------- linux.ping
async def _run_proc(argv: list[str], timeout: float) -> tuple[int | None, str]:
    """Run *argv*; (exit code or None on timeout, combined output). The process is always reaped."""
    proc = await asyncio.create_subprocess_exec(*argv, stdin=asyncio.subprocess.DEVNULL,
                                                stdout=asyncio.subprocess.PIPE,
                                                stderr=asyncio.subprocess.STDOUT)
    try:
        out, _ = await asyncio.wait_for(proc.communicate(), timeout)
        return proc.returncode, out.decode(errors="replace")
    except asyncio.TimeoutError:
        return None, ""
    finally:
        if proc.returncode is None:
            with contextlib.suppress(ProcessLookupError):
                proc.kill()
            with contextlib.suppress(Exception):
                await asyncio.wait_for(proc.wait(), 1.0)


async def ping_name(name: str, timeout: float) -> tuple[bool | None, str]:
    """ICMP echo to *name* with the system ``ping`` (unprivileged where the kernel allows it)."""
    exe = shutil.which("ping")
    if exe is None:
        return None, "no ping command here"
    deadline = max(int(timeout), 1)
    code, out = await _run_proc([exe, "-c", "1", "-i", "0.2", "-w", str(deadline), name],
                                timeout + 0.5)
    first = out.strip().splitlines()[0] if out.strip() else ""
    m = re.search(r"PING \S+ \(([\d.]+)\)", out)
    target = f"{name} ({m.group(1)})" if m else name
    if code == 0:
        rtt = re.search(r"time[=<]([\d.]+) ?ms", out)
        return True, f"ping {target}: reply" + (f" in {rtt.group(1)} ms" if rtt else "")
    if code == 1:
        return False, f"ping {target}: no reply within {deadline} s"
    if code is None:
        return False, f"ping {target}: no reply within {timeout:.1f} s"
    last = out.strip().splitlines()[-1] if out.strip() else first
    return None, f"ping {name}: {last or f'exit status {code}'}"


async def tcp_connect(host: str, port: int, timeout: float) -> tuple[str, str]:
    """(kind, what was seen) of a TCP connection to *host*:*port*; kind as in core.connect."""
    writer = None
    try:
        _r, writer = await asyncio.wait_for(asyncio.open_connection(host, port), timeout)
        peer = writer.get_extra_info("peername")
        return "connected", f"TCP {host}:{port} ({peer[0] if peer else '?'}): connected"
    except asyncio.TimeoutError:
        return "timeout", f"TCP {host}:{port}: no answer within {timeout:.1f} s (dropped)"
    except OSError as exc:
        kind = tcp_failure_kind(exc)
        if isinstance(exc, socket.gaierror):
            kind = "resolve"
        return kind, f"TCP {host}:{port}: {exc.strerror or exc}" + (
            " (something there answers and rejects the port)" if kind == "refused" else "")
    finally:
        if writer is not None:
            writer.close()
            with contextlib.suppress(Exception):
                await asyncio.wait_for(writer.wait_closed(), 0.5)


@check("linux.ping", "linux", "Peers answer ping by name", 1.0)
async def check_ping(ctx: CheckContext) -> Outcome:
    peers = ctx.settings.peers
    data: dict[str, Any] = {"peers": {}}
    if not peers:
        return Outcome(Status.SKIP, "no peers in the settings", data=data)
    t = budget(ctx, "linux.ping") * 0.8

    async def one(p: Peer) -> tuple[bool | None, str, list[str]]:
        (icmp, line), (kind, tline) = await asyncio.gather(
            ping_name(p.name, t), tcp_connect(p.name, p.ssh_port or 22, min(t, ctx.timeout_s)))
        return icmp, kind, [line, tline]

    got = await each_peer(peers, one)
    evidence: list[str] = []
    ok: list[str] = []
    tcp_only: list[str] = []
    down: list[str] = []
    for p, (icmp, kind, lines) in zip(peers, got, strict=True):
        tcp = kind == "connected"
        data["peers"][p.name] = {"icmp": icmp, "tcp22": tcp, "tcp": kind,
                                 "port": p.ssh_port or 22}
        evidence.extend(lines)
        (ok if icmp else tcp_only if tcp else down).append(p.name)
    if down:
        return Outcome(Status.FAIL, f"no answer from {', '.join(down)} (neither ping nor TCP "
                                    f"{'/'.join(sorted({str(p.ssh_port or 22) for p in peers}))})",
                       evidence, data)
    if tcp_only:
        return Outcome(Status.WARN, f"{', '.join(tcp_only)} did not answer ping but accepted TCP on "
                                    "the SSH port: ICMP is filtered on the way, which is harmless",
                       evidence, data)
    return Outcome(Status.PASS, f"{', '.join(ok)} answer{'s' if len(ok) == 1 else ''} ping by name",
                   evidence, data)


# --------------------------------------------------------------------------- linux.ssh
_NO_SSH = ("no peer has an SSH user in the settings (peer.ssh_user), so the peer's side cannot "
           "be run from here")


@check("linux.ssh", "linux", "SSH to each peer by name (host key verified)", 2.0)
async def check_ssh(ctx: CheckContext) -> Outcome:
    data: dict[str, Any] = {"peers": {}}
    for p in ctx.settings.peers:
        if not p.ssh_user:
            data["peers"][p.name] = {"ok": False, "failure": "no_user", "fingerprint": None}
    peers = ssh_peers(ctx.settings)
    if not peers:
        return Outcome(Status.SKIP, _NO_SSH, data=data)
    t = budget(ctx, "linux.ssh") * 0.85
    # The TCP connection is bounded by the round's timeout: an unreachable peer is told by then.
    results = await each_peer(peers, lambda p: ssh_run(ctx.ssh, p,
                                                        "echo rosnet-tui-ssh-ok; hostname",
                                                        timeout=t, tcp_timeout=ctx.timeout_s))
    evidence: list[str] = []
    good: list[str] = []
    bad: list[tuple[str, str | None]] = []
    for p, r in zip(peers, results, strict=True):
        ran = r.ok and "rosnet-tui-ssh-ok" in r.stdout
        failure = r.failure if not ran else None
        if r.ok and not ran:
            failure = "sshd"
        data["peers"][p.name] = {"ok": ran, "failure": failure, "fingerprint": r.fingerprint,
                                 "host_key": r.host_key, "address": r.address,
                                 "detail": r.detail, "tcp": r.tcp, "port": p.ssh_port or 22}
        where = f"{p.ssh_user}@{p.name}" + (f":{p.ssh_port}" if p.ssh_port != 22 else "")
        if ran:
            host = r.stdout.replace("rosnet-tui-ssh-ok", "").strip()
            evidence.append(f"ssh {where} ({r.address}): ok, host key {r.fingerprint}, "
                            f"remote hostname {host!r}")
            good.append(p.name)
        else:
            evidence.append(f"ssh {where}: {failure}: {r.detail}"
                            + (f" [{r.stderr.strip()[:120]}]" if r.stderr.strip() else ""))
            bad.append((p.name, f"refused:{p.ssh_port or 22}" if r.tcp == "refused"
                        else failure))
    if bad:
        words = {"network": "not reachable", "resolve": "name does not resolve",
                 "host_key_unknown": "host key not yet trusted (compare the fingerprint)",
                 "host_key_changed": "HOST KEY CHANGED, refused", "auth": "key login refused",
                 "sshd": "sshd problem", "timeout": "timed out"}
        for _, f in bad:
            if f and f.startswith("refused:"):
                words[f] = (f"port {f[8:]} refused: sshd does not listen there (it may listen "
                            "on another port: ssh_port under its [[peer]]), or its modem "
                            f"rejects {f[8:]}")
        return Outcome(Status.FAIL, "; ".join(f"{n}: {words.get(f or '', f)}" for n, f in bad),
                       evidence, data)
    return Outcome(Status.PASS, f"SSH works to {', '.join(good)} (host key verified, key login)",
                   evidence, data)


# --------------------------------------------------------------------------- chats
CHAT = "ROSNET-TUI CHAT"
PYTHON = "python3"  # what the peer's side runs with; without it, nc does the job

_LISTEN_SCRIPT = r"""
import random, socket, sys
port = int(sys.argv[1]); token = sys.argv[2]; wait = float(sys.argv[3])
srv = None; last = ""
for p in [port] + [random.randint(20000, 60000) for _ in range(5)]:
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        s.bind(("0.0.0.0", p)); s.listen(4); srv = s; port = p; break
    except Exception as e:
        last = str(e); s.close()
if srv is None:
    print("ERROR cannot listen: " + last); sys.exit(3)
print("LISTENING %d" % port); sys.stdout.flush()
srv.settimeout(wait)
try:
    c, a = srv.accept()
except socket.timeout:
    print("TIMEOUT nobody connected"); sys.exit(4)
c.settimeout(3)
try:
    c.sendall(("ROSNET-TUI CHAT %s\n" % token).encode())
    data = b""
    while b"\n" not in data and len(data) < 512:
        chunk = c.recv(512)
        if not chunk:
            break
        data += chunk
    print("FROM %s" % a[0])
    print("GOT " + data.decode("utf-8", "replace").strip())
except Exception as e:
    print("ERROR " + str(e)); sys.exit(5)
finally:
    c.close(); srv.close()
"""

_CONNECT_SCRIPT = r"""
import socket, sys
name = sys.argv[1]; port = int(sys.argv[2]); token = sys.argv[3]; t = float(sys.argv[4])
try:
    ip = socket.gethostbyname(name)
except Exception as e:
    print("RESOLVE-ERROR %s" % e); sys.exit(2)
print("RESOLVED %s" % ip); sys.stdout.flush()
try:
    c = socket.create_connection((ip, port), timeout=t)
except Exception as e:
    print("CONNECT-ERROR %s" % e); sys.exit(3)
c.settimeout(t)
def line():
    b = b""
    while b"\n" not in b and len(b) < 512:
        x = c.recv(512)
        if not x:
            break
        b += x
    return b.decode("utf-8", "replace").strip()
try:
    print("HELLO " + line()); sys.stdout.flush()
    c.sendall(("ROSNET-TUI CHAT %s\n" % token).encode())
    print("ECHO " + line())
except Exception as e:
    print("ERROR %s" % e); sys.exit(4)
finally:
    c.close()
"""


_IS_OPENBSD_NC = "nc -h 2>&1 | grep -q OpenBSD"


def listen_command(port: int, token: str, wait: float) -> str:
    """Peer side of chat_out: python3 when present, else ``nc -l`` (OpenBSD or traditional)."""
    py = python_command(_LISTEN_SCRIPT, str(port), token, f"{wait:.1f}", python=PYTHON)
    w = max(int(wait + 0.999), 1)
    msg = shq(f"{CHAT} {token}")
    nc = (f"echo LISTENING {port}; echo NC; if {_IS_OPENBSD_NC}; then "
          f"echo {msg} | timeout {w} nc -N -l {port}; else "
          f"echo {msg} | timeout {w} nc -l -p {port}; fi")
    return f"if command -v {PYTHON} >/dev/null 2>&1; then {py}; else {nc}; fi"


def connect_command(name: str, port: int, token: str, t: float) -> str:
    """Peer side of chat_in: connect to *name* as the peer resolves it."""
    py = python_command(_CONNECT_SCRIPT, name, str(port), token, f"{t:.1f}", python=PYTHON)
    w = max(int(t + 0.999), 1)
    msg = shq(f"{CHAT} {token}")
    nc = (f"echo NC; echo RESOLVED $(getent ahostsv4 {shq(name)} | head -n1 | cut -d' ' -f1); "
          f"if {_IS_OPENBSD_NC}; then echo {msg} | timeout {w} nc -N {shq(name)} {port}; "
          f"else echo {msg} | timeout {w} nc {shq(name)} {port}; fi")
    return f"if command -v {PYTHON} >/dev/null 2>&1; then {py}; else {nc}; fi"


async def _chat_per_peer(ctx: CheckContext, check_id: str,
                         one: Callable[[Peer, float], Awaitable[tuple[bool, str | None, list[str]]]],
                         what: str, kinds: dict[str, str] | None = None) -> Outcome:
    data: dict[str, Any] = {"peers": {}}
    peers = ssh_peers(ctx.settings)
    for p in ctx.settings.peers:
        if not p.ssh_user:
            data["peers"][p.name] = {"ok": False, "failure": "no_user"}
    if not peers:
        return Outcome(Status.SKIP, _NO_SSH, data=data)
    t = budget(ctx, check_id) * 0.9
    got = await each_peer(peers, lambda p: one(p, t))
    evidence: list[str] = []
    good: list[str] = []
    bad: list[str] = []
    for p, (ok, failure, lines) in zip(peers, got, strict=True):
        data["peers"][p.name] = {"ok": ok, "failure": failure}
        if kinds and p.name in kinds:
            data["peers"][p.name]["tcp"] = kinds[p.name]
        evidence.extend(lines)
        (good if ok else bad).append(f"{p.name}" if ok else f"{p.name} ({failure})")
    if bad:
        return Outcome(Status.FAIL, f"{what} failed: {', '.join(bad)}", evidence, data)
    return Outcome(Status.PASS, f"{what} works: {', '.join(good)}", evidence, data)


def _ssh_failure(res: SshResult, peer: Peer) -> tuple[bool, str, list[str]]:
    return False, f"ssh:{res.failure}", [f"could not run the peer's side on {peer.name} over SSH "
                                         f"({res.failure}): {res.detail}"]


@check("linux.chat_out", "linux", "Chat by name: we connect to the peer", 3.0)
async def check_chat_out(ctx: CheckContext) -> Outcome:
    if ctx.settings.ros2:  # ROS 2 over rmw_zenoh: only the way to the master's router matters
        return await chat_ros2(ctx, out=True)
    me = ctx.settings.this.name or "this component"
    kinds: dict[str, str] = {}      # how our TCP connection to each peer's listener went

    async def one(peer: Peer, total: float) -> tuple[bool, str | None, list[str]]:
        start = time.monotonic()

        def left() -> float:
            return max(total - (time.monotonic() - start), 0.2)

        peer_token = secrets.token_hex(6)
        my_token = secrets.token_hex(6)
        port = ctx.settings.probe.port
        ev: list[str] = []
        async with ssh_session(ctx.ssh, peer, listen_command(port, peer_token, total * 0.6),
                               timeout=total * 0.45, tcp_timeout=ctx.timeout_s) as sess:
            if not sess.ok:
                return _ssh_failure(sess.result, peer)
            out = await sess.read_until("LISTENING", left() * 0.6)
            if out is None:
                res = await sess.wait(0.3)
                text = (res.stdout + res.stderr).strip().splitlines()
                return False, "peer_listen", [f"{peer.name} did not start listening: "
                                              f"{text[-1] if text else 'no output'}"]
            m = re.search(r"LISTENING (\d+)", out)
            rport = int(m.group(1)) if m else port
            use_nc = "\nNC" in out or out.startswith("NC")
            ev.append(f"{peer.name} listens on TCP {rport} (over SSH, "
                      f"{'nc' if use_nc else 'python3'})")
            addrs, err = await resolve_ipv4(peer.name, min(left() * 0.3, 2.0))
            if not addrs:
                return False, "resolve", ev + [f"{peer.name} does not resolve here: {err}"]
            reader = writer = None
            connect_err = ""
            for _ in range(8 if use_nc else 1):
                try:
                    reader, writer = await asyncio.wait_for(
                        asyncio.open_connection(addrs[0], rport),
                        min(left() * 0.5, ctx.timeout_s))
                    kinds[peer.name] = "connected"
                    break
                except (OSError, asyncio.TimeoutError) as exc:
                    kinds[peer.name] = tcp_failure_kind(exc)
                    connect_err = str(exc) or "no answer (timed out)"
                    if not use_nc:
                        break
                    await asyncio.sleep(0.15)
            if writer is None:
                await sess.wait(0.2)
                return False, "connect", ev + [
                    f"connect {peer.name} ({addrs[0]}):{rport}: {connect_err}: the peer listens, "
                    f"but its modem does not let the connection in (port forwarding on "
                    f"{peer.name}'s side), or the name points to the wrong address"]
            assert reader is not None
            try:
                hello = await asyncio.wait_for(reader.readline(), left() * 0.5)
                writer.write(f"{CHAT} hello from {me} {my_token}\n".encode())
                await asyncio.wait_for(writer.drain(), left() * 0.5)
            except (OSError, asyncio.TimeoutError) as exc:
                hello = b""
                ev.append(f"exchange with {peer.name}: {exc or 'timed out'}")
            finally:
                writer.close()
                with contextlib.suppress(Exception):
                    await asyncio.wait_for(writer.wait_closed(), 0.5)
            hello_text = hello.decode(errors="replace").strip()
            ev.append(f"connect {peer.name} ({addrs[0]}):{rport}: connected, read {hello_text!r}")
            res = await sess.wait(left())
        got_line = next((ln for ln in res.stdout.splitlines() if my_token in ln), None)
        src = next((ln[5:] for ln in res.stdout.splitlines() if ln.startswith("FROM ")), None)
        if peer_token not in hello_text:
            return False, "wrong_peer", ev + [f"the answer did not come from our listener on "
                                              f"{peer.name}: the name or the forwarding leads "
                                              "to another machine"]
        if got_line is None:
            return False, "no_message", ev + [f"{peer.name} did not receive our message "
                                              f"(its output: {res.stdout.strip()[-120:]!r})"]
        ev.append(f"{peer.name} received {got_line.removeprefix('GOT ')!r}"
                  + (f" from {src}" if src else ""))
        return True, None, ev

    return await _chat_per_peer(ctx, "linux.chat_out", one, f"chat from {me} to the peer", kinds)


@check("linux.chat_in", "linux", "Chat by name: the peer connects to us", 3.0)
async def check_chat_in(ctx: CheckContext) -> Outcome:
    if ctx.settings.ros2:  # ROS 2 over rmw_zenoh: only the way to the master's router matters
        return await chat_ros2(ctx, out=False)
    me = ctx.settings.this.name
    if not me:
        return Outcome(Status.SKIP, "this component has no name in the settings yet",
                       data={"peers": {}})
    kinds: dict[str, str] = {}      # how the peer's TCP connection to our listener went

    async def one(peer: Peer, total: float) -> tuple[bool, str | None, list[str]]:
        start = time.monotonic()
        token = secrets.token_hex(6)
        ev: list[str] = []
        port = ctx.settings.probe.port
        async with contextlib.AsyncExitStack() as stack:
            try:
                lst = await stack.enter_async_context(ctx.listeners.hold(port))
            except OSError as exc:
                return False, "local_listen", [f"cannot listen on our test port {port}: "
                                               f"{exc.strerror or exc} (see router.port_free)"]
            ev.append(f"we listen on TCP {port}")
            left = max(total - (time.monotonic() - start), 0.5)
            res = await ssh_run(ctx.ssh, peer,
                                connect_command(me, port, token, min(left * 0.45, ctx.timeout_s)),
                                timeout=left * 0.95, connect_timeout=left * 0.45,
                                tcp_timeout=ctx.timeout_s)
            if not res.ok and res.failure != "timeout" and not res.stdout:
                return _ssh_failure(res, peer)
            seen = await lst.wait_for_line(token, 0.3)
        out = res.stdout
        resolved = next((ln[9:] for ln in out.splitlines() if ln.startswith("RESOLVED ")), None)
        hello = next((ln[6:] for ln in out.splitlines() if ln.startswith("HELLO ")), None)
        if hello is None:
            hello = next((ln for ln in out.splitlines() if ln.startswith(GREETING)), None)
        for ln in out.splitlines():
            if ln.startswith(("RESOLVE-ERROR", "CONNECT-ERROR", "ERROR")):
                ev.append(f"on {peer.name}: {ln}")
            if ln.startswith("CONNECT-ERROR"):
                kinds[peer.name] = kind_from_text(ln)
            elif ln.startswith("HELLO ") or ln.startswith(GREETING):
                kinds[peer.name] = "connected"
        if resolved is not None and not resolved.strip():
            resolved = None
        if resolved is None:
            return False, "peer_resolve", ev + [f"{peer.name} cannot resolve {me}: add it to "
                                                f"{peer.name}'s hosts file"]
        ev.append(f"{peer.name} resolves {me} -> {resolved}")
        if hello is None:
            return False, "connect", ev + [
                f"{peer.name} could not connect to {me} ({resolved}):{port}: our modem does not "
                f"forward the port to us, or {peer.name}'s hosts entry for {me} is stale"]
        if ctx.listeners.token not in hello:
            return False, "wrong_peer", ev + [f"{peer.name} reached something else on "
                                              f"{resolved}:{port} ({hello[:60]!r}), not our listener"]
        if seen is None:
            return False, "no_message", ev + [f"{peer.name} connected but its message did not "
                                              "arrive here"]
        echo = next((ln[5:] for ln in out.splitlines() if ln.startswith("ECHO ")), "")
        ev.append(f"we received {seen.line!r} from {seen.address}"
                  + (f"; {peer.name} got our reply" if ECHO in echo else ""))
        return True, None, ev

    return await _chat_per_peer(ctx, "linux.chat_in", one, f"chat from the peer to {me}", kinds)
