"""security.*: what a stranger on the internet gets from this component (issue 22).

- ``security.ssh_auth`` (Linux step): a peer asks this component's sshd, at its public address
  and without logging in, which authentication methods it offers (``auth_none``); password or
  keyboard-interactive is a finding with the fix, and so is a password offered to root. When no
  peer reaches anything there (refused, dropped, no route: a modem that forwards nothing, the
  normal ROS 2 member), nothing is offered to strangers: a pass, unless this machine's own sshd
  offers a password (a warning: one forward, or a ban of that peer alone, would expose it).
- ``security.outsider`` (ROS step): ROS 2: from a seat that is not the master (a member; the
  master runs it on a member over SSH), a TLS probe at the master's Zenoh port with no client
  certificate, with a foreign one and (read from the same answer) in plain TCP must all be
  refused, and the seat's fleet certificate must get in. ROS 1: the configured echoip-style
  port checker (not a peer) must find the master's port and a port of the range closed, and a
  peer must still connect to both, at the public IP the internet sees (isp.public_ip's, or the
  settings' when none is measured).
The programs and their reading are in core/exposure/outsider.py.
"""

from __future__ import annotations

import asyncio
import contextlib
import getpass
import os
import sys
import tempfile
from typing import Any

import rosnet_tui
from rosnet_tui.core.checks import CheckContext, check
from rosnet_tui.core.checks.probes.agents import (
    ZENOH_AGENT,
    chat_agent,
    peer_program_problem,
    peer_run,
    why_no_report,
)
from rosnet_tui.core.checks.probes.budget import budget
from rosnet_tui.core.checks.probes.peers import each_peer, ssh_peers
from rosnet_tui.core.checks.probes.public_ip import fetch_public_ip
from rosnet_tui.core.config.settings_model import Peer, Settings
from rosnet_tui.core.exposure import outsider
from rosnet_tui.core.jsonsafe import loads_bounded
from rosnet_tui.core.net.blocking import run_blocking
from rosnet_tui.core.net.connect import close_writer
from rosnet_tui.core.net.http import http_get
from rosnet_tui.core.peer.commands import installed_python_command
from rosnet_tui.core.results import Outcome, Status
from rosnet_tui.core.ssh.session import ssh_run

SSH_PORT = 22


async def _public_ip(ctx: CheckContext, timeout: float) -> tuple[str | None, list[str]]:
    """This component's public IP with what to say about it: the address the internet sees
    (this round's isp.public_ip, or one quick ask of a what-is-my-IP service), else the one in
    the settings (the set-up screen asks for none); None: neither."""
    s = ctx.settings
    seen = await fetch_public_ip(ctx, timeout)
    if seen and s.this.public_ip and seen != s.this.public_ip:
        return seen, [f"the internet sees {seen}; the settings say {s.this.public_ip}"]
    return seen or s.this.public_ip or None, []


def _offers_password(methods: list[str]) -> list[str]:
    return [m for m in methods if m in outsider.PASSWORD_METHODS or m == "none"]


async def _audit_here(users: list[str], timeout: float) -> tuple[outsider.SshAudit | None, str]:
    """What the sshd of this machine offers (the audit program run here against loopback):
    (the audit, why none)."""
    out, err = await run_here(outsider.SSH_AUDIT_PROGRAM.encode(),
                               ["127.0.0.1", str(SSH_PORT), f"{min(1.0, timeout / 3):.1f}",
                                *users], timeout)
    rep = outsider.parse_marked(out, outsider.SSH_MARK)
    if rep is None or rep.get("error"):
        return None, err or str((rep or {}).get("error") or "no report")
    return outsider.read_ssh_audit(rep, users[0]), ""


_NOT_REACHED_WORDS = {"refused": "the connection was refused",
                      "timeout": "no answer (dropped by a modem or firewall)",
                      "unreachable": "no route (an ICMP error came back)"}


# --------------------------------------------------------------------------- security.ssh_auth
@check("security.ssh_auth", "linux", "SSH offers the internet no password (seen from a peer)",
       2.0)
