"""Pairing a component with the fleet CA (ROS 2, [ros] security = "mtls").

On the master, :func:`prepare_master` makes the CA (once) and the master's own certificate. On a
member, :func:`pair_over_ssh` makes the member's key and request here, has the master sign the
request over the SSH the checks already use (host keys verified as for every check), and
installs the CA certificate and the member's certificate: one SSH round trip.

The master's side is the master's own ``rosnet-tui ros pair --serve NAME`` (:func:`serve`), run
by the interpreter of the rosnet-tui installed there (found by the prelude the Zenoh peer program
uses, ``peer.commands.installed_python_command``), the request on stdin. It reads the master's
own settings: the master's name, the members it signs for. A member whose operators get no shell
on the master pairs through a forced command in the master's ``authorized_keys``
(``ros pair --admit NAME``, :mod:`.pair_access`) that runs only that: sshd ignores what the
member asks for. (The master re-pairing its members still feeds ``fleet_tls.py`` on stdin to
each member: ``request`` and ``install``, code of the master's own.)
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rosnet_tui.core.config.paths import default_config_dir
from rosnet_tui.core.config.settings_model import Settings
from rosnet_tui.core.jsonsafe import JsonInputError, loads_bounded
from rosnet_tui.core.peer.commands import installed_python_command, zenoh_peer_command
from rosnet_tui.core.ros import fleet_tls
from rosnet_tui.core.ros.fleet_tls import TlsError, TlsPaths
from rosnet_tui.core.ros.ros2 import mtls
from rosnet_tui.core.ssh.options import options_for
from rosnet_tui.core.ssh.session import ssh_run

PAIR_TIMEOUT_S = 5.0
FLEET_TLS_SOURCE = Path(fleet_tls.__file__).read_bytes()


@dataclass
class PairResult:
    ok: bool
    detail: str
    summary: dict[str, Any] = field(default_factory=dict)
    seconds: float = 0.0
    master_sync_key: str = ""   # the master's public sync key, when its answer carried it


def _ca_words(paths: TlsPaths) -> str:
    return f"the fleet CA ({paths.ca_crt}; its key {paths.ca_key} stays here, 0600)"


def _cert_words(s: Settings, paths: TlsPaths) -> str:
    return f"this router's certificate ({paths.node_crt}, naming {s.this.name})"


def prepare_master(s: Settings, paths: TlsPaths, *, renew: bool = False) -> list[str]:
    """On the master: the fleet CA (made once) and the master's certificate naming it as members
    dial it (its name; its public IP when known). Returns what was made (for the user)."""
    made = []
    if fleet_tls.ensure_ca(paths, s.this.name):
        made.append(_ca_words(paths))
    if fleet_tls.ensure_master_cert(paths, s.this.name, s.this.public_ip, renew=renew):
        made.append(_cert_words(s, paths))
    return made


def master_plan(s: Settings, paths: TlsPaths) -> list[str]:
    """What :func:`prepare_master` would make now, in its words; nothing is made (a preview)."""
    plan = []
    if not (paths.ca_key.exists() and paths.ca_crt.exists()):
        plan.append(_ca_words(paths))
    try:
        current = fleet_tls.master_cert_current(paths, s.this.name, s.this.public_ip)
    except (TlsError, OSError, ValueError):
        current = False             # unreadable: prepare_master makes a new one
    if plan or not current:
        plan.append(_cert_words(s, paths)
                    + ("" if paths.node_key.exists() else f" and its key ({paths.node_key}, 0600)"))
    return plan


def needs_pairing(s: Settings, paths: TlsPaths) -> str | None:
    """Why this member needs (re)pairing (None: its certificate is good for a while)."""
    if not (paths.node_crt.exists() and paths.ca_crt.exists() and paths.node_key.exists()):
        return "no fleet certificate here yet"
    try:
        summ = fleet_tls.cert_summary(paths.node_crt)
    except (TlsError, OSError) as exc:
        return f"the certificate cannot be read ({exc})"
    if summ["issuer_key_id"] != fleet_tls.ca_key_id(paths.ca_crt):
        return "the certificate is not from the fleet CA installed here"
    if summ["cn"].lower() != s.this.name.lower():   # the CA names members in lower case
        return f"the certificate names {summ['cn']}, not {s.this.name}"
    if summ["days_left"] <= fleet_tls.WARN_DAYS:
        return f"the certificate expires in {summ['days_left']:.0f} days"
    return None


def master_peer(s: Settings) -> Any:
    return s.peer(s.master_name)


def tls_command(*args: str) -> str:
    """The command running fleet_tls.py (fed on stdin) with the peer's installed interpreter."""
    return zenoh_peer_command(*args)


