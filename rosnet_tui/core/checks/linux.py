"""Step 3, Linux: hosts file, names resolve, ping, SSH (the chats by name: :mod:`.linux_chat`).

The peer's side runs over SSH (:mod:`rosnet_tui.core.ssh`) as small stdlib-only ``python3``
programs (nothing to install on the peer), with ``nc`` as the fallback when there is no python3.
"""

from __future__ import annotations

import asyncio
import contextlib
import re
import shutil
import socket
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from rosnet_tui.core.addresses import is_loopback_ip
from rosnet_tui.core.checks import CheckContext, check
from rosnet_tui.core.checks.probes.budget import budget
from rosnet_tui.core.checks.probes.peers import NO_SSH_USER, each_peer, ssh_peers
from rosnet_tui.core.config.settings_model import Peer
from rosnet_tui.core.files.hosts import HostsEntry, hosts_entries, parse_hosts
from rosnet_tui.core.files.managed_text import ManagedFileError
from rosnet_tui.core.files.managed_write import read_text
from rosnet_tui.core.net.connect import close_writer, tcp_failure_kind
from rosnet_tui.core.results import Outcome, Status
from rosnet_tui.core.saved.sync_applied import load_applied
from rosnet_tui.core.ssh.connection import resolve_ipv4
from rosnet_tui.core.ssh.session import ssh_run


def _plural(n: int, word: str) -> str:
    return f"{n} {word}{'' if n == 1 else 's'}"


# --------------------------------------------------------------------------- linux.hosts
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
        if any(is_loopback_ip(ip) for ip in distinct) and not is_loopback_ip(e.ip):
            loopback.append(e.name)
        other = next((ip for ip in distinct if ip != e.ip and not is_loopback_ip(ip)), None)
        if other is not None:
            wrong.append({"name": e.name, "found": other, "expected": e.ip})
    return {"missing": missing, "wrong": wrong, "duplicates": duplicates, "loopback": loopback,
            "lines": {k: [f"line {n}: {ip}" for n, ip in v] for k, v in lines.items()}}