async def check_ssh_auth(ctx: CheckContext) -> Outcome:
    s = ctx.settings
    user = getpass.getuser()
    data: dict[str, Any] = {"target": s.this.name, "port": SSH_PORT, "user": user}
    peers = ssh_peers(s)
    if not peers:
        return Outcome(Status.SKIP, "skipped: no peer has an SSH user in the settings "
                                    "(peer.ssh_user), so nobody outside can look at our sshd",
                       [], data)
    t = budget(ctx, "security.ssh_auth")
    loop = asyncio.get_running_loop()
    end = loop.time() + t * 0.95

    def left() -> float:
        return max(end - loop.time(), 0.2)

    ev: list[str] = []
    target = s.this.name     # a LAN profile: the name (nothing comes from the internet)
    if s.this.profile == "remote":  # where a stranger comes from: the address the internet sees
        ip, ev = await _public_ip(ctx, min(t * 0.2, 2.0))
        target = ip or target
    data["target"] = target
    if not target:
        return Outcome(Status.SKIP, "skipped: no public IP is known (isp.public_ip found none, "
                                    "the settings give none) and this component has no name "
                                    "to test", ev, data)
    users = [user] if user == "root" else [user, "root"]
    rem = left()
    cmd = installed_python_command(target, str(SSH_PORT), f"{rem * 0.3:.1f}", *users,
                                   mark=outsider.SSH_MARK)
    try:    # bounded by our end as well: on a thin, busy link SSH can outlast its own bounds
        got = await asyncio.wait_for(each_peer(peers[:2], lambda p: ssh_run(
            ctx.ssh, p, cmd, stdin=outsider.SSH_AUDIT_PROGRAM, timeout=rem * 0.85,
            connect_timeout=min(t * 0.4, rem * 0.45), tcp_timeout=ctx.timeout_s)),
            max(0.1, end - loop.time()))
    except asyncio.TimeoutError:
        data["from"] = ""
        return Outcome(Status.WARN, f"no peer could run the SSH audit within the check's {t:g} s "
                                    "(SSH to the peers too slow: a slow or busy link?)",
                       ev + [f"the audit on {', '.join(p.name for p in peers[:2])} gave no "
                             f"report by the end of the check's {t:g} s"], data)
    audits: list[tuple[Peer, outsider.SshAudit, dict[str, Any]]] = []
    problems: list[str] = []
    for p, res in zip(peers[:2], got, strict=True):
        if res.failure:
            data.setdefault("ssh_failures", {})[p.name] = res.failure
        rep = outsider.parse_marked(res.stdout, outsider.SSH_MARK)
        if rep is None or rep.get("error"):
            problems.append(peer_program_problem(res, p) or (
                f"rosnet-tui is not installed on {p.name} (the audit needs its paramiko)"
                if rep and rep.get("error") == "no_install" else
                f"the audit on {p.name} gave no report ({why_no_report(res)})"))
            continue
        audits.append((p, outsider.read_ssh_audit(rep, user), rep))
    ev += problems
    # A peer that read the methods has the say; then one that reached something it could not
    # read; only when every peer that looked reached nothing is sshd out of the internet's reach.
    read = [x for x in audits if x[1].methods]
    unread = [x for x in audits if not x[1].methods and not x[1].not_reached]
    if read:
        return _judge_methods(s, target, user, *read[0], ev, data)
    if unread:
        p, audit, _rep = unread[0]
        data.update({"from": p.name, "tcp": audit.tcp or "error",
                     "error": audit.error or "no methods"})
        if audit.tcp == "connected":    # something answers there: reachable, but not read
            data["reachable"] = True
        return Outcome(Status.FAIL, f"{p.name} could not read what sshd at {target}:"
                                    f"{SSH_PORT} offers: {audit.error or 'no methods'}",
                       ev, data)
    if audits:
        return await _judge_not_reached(s, target, users, audits, ev, data, left())
    data["from"] = ""     # not a finding about sshd: the audit could not run (linux.ssh says why)
    return Outcome(Status.WARN, "no peer could run the SSH audit: " + "; ".join(problems), ev,
                   data)