async def remote_tls(opts: Any, peer: Any, timeout: float, *args: str) -> dict[str, Any]:
    """Run fleet_tls.py's *args* (``request NAME``, ``install CA CERT``) on *peer* with its
    installed rosnet-tui; its report, or ``{"error": ...}`` saying what went wrong."""
    res = await ssh_run(opts, peer, tls_command(*args), stdin=FLEET_TLS_SOURCE, timeout=timeout)
    if res.failure:
        return {"error": f"SSH to {peer.name} failed ({res.failure}): {res.detail}"}
    rep = report_of(res.stdout)
    if rep is None:
        tail = " | ".join((res.stderr or "").strip().splitlines()[-3:])
        return {"error": f"{peer.name} gave no answer (exit status {res.exit_status}"
                         f"{': ' + tail if tail else ''})"}
    if rep.get("error") == "no_install":
        return {"error": f"{peer.name} has no rosnet-tui installed: install it there as the "
                         "README says"}
    return rep


async def repair_members(s: Settings, paths: TlsPaths, peers: list[Any], opts: Any = None,
                         timeout: float = PAIR_TIMEOUT_S) -> list[tuple[str, bool, str]]:
    """On the master after a new CA: each member makes a request with its own key (which stays
    there), the master signs it here, the member installs the result. Two SSH round trips each,
    the members in parallel."""
    import asyncio

    async def one(peer: Any) -> tuple[str, bool, str]:
        if not peer.ssh_user:
            return (peer.name, False, "no SSH user in the settings: run `rosnet-tui ros pair` "
                                      "there")
        rep = await remote_tls(opts, peer, timeout, "request", peer.name)
        if "csr" not in rep:
            return (peer.name, False, str(rep.get("error")))
        try:
            ca, cert = fleet_tls.sign_request(paths, str(rep["csr"]), master=s.this.name,
                                              members=member_names(s))
        except TlsError as exc:
            return (peer.name, False, str(exc))
        rep = await remote_tls(opts, peer, timeout, "install", ca, cert)
        if "installed" not in rep:
            return (peer.name, False, str(rep.get("error")))
        return (peer.name, True, f"valid until {rep['installed']['not_after'][:10]}")

    return list(await asyncio.gather(*(one(p) for p in peers)))


def member_names(s: Settings) -> list[str]:
    """The names the fleet CA signs for: the peers in the master's own settings."""
    return [p.name for p in s.peers]


# Run by the master's installed interpreter (found as for the Zenoh program): its own
# `rosnet-tui ros pair --serve NAME`, the current folder off the path.
SERVE_BOOT = ("import sys,runpy;sys.path[:]=[p for p in sys.path if p not in ('','.')];"
              "sys.argv=['rosnet-tui',*sys.argv[1:]];runpy.run_module('rosnet_tui',"
              "run_name='__main__')")


def serve_command(name: str) -> str:
    """What a member asks the master to run: its `ros pair --serve NAME` (under a forced
    command in the master's authorized_keys, sshd runs that one whatever is asked)."""
    return installed_python_command("ros", "pair", "--serve", name,
                                    mark=fleet_tls.REPORT_PREFIX, boot=SERVE_BOOT)


def serve(s: Settings, paths: TlsPaths, name: str, csr_pem: str) -> dict[str, Any]:
    """On the master (`ros pair --serve NAME`, a member's forced command): sign the request on
    stdin when it names *name*, a member in these settings. The answer as one ROSNET_TLS
    line's JSON."""
    if not s.is_master:
        return {"error": f"{s.this.name} is not the master in its settings"}
    try:
        prepare_master(s, paths)
        req = fleet_tls.read_request(csr_pem, master=s.this.name, members=member_names(s),
                                     removed=fleet_tls.removed_members(paths),
                                     relay=s.relay.host)
        if req.name != name.lower():
            raise TlsError(f"this way in signs only for {name}; the request names {req.name}")
        ca, cert = fleet_tls.sign_checked(paths, req)
    except (TlsError, OSError) as exc:
        return {"error": str(exc)}
    return {"ca": ca, "cert": cert}