@check("linux.hosts", "linux", "The hosts file maps every name to the right address", 1.0)
async def check_hosts(ctx: CheckContext) -> Outcome:
    expected = hosts_entries(ctx.settings)
    path = Path(ctx.paths.hosts_path)
    base: dict[str, Any] = {"missing": [], "wrong": [], "duplicates": [], "loopback": []}
    if not expected:
        return Outcome(Status.SKIP, "no names with known addresses in the settings yet", data=base)
    try:
        # Through the managed-file reader: a write of ours cut short is completed first.
        text = read_text(path, state_dir=ctx.paths.state_dir, errors="replace",
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
            records = load_applied(ctx.paths.state_dir)
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
        if is_loopback_ip(resolved) and not is_loopback_ip(e.ip):
            data["loopback"].append(e.name)
        elif resolved != e.ip:
            data["wrong"].append(e.name)
    if ctx.settings.has_sync:
        data["unpinned"] = [p.name for p in ctx.settings.peers if not p.sync_key]
        evidence += [f"{n}: sync cannot follow it here (no sync key pinned: `rosnet-tui sync "
                     "pin`)" for n in data["unpinned"]]
    bad = [n for n in data["wrong"]] + data["loopback"]
    if not bad:
        return Outcome(Status.PASS, "every name resolves as expected ("
                       + ", ".join(f"{e.name} -> {e.ip}" for e in expected) + ")", evidence, data)
    parts = []
    for n in data["wrong"]:
        r = data["names"][n]
        parts.append((f"{n} -> {r['resolved']} (expected {r['expected']})" if r["resolved"]
                      else f"{n} does not resolve")
                     + (" (sync cannot follow it: no sync key pinned; `rosnet-tui sync pin`)"
                        if n in data.get("unpinned", ()) else ""))
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
    """(kind, what was seen) of a TCP connection to *host*:*port*; kind as in core.net.connect."""
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
            await close_writer(writer)


@check("linux.ping", "linux", "Peers answer ping by name", 1.0)
async def check_ping(ctx: CheckContext) -> Outcome:
    route = ctx.ssh.relay
    relayed = [p.name for p in ctx.settings.peers if route and route.tunnel_port(p.name)]
    peers = [p for p in ctx.settings.peers if p.name not in relayed]
    data: dict[str, Any] = {"peers": {}}
    if relayed and route is not None:
        why = (f"{', '.join(relayed)} {'is' if len(relayed) == 1 else 'are'} reached through the "
               f"relay {route.host} (linux.ssh tests that way): no direct path is needed")
        if not peers:
            return Outcome(Status.SKIP, why, data=data)
    if not peers:
        return Outcome(Status.SKIP, "no peers in the settings", data=data)
    t = budget(ctx, "linux.ping") * 0.8

    async def one(p: Peer) -> tuple[bool | None, str, list[str]]:
        (icmp, line), (kind, tline) = await asyncio.gather(
            ping_name(p.name, t), tcp_connect(p.name, p.ssh_port or 22, min(t, ctx.timeout_s)))
        return icmp, kind, [line, tline]

    got = await each_peer(peers, one)
    evidence: list[str] = [why] if relayed else []
    ok: list[str] = []
    tcp_only: list[str] = []
    down: list[str] = []
    unresolved: list[str] = []
    for p, (icmp, kind, lines) in zip(peers, got, strict=True):
        tcp = kind == "connected"
        data["peers"][p.name] = {"icmp": icmp, "tcp22": tcp, "tcp": kind,
                                 "port": p.ssh_port or 22}
        evidence.extend(lines)
        (ok if icmp else tcp_only if tcp else unresolved if kind == "resolve"
         else down).append(p.name)
    if down or unresolved:
        parts = ([f"{', '.join(unresolved)} {'does' if len(unresolved) == 1 else 'do'} not "
                  "resolve (no address for the name: see linux.hosts)"] if unresolved else [])
        if down:
            ports = "/".join(sorted({str(p.ssh_port or 22) for p in peers}))
            parts.append(f"no answer from {', '.join(down)} (neither ping nor TCP {ports})")
        return Outcome(Status.FAIL, "; ".join(parts), evidence, data)
    if tcp_only:
        return Outcome(Status.WARN, f"{', '.join(tcp_only)} did not answer ping but accepted TCP on "
                                    "the SSH port: ICMP is filtered on the way, which is harmless",
                       evidence, data)
    return Outcome(Status.PASS, f"{', '.join(ok)} answer{'s' if len(ok) == 1 else ''} ping by name",
                   evidence, data)


# --------------------------------------------------------------------------- linux.ssh


@check("linux.ssh", "linux", "SSH to each peer by name (host key verified)", 2.0)
async def check_ssh(ctx: CheckContext) -> Outcome:
    data: dict[str, Any] = {"peers": {}}
    for p in ctx.settings.peers:
        if not p.ssh_user:
            data["peers"][p.name] = {"ok": False, "failure": "no_user", "fingerprint": None}
    peers = ssh_peers(ctx.settings)
    if not peers:
        return Outcome(Status.SKIP, NO_SSH_USER, data=data)
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
            route = ctx.ssh.relay
            how = (f"through the relay {route.host}" if route and route.tunnel_port(p.name)
                   else r.address)
            evidence.append(f"ssh {where} ({how}): ok, host key {r.fingerprint}, "
                            f"remote hostname {host!r}")
            good.append(p.name)
        else:
            evidence.append(f"ssh {where}: {failure}: {r.detail}"
                            + (f" [{r.stderr.strip()[:120]}]" if r.stderr.strip() else ""))
            relayed = ctx.ssh.relay is not None and ctx.ssh.relay.tunnel_port(p.name)
            bad.append((p.name, ("tunnel_down" if failure == "network" else failure) if relayed
                        else f"refused:{p.ssh_port or 22}" if r.tcp == "refused" else failure))
    if bad:
        words = {"network": "not reachable", "resolve": "name does not resolve",
                 "host_key_unknown": "host key not yet trusted (compare the fingerprint)",
                 "host_key_changed": "HOST KEY CHANGED, refused", "auth": "key login refused",
                 "sshd": "sshd problem", "timeout": "timed out",
                 "relay": "the relay turned us away", "tunnel_down": "its tunnel on the relay is down"}
        for _, f in bad:
            if f and f.startswith("refused:"):
                words[f] = (f"port {f[8:]} refused: sshd does not listen there (it may listen "
                            "on another port: ssh_port under its [[peer]]), or its modem "
                            f"rejects {f[8:]}")
        return Outcome(Status.FAIL, "; ".join(f"{n}: {words.get(f or '', f)}" for n, f in bad),
                       evidence, data)
    return Outcome(Status.PASS, f"SSH works to {', '.join(good)} (host key verified, key login)",
                   evidence, data)