def _judge_methods(s: Settings, target: str, user: str, p: Peer, audit: outsider.SshAudit,
                   rep: dict[str, Any], ev: list[str], data: dict[str, Any]) -> Outcome:
    """The verdict when *p* read what sshd at *target* offers (it is reachable)."""
    data.update({"from": p.name, "reachable": True, "tcp": "connected",
                 "methods": audit.methods, "root_methods": audit.root_methods,
                 "password": audit.password,
                 "keyboard_interactive": audit.keyboard_interactive,
                 "root_password": audit.root_password})
    ev.append(f"{p.name} -> {target}:{SSH_PORT} ({rep.get('banner') or 'sshd'}): "
              f"auth_none({user}) offers {', '.join(audit.methods) or 'nothing'}; "
              f"auth_none(root) offers {', '.join(audit.root_methods) or 'nothing'}")
    bad = _offers_password(audit.methods)
    if bad:
        return Outcome(Status.FAIL, f"sshd at {target}:{SSH_PORT} offers the internet "
                                    f"{' and '.join(bad)}: anyone can try passwords",
                       ev + outsider.ssh_fix(s.this.name or target, user), data)
    if audit.root_password:
        return Outcome(Status.FAIL, f"sshd at {target}:{SSH_PORT} offers root a password "
                                    "(methods offered for the user root)",
                       ev + outsider.ssh_fix(s.this.name or target, user), data)
    return Outcome(Status.PASS, f"sshd at {target}:{SSH_PORT} offers only "
                                f"{', '.join(audit.methods) or 'nothing'} (no password, "
                                "also not to root)", ev, data)


async def _judge_not_reached(s: Settings, target: str, users: list[str],
                             audits: list[tuple[Peer, outsider.SshAudit, dict[str, Any]]],
                             ev: list[str], data: dict[str, Any], timeout: float) -> Outcome:
    """The verdict when no peer reached anything at *target*:22 (refused, dropped, no route):
    nothing there is offered to strangers. Port 22 is optional in every role (core/exposure/forwarding.py:
    peers that SSH here are told by their own linux.ssh). A peer alone may be shut out (a ban)
    while strangers are not, so this machine's own sshd is asked too: if it offers a password,
    a warning with the fix."""
    for p, audit, _rep in audits:
        ev.append(f"{p.name} -> {target}:{SSH_PORT}: {_NOT_REACHED_WORDS[str(audit.tcp)]}"
                  + (f" ({audit.tcp_error})" if audit.tcp_error else ""))
    p, audit, _rep = audits[0]
    data.update({"from": p.name, "reachable": False, "tcp": audit.tcp})
    where = f"sshd at {target}:{SSH_PORT} is not reachable from the internet"
    seen = f"{p.name}: {_NOT_REACHED_WORDS[str(audit.tcp)].split(' (')[0]}"
    here, why = await _audit_here(users, timeout)
    if here is None:
        ev.append(f"what sshd here offers was not read ({why})")
    elif here.not_reached:
        ev.append(f"no sshd answers on this machine's port {SSH_PORT} either")
    else:
        data.update({"local_methods": here.methods, "local_root_methods": here.root_methods})
        ev.append(f"sshd here (127.0.0.1:{SSH_PORT}): auth_none({users[0]}) offers "
                  f"{', '.join(here.methods) or 'nothing'}; auth_none(root) offers "
                  f"{', '.join(here.root_methods) or 'nothing'}")
        bad = _offers_password(here.methods) or (
            ["a password to root"] if here.root_password else [])
        if bad:
            return Outcome(Status.WARN, f"{where} ({seen}), but sshd here offers "
                                        f"{' and '.join(bad)}: forwarding port {SSH_PORT} (or a "
                                        f"firewall that shuts out {p.name} alone) would let "
                                        "anyone try passwords",
                           ev + outsider.ssh_fix(s.this.name or target, users[0]), data)
    return Outcome(Status.PASS, f"{where} ({seen}): it offers strangers nothing", ev, data)


# --------------------------------------------------------------------------- security.outsider
@check("security.outsider", "ros", "An outsider is refused; the fleet still gets in", 3.0)
async def check_outsider(ctx: CheckContext) -> Outcome:
    s = ctx.settings
    data: dict[str, Any] = {"security": s.ros.security, "ros": s.ros.version}
    if s.ros.version == 2:
        return await _outsider_ros2(ctx, data)
    return await _outsider_ros1(ctx, data)


def _package_parent() -> str:
    """The folder holding the rosnet_tui package this run imports (a checkout or site-packages)."""
    return os.path.dirname(os.path.dirname(os.path.abspath(rosnet_tui.__file__)))