async def pair_over_ssh(s: Settings, paths: TlsPaths, opts: Any = None,
                        timeout: float = PAIR_TIMEOUT_S) -> PairResult:
    """Have the master sign this member's request over SSH (its `ros pair --serve`) and install
    the result."""
    t0 = time.monotonic()
    peer = master_peer(s)
    if s.is_master:
        return PairResult(False, "this component is the master: it signs, it does not pair")
    if peer is None or not peer.ssh_user:
        return PairResult(False, f"no SSH user for the master {s.master_name} in the settings: "
                                 "set it, or pair by text (`rosnet-tui ros pair --print-request`"
                                 " here, `--sign` on the master, `--install` here)")
    if getattr(opts, "relay", None) is None:      # a master behind the relay: through it
        opts = options_for(s.relay, opts)
    csr = fleet_tls.make_request(paths, s.this.name)
    res = await ssh_run(opts, peer, serve_command(s.this.name), stdin=csr, timeout=timeout)
    took = time.monotonic() - t0
    rep = report_of(res.stdout)
    if res.failure:
        rep = {"error": f"SSH to {peer.name} failed ({res.failure}): {res.detail}"}
    elif rep is None:
        tail = " | ".join((res.stderr or "").strip().splitlines()[-3:])
        rep = {"error": f"{peer.name} gave no answer (exit status {res.exit_status}"
                        f"{': ' + tail if tail else ''})"}
    elif rep.get("error") == "no_install":
        rep = {"error": f"{peer.name} has no rosnet-tui installed: install it there as the "
                        "README says"}
    if "error" in rep:
        return PairResult(False, f"{peer.name} did not sign: {rep['error']}", seconds=took)
    try:
        summ = fleet_tls.install(paths, str(rep.get("ca", "")), str(rep.get("cert", "")))
    except TlsError as exc:
        return PairResult(False, f"the answer from {peer.name} was not installed: {exc}",
                          seconds=took)
    key = rep.get("sync_key")
    return PairResult(True, f"paired with {peer.name}'s fleet CA: {paths.node_crt} names "
                            f"{summ['cn']}, valid until {summ['not_after'][:10]}", summ,
                      time.monotonic() - t0, key if isinstance(key, str) else "")


def report_of(text: str) -> dict[str, Any] | None:
    """The ``ROSNET_TLS`` line of the master's answer (the last one), or None."""
    for line in reversed((text or "").splitlines()):
        if line.startswith(fleet_tls.REPORT_PREFIX):
            try:
                value = loads_bounded(line[len(fleet_tls.REPORT_PREFIX):])
            except JsonInputError:
                return None
            return value if isinstance(value, dict) else None
        if line.startswith("ROSNET_ZENOH ") and "no_install" in line:
            return {"error": "no_install"}
    return None


def renew_due(s: Settings, paths: TlsPaths, opts: Any = None) -> tuple[list[str], float]:
    """The sync service's part: renew this component's certificate when it expires within 30
    days (on a member over SSH, as ``ros pair --renew``). (lines to log, seconds to the next
    look: 6 h, or 10 min after a failure)."""
    import asyncio

    if not mtls(s):
        return [], 6 * 3600.0
    if s.is_master:
        if not paths.ca_key.exists():
            return [], 6 * 3600.0     # `ros apply` makes the CA; the sync service never does
        made = prepare_master(s, paths)
        return [f"TLS: made {m}" for m in made], 6 * 3600.0
    why = needs_pairing(s, paths)
    if why is None or "expire" not in why:   # never paired: `ros apply` / `ros pair` do that
        return [], 6 * 3600.0
    res = asyncio.run(pair_over_ssh(s, paths, opts))
    return [f"TLS: renewing ({why}): {res.detail}"], 6 * 3600.0 if res.ok else 600.0


class CertRenewer:
    """Renews the fleet certificate before it expires, on a thread of its own while the sync
    service runs (same shape as the forwards' Renewer: ``tick`` each round)."""

    def __init__(self, log: Any) -> None:
        self.log = log
        self.next_at = 0.0
        self._thread: Any = None

    def tick(self, settings: Settings | None, *, background: bool) -> None:
        import copy
        import threading

        if settings is None or time.monotonic() < self.next_at or \
                (self._thread is not None and self._thread.is_alive()):
            return
        self.next_at = float("inf")
        s = copy.deepcopy(settings)

        def work() -> None:
            try:
                said, nxt = renew_due(s, fleet_tls.tls_paths(default_config_dir()))
            except Exception as exc:  # noqa: BLE001 - a renewal's trouble must not stop the sync
                said, nxt = [f"TLS: renewing the certificate failed: {exc}"], 600.0
            for line in said:
                self.log.info("%s", line)
            self.next_at = time.monotonic() + nxt

        if not background:
            work()
            return
        self._thread = threading.Thread(target=work, name="certificate renewal", daemon=True)
        self._thread.start()