async def run_here(program: bytes, args: list[str], timeout: float) -> tuple[str, str]:
    """Run a probe program here (stdin), as a peer would: (stdout, why not).

    Isolated (``python -I``: no PYTHON* variables, no user site, not the caller's folder on the
    path) and from a private folder of its own, so nothing planted where the caller stands
    (an ``ssl.py``) runs; it finds this run's rosnet_tui by the path put first in it."""
    # The program is compiled on its own (its `from __future__` lines stay first in it), after
    # this run's rosnet_tui is put first on the path.
    boot = (f"import sys; sys.path.insert(0, {_package_parent()!r}); "
            "exec(compile(sys.stdin.read(), '<probe>', 'exec', dont_inherit=True), "
            "{'__name__': '__main__'})")
    with tempfile.TemporaryDirectory(prefix="rosnet-probe-") as private:
        os.chmod(private, 0o700)
        proc = await asyncio.create_subprocess_exec(
            sys.executable, "-I", "-c", boot, *args, stdin=asyncio.subprocess.PIPE,
            stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE, cwd=private)
        try:
            out, err = await asyncio.wait_for(proc.communicate(program), timeout)
        except asyncio.TimeoutError:
            return "", f"the probe gave no verdict within {timeout:.1f} s"
        finally:     # timed out, or the check itself was stopped: the program goes with it
            if proc.returncode is None:
                with contextlib.suppress(ProcessLookupError):
                    proc.kill()
                await proc.wait()
    return out.decode(errors="replace"), err.decode(errors="replace").strip()[-200:]


def _hub(s: Settings) -> tuple[str, int]:
    """The router the internet can reach: the relay's under a relay, else the master's."""
    return (s.relay.host, s.relay.zenoh_port) if s.relayed else (s.master_name, s.ros.zenoh_port)


async def _outsider_ros2(ctx: CheckContext, data: dict[str, Any]) -> Outcome:
    s = ctx.settings
    master, port = _hub(s)
    t = budget(ctx, "security.outsider")
    data["target"] = f"{master}:{port}"
    args = [master, str(port), f"{min(2.0, t * 0.2):.1f}"]
    # in a thread: the foreign certificate is made here (cryptography's keys and signatures)
    program = await run_blocking(outsider.tls_probe_program, timeout=max(t * 0.5, 1.0))
    if s.is_master and not s.relayed:   # under a relay, the relay is outside every component
        members = [p for p in ssh_peers(s) if p.name != master]
        if not members:
            return Outcome(Status.SKIP, "skipped: no member has an SSH user in the settings, so "
                                        "the master cannot be tested from outside it", [], data)
        peer = members[0]
        data["from"] = peer.name
        # on the member's agent of the round (its rosnet-tui's interpreter, or python3 without
        # one: the probe needs only the standard library), not an interpreter of its own
        res = await peer_run(ctx, peer, ZENOH_AGENT, "outsider_tls", args, timeout=t * 0.9,
                             connect_timeout=t * 0.4, tcp_timeout=ctx.timeout_s, source=program)
        rep = outsider.parse_marked(res.stdout, outsider.TLS_MARK)
        problem = None if rep is not None else (peer_program_problem(res, peer) or
                                                f"no report ({why_no_report(res)})")
        if res.failure:
            data["ssh_failures"] = {peer.name: res.failure}
        if rep is None and res.failure:   # no way to look from outside: unknown, not insecure
            return Outcome(Status.WARN, f"not judged from outside: {problem}", [], data)
    else:
        data["from"] = "here"
        out, err = await run_here(program, args, t * 0.9)
        rep = outsider.parse_marked(out, outsider.TLS_MARK)
        problem = None if rep is not None else f"the probe gave no report ({err or 'no output'})"
    if rep is None:
        return Outcome(Status.FAIL, f"the TLS probe did not run: {problem}", [], data)
    return ros2_verdict(s, rep, data)


_ATTEMPT_WORDS = {"no_cert": "without a certificate", "foreign": "with a foreign CA's "
                  "certificate", "plain": "in plain TCP", "insider": "with the fleet certificate"}


def ros2_verdict(s: Settings, rep: dict[str, Any], data: dict[str, Any]) -> Outcome:
    """The verdict on the TLS probe's report *rep* (any shape: a peer's output)."""
    master, port = _hub(s)
    no_cert = outsider.as_dict(rep.get("no_cert"))
    attempts = {"no_cert": no_cert, "foreign": outsider.as_dict(rep.get("foreign")),
                "plain": outsider.plain_attempt(no_cert, outsider.as_dict(rep.get("plain"))),
                "insider": outsider.as_dict(rep.get("insider"))}
    ev = [f"{data.get('from')}: {_ATTEMPT_WORDS[k]} -> {a.get('result')}"
          + (f" ({a.get('detail')})" if a.get("detail") else "") for k, a in attempts.items()]
    data["attempts"] = {k: {"result": str(a.get("result") or "none"),
                            "detail": str(a.get("detail") or "")} for k, a in attempts.items()}
    let_in = [k for k in ("no_cert", "foreign", "plain") if not outsider.refused(attempts[k])
              and not outsider.no_verdict(attempts[k])]
    cert_b64 = next((a.get("server_cert") for a in attempts.values() if a.get("server_cert")), "")
    facts = outsider.cert_facts(cert_b64) if cert_b64 else None
    if facts is not None:
        data["master_cert"] = {"names": facts.names, "not_after": facts.not_after,
                               "expired": facts.expired}
        ev.append(f"{master}'s certificate names {', '.join(facts.names) or 'nothing'}; "
                  f"valid until {facts.not_after}")
    if no_cert.get("result") == "closed" and attempts["insider"].get("result") != "accepted":
        data["cause"] = "unreachable"
        return Outcome(Status.FAIL, f"nothing answers at {master}:{port} from "
                                    f"{data.get('from')} (see ros2.router): nothing to judge",
                       ev, data)
    insider_cause = outsider.insider_cause(attempts["insider"])
    if facts is not None and master not in facts.names and insider_cause in (None, "refused"):
        insider_cause = "wrong_name"
    if let_in:
        mode = s.ros.security
        data["cause"] = ("security_off" if mode == "none" else
                         "plain_open" if "plain" in let_in else "no_mtls")
        words = ", ".join(_ATTEMPT_WORDS[k] for k in let_in)
        return Outcome(Status.FAIL, f"an outsider gets a Zenoh session at {master}:{port} "
                                    f"({words})", ev, data)
    late = [k for k in ("no_cert", "foreign", "plain") if outsider.no_verdict(attempts[k])]
    if late:    # no answer in time to these: not judged (a slow or busy link), not insecure
        data["cause"] = "no_verdict"
        words = ", ".join(_ATTEMPT_WORDS[k] for k in late)
        return Outcome(Status.WARN, f"not judged from {data.get('from')}: {master}:{port} gave "
                                    f"no answer in time to a session {words} (a slow or busy "
                                    "link, see ros2.link); check again when it is quieter, or "
                                    "raise [checks] timeout_s", ev, data)
    if insider_cause:
        data["cause"] = insider_cause
        return Outcome(Status.FAIL, f"outsiders are refused at {master}:{port}, but so is the "
                                    f"fleet certificate from {data.get('from')} "
                                    f"({insider_cause.replace('_', ' ')})", ev, data)
    data["cause"] = None
    return Outcome(Status.PASS, f"{master}:{port} refuses a session without a certificate, with "
                                "a foreign one and in plain TCP; the fleet certificate gets in",
                   ev, data)


async def _listens_here(port: int) -> bool:
    """Whether something accepts TCP on *port* here (loopback)."""
    try:
        _r, w = await asyncio.wait_for(asyncio.open_connection("127.0.0.1", port), 0.5)
    except (OSError, asyncio.TimeoutError):
        return False
    await close_writer(w)
    return True


_CONNECT = r"""
import socket, sys
ip = sys.argv[1]; t = float(sys.argv[2])
for p in sys.argv[3:]:
    try:
        socket.create_connection((ip, int(p)), timeout=t).close(); print("OPEN %s" % p)
    except Exception as e:
        print("SHUT %s %s" % (p, e))
"""


async def _outsider_ros1(ctx: CheckContext, data: dict[str, Any]) -> Outcome:
    s = ctx.settings
    if s.this.profile != "remote":
        return Outcome(Status.SKIP, "skipped: on a LAN profile nothing is forwarded from the "
                                    "internet", [], data)
    peers = ssh_peers(s)
    if not peers:
        return Outcome(Status.SKIP, "skipped: no peer has an SSH user, so no outsider/insider "
                                    "pair can be made", [], data)
    t = budget(ctx, "security.outsider")
    loop = asyncio.get_running_loop()
    end = loop.time() + t * 0.95

    def left() -> float:
        return max(end - loop.time(), 0.2)

    # The port checker tests the address that asks it: the insider tries the same one.
    target, ev = await _public_ip(ctx, min(t * 0.15, 2.0))
    data["target"] = target or ""
    if not target:
        return Outcome(Status.SKIP, "skipped: this component's public IP is unknown (no "
                                    "what-is-my-IP service answered, see isp.public_ip, and the "
                                    "settings give none), so no outsider/insider pair can be "
                                    "made", ev, data)
    ports: list[int] = []
    if s.is_master:     # the master's port is judged only when something listens there
        if await _listens_here(s.ros.port):
            ports.append(s.ros.port)
        else:
            ev.append(f"nothing listens on {s.ros.port} here (see ros.master): not judged")
    base = s.probe.port_check_url.rstrip("/")
    async with contextlib.AsyncExitStack() as stack:
        try:
            spare = await stack.enter_async_context(ctx.listeners.hold_spare(
                {s.ros.port, s.probe.port, SSH_PORT}))
        except OSError as exc:
            return Outcome(Status.FAIL, f"cannot listen on a spare port of the range for the "
                                        f"test: {exc.strerror or exc}", ev, data)
        ports.append(spare.port)
        data["ports"] = ports
        rem = left()
        peer = peers[0]
        asked = loop.time()
        answered: dict[int, float] = {}

        async def ask_checker(p: int) -> Any:
            ans = await http_get(f"{base}/port/{p}", min(t * 0.4, rem * 0.45))
            answered[p] = round(loop.time() - asked, 3)
            return ans
        res, *outs = await asyncio.gather(
            peer_run(ctx, peer, chat_agent(ctx), "outsider_connect",   # on the round's agent
                     [target, f"{rem * 0.25:.2f}", *map(str, ports)], timeout=rem * 0.85,
                     connect_timeout=min(t * 0.4, rem * 0.45), tcp_timeout=ctx.timeout_s,
                     source=_CONNECT.encode()),
            *(ask_checker(p) for p in ports))
    data["from"] = peer.name
    # How long each of the checker's verdicts took: a refusal (the peers-only firewall resets a
    # stranger) comes in round trips; a drop costs the checker's own connect timeout.
    data["outsider_s"] = {str(p): answered.get(p) for p in ports}
    outside: dict[str, Any] = {}
    for p, ans in zip(ports, outs, strict=True):
        reach = None
        if ans.ok:
            with contextlib.suppress(ValueError, AttributeError):
                reach = loads_bounded(ans.text, unique_keys=False).get("reachable")
        outside[str(p)] = reach if isinstance(reach, bool) else None
        ev.append(f"outsider {base}: port {p} -> "
                  + ({True: "reachable", False: "closed"}.get(reach, ans.describe())))
    inside = {str(p): f"OPEN {p}" in res.stdout for p in ports}
    ev.append(f"insider {peer.name} -> {target}: " + ", ".join(
        f"{p} {'open' if ok else 'closed'}" for p, ok in inside.items()))
    data["outsider_reachable"] = outside
    data["insider_reachable"] = inside
    if not res.ok:
        ev.append(f"SSH to {peer.name} failed ({res.failure}): {res.detail}")
        if res.failure:
            data["ssh_failures"] = {peer.name: res.failure}
    if any(v is None for v in outside.values()):
        data["cause"] = "checker_unavailable"
        return Outcome(Status.FAIL, f"the port checker ({base}) gave no verdict: the outsider's "
                                    "view is unknown", ev, data)
    if any(outside.values()):
        data["cause"] = "security_off" if s.ros.security == "none" else "firewall_missing"
        open_ = [p for p, v in outside.items() if v]
        return Outcome(Status.FAIL, f"an outsider ({base}) reaches port "
                                    f"{', '.join(open_)} of {target}", ev, data)
    if res.failure:     # the insider never tried: its view is unknown, not blocked
        return Outcome(Status.WARN, f"outsiders are refused; whether {peer.name} gets in is "
                                    f"not known: SSH to it failed ({res.failure})", ev, data)
    if not all(inside.values()):
        data["cause"] = "insider_blocked"
        return Outcome(Status.FAIL, f"outsiders are refused, but {peer.name} cannot connect "
                                    "either", ev, data)
    data["cause"] = None
    return Outcome(Status.PASS, f"{target} refuses an outsider on {', '.join(map(str, ports))}; "
                                f"{peer.name} gets through", ev, data)
