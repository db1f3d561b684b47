"""`rosnet-tui relay apply` (issue 30): the master sets the relay up over SSH.

The relay makes its own TLS key (it never leaves the relay), the fleet CA here signs its request
for the relay's name (``[relay] host``, as pairing signs a member's: :func:`fleet_tls.read_request`
takes it in role "relay"), and the relay's router config and the systemd unit that runs
``rosnet-tui relay serve`` are written there. Everything runs on the relay with the interpreter of
the rosnet-tui installed there (``core/peer/relayproto.py`` and ``fleet_tls.py``, fed on stdin),
never its system Python; the relay's host key is verified as for every SSH use of the product.

The config and the unit go in an undo entry of their own kind (:data:`KIND`, their text before
and the digest after): ``rosnet-tui undo`` puts them back over SSH. Not the key and certificate,
as ``ros apply`` leaves the fleet CA.
"""

from __future__ import annotations

import asyncio
import getpass
import json
import shlex
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rosnet_tui.core.config.settings_model import Peer, Settings
from rosnet_tui.core.files import undo_journal as uj
from rosnet_tui.core.files.managed_text import ManagedFileError
from rosnet_tui.core.jsonsafe import JsonInputError, loads_bounded
from rosnet_tui.core.peer import relayproto
from rosnet_tui.core.peer.commands import installed_python_command
from rosnet_tui.core.ros import fleet_tls
from rosnet_tui.core.ros.fleet_tls import TlsError, TlsPaths
from rosnet_tui.core.ros.pairing import member_names, remote_tls
from rosnet_tui.core.ros.relay import render_relay_config
from rosnet_tui.core.ros.ros2 import mtls
from rosnet_tui.core.ssh.options import SshOptions
from rosnet_tui.core.ssh.session import ssh_run

KIND = "relay_files"
UNIT_NAME = "rosnet-tui-relay.service"
UNIT_DIR = Path("/etc/systemd/system")
STEP_TIMEOUT_S = 20.0      # one SSH round trip to the relay (an interpreter start, a key made)
PROGRAM = Path(relayproto.__file__).read_bytes()


class RelayApplyError(Exception):
    """A step on the relay failed (SSH, its install, a file there): the words say which."""


def refusal(s: Settings, tls: TlsPaths) -> str | None:
    """Why `relay apply` cannot run with these settings here (None: it can); the CLI exits 2."""
    if not s.relay.host:
        return ("no relay in the settings: set [relay] host (and ssh_user, ssh_port) as "
                "docs/SETTINGS.md says")
    if not s.ros2:
        return ("a relay carries ROS 2 only ([ros] version = 2); ROS 1 nodes connect to each "
                "other directly")
    if not mtls(s):
        return "a relay takes only fleet certificates: [ros] security must be \"mtls\""
    if not s.is_master:
        return (f"{s.this.name} is not the master: run `rosnet-tui relay apply` on the master "
                f"{s.master_name}, where the fleet CA is")
    if not (tls.ca_key.exists() and tls.ca_crt.exists()):
        return f"no fleet CA here yet ({tls.ca_key}): run `rosnet-tui ros apply` first"
    return None


def relay_peer(s: Settings) -> Peer:
    """The relay as an SSH peer: its name, its sshd's port, its account ([relay] ssh_user, or
    the user running rosnet-tui)."""
    r = s.relay
    return Peer(name=r.host, ssh_user=r.ssh_user or getpass.getuser(), ssh_port=int(r.ssh_port))


def hop_words(s: Settings) -> str:
    p = relay_peer(s)
    return f"SSH from {s.this.name} to the relay {p.name} ({p.ssh_user}@{p.name}:{p.ssh_port})"


async def _run(opts: SshOptions | None, s: Settings, *args: str,
               timeout: float = STEP_TIMEOUT_S) -> dict[str, Any]:
    """relayproto's *args* on the relay; its report. Raises RelayApplyError."""
    peer = relay_peer(s)
    cmd = installed_python_command(*args, mark=relayproto.REPORT_MARK)
    res = await ssh_run(opts, peer, cmd, stdin=PROGRAM, timeout=timeout)
    if res.failure:
        raise RelayApplyError(f"{hop_words(s)} failed ({res.failure}): {res.detail}")
    rep = None
    for line in reversed(res.stdout.splitlines()):
        if line.startswith(relayproto.REPORT_MARK):
            try:
                rep = loads_bounded(line[len(relayproto.REPORT_MARK):])
            except JsonInputError:
                rep = None
            break
    if not isinstance(rep, dict):
        tail = " | ".join((res.stderr or "").strip().splitlines()[-3:])
        raise RelayApplyError(f"the relay {peer.name} gave no answer (exit status "
                              f"{res.exit_status}{': ' + tail if tail else ''})")
    if rep.get("error") == "no_install":
        raise RelayApplyError(f"the relay {peer.name} has no rosnet-tui installed for "
                              f"{peer.ssh_user}: install it there as the README says")
    if "error" in rep:
        raise RelayApplyError(f"on the relay {peer.name}: {rep['error']}")
    return rep


@dataclass(frozen=True)
class RelayLook:
    """What one look at the relay saw (relayproto's ``look``): where its files are, what runs
    ``relay serve`` there, the text of its files (None: absent)."""

    config_dir: str
    relay_config: str
    ca_crt: str
    node_key: str
    node_crt: str
    python: str
    package_root: str
    user: str
    systemd: bool
    node_key_exists: bool
    files: dict[str, str | None]
    writable: dict[str, bool]

    @classmethod
    def from_report(cls, rep: dict[str, Any]) -> RelayLook:
        try:
            return cls(**{k: rep[k] for k in ("config_dir", "relay_config", "ca_crt", "node_key",
                                              "node_crt", "python", "user")},
                       package_root=str(rep.get("package_root") or ""),
                       systemd=bool(rep.get("systemd")),
                       node_key_exists=bool(rep.get("node_key_exists")),
                       files={str(k): (v if isinstance(v, str) else None)
                              for k, v in (rep.get("files") or {}).items()},
                       writable={str(k): bool(v) for k, v in (rep.get("writable") or {}).items()})
        except (KeyError, AttributeError, TypeError):
            raise RelayApplyError("the relay's answer lacks what it must say (another version "
                                  "of rosnet-tui there?)") from None


@dataclass
class RemoteFile:
    path: str
    old: str | None           # its text on the relay now (None: absent)
    new: str
    mode: int = 0o644
    what: str = ""

    @property
    def changed(self) -> bool:
        return self.old != self.new


@dataclass
class RelayPlan:
    """What `relay apply` would do, from one look at the relay; nothing done yet."""

    host: str
    look: RelayLook
    cert_why: str | None          # why the relay needs a new certificate (None: its own is good)
    cert_kept: str = ""           # the good certificate's words, when kept
    files: list[RemoteFile] = field(default_factory=list)

    @property
    def changed(self) -> bool:
        return self.cert_why is not None or any(f.changed for f in self.files)


def _cert_need(s: Settings, tls: TlsPaths, look: RelayLook) -> tuple[str | None, str]:
    """Why the relay needs a certificate from the fleet CA now (None: the one there is good),
    and the kept one's words."""
    cert, ca = look.files.get(look.node_crt), look.files.get(look.ca_crt)
    if not look.node_key_exists or not cert:
        return "it has none yet", ""
    try:
        summ = fleet_tls.cert_summary(cert.encode())
    except (TlsError, ValueError):
        return "the certificate there cannot be read", ""
    if summ["issuer_key_id"] != fleet_tls.ca_key_id(tls.ca_crt) \
            or (ca or "").strip() != tls.ca_crt.read_text().strip():
        return "the certificate there is not from this fleet CA", ""
    if s.relay.host.lower() not in [n.lower() for n in summ["sans"]]:
        return f"the certificate there names {summ['cn']}, not {s.relay.host}", ""
    if summ["days_left"] <= fleet_tls.WARN_DAYS:
        return f"the certificate there expires in {summ['days_left']:.0f} days", ""
    return None, f"{look.node_crt}, naming {summ['cn']}, valid until {summ['not_after'][:10]}"


async def plan(s: Settings, tls: TlsPaths, opts: SshOptions | None, unit_path: Path,
               unit_text: Any) -> RelayPlan:
    """Look at the relay (one SSH round trip) and say what would change there. *unit_text*:
    the unit's text for the relay's interpreter, package root and user (the CLI's, one home for
    units). Raises RelayApplyError."""
    look = RelayLook.from_report(await _run(opts, s, "look", str(unit_path)))
    if not look.writable.get(str(unit_path)):
        raise RelayApplyError(f"the relay's user {look.user} may not write {unit_path}: "
                              "set [relay] ssh_user = \"root\", or name a folder it may write "
                              "with --unit-dir")
    tls_dir = Path(look.config_dir) / "tls"
    rtls = TlsPaths(tls_dir, Path(look.ca_crt), tls_dir / "ca.key", Path(look.node_key),
                    Path(look.node_crt))
    config = render_relay_config(s.relay.host, s.relay.zenoh_port, rtls)
    unit = unit_text(look.python, look.package_root, look.user, look.relay_config)
    why, kept = _cert_need(s, tls, look)
    return RelayPlan(s.relay.host, look, why, kept, [
        RemoteFile(look.relay_config, look.files.get(look.relay_config), config, 0o644,
                   "the relay's router config"),
        RemoteFile(str(unit_path), look.files.get(str(unit_path)), unit, 0o644,
                   "the systemd unit that runs `rosnet-tui relay serve`")])


def _record(s: Settings, p: RelayPlan) -> dict[str, Any]:
    peer = relay_peer(s)
    return {"kind": KIND, "state": "planned", "host": peer.name, "user": peer.ssh_user,
            "port": peer.ssh_port,
            "files": [{"path": f.path, "before": f.old, "after": relayproto.digest(f.new),
                       "mode": f.mode} for f in p.files if f.changed]}


def _save(state_dir: Path | None, entry: uj.JournalEntry) -> None:
    sd = uj.state_dir_path(state_dir)
    owner = uj.owner_for(sd)
    with uj.locked(sd, owner):
        uj.save_entry(sd, entry, owner)
        uj.prune(sd)


async def apply(s: Settings, tls: TlsPaths, opts: SshOptions | None, p: RelayPlan,
                state_dir: Path | None = None) -> list[str]:
    """Do what *p* says on the relay: its key and certificate (when needed), then its files (in
    an undo entry recorded before they are written). What was done, a line each. Raises
    RelayApplyError."""
    done: list[str] = []
    if p.cert_why is not None:
        peer = relay_peer(s)
        rep = await remote_tls(opts, peer, STEP_TIMEOUT_S, "request", s.relay.host)
        if "csr" not in rep:
            raise RelayApplyError(f"the relay made no request: {rep.get('error')}")
        try:
            ca, cert = fleet_tls.sign_request(tls, str(rep["csr"]), master=s.this.name,
                                              members=member_names(s), relay=s.relay.host)
        except TlsError as exc:
            raise RelayApplyError(f"the relay's request was not signed: {exc}") from None
        if fleet_tls.cert_summary(cert.encode())["cn"] != s.relay.host.lower():
            raise RelayApplyError("the relay's request names another host")
        rep = await remote_tls(opts, peer, STEP_TIMEOUT_S, "install", ca, cert)
        if "installed" not in rep:
            raise RelayApplyError(f"the relay did not install its certificate: "
                                  f"{rep.get('error')}")
        done.append(f"the relay's key made there ({p.look.node_key}) and its "
                    f"certificate signed here for {s.relay.host}, valid until "
                    f"{rep['installed']['not_after'][:10]}")
    todo = [f for f in p.files if f.changed]
    if not todo:
        return done
    sd = uj.state_dir_path(state_dir)
    entry = uj.JournalEntry(uj.next_id(sd), uj.now(), f"relay {s.relay.host}: router config "
                            "and unit", [], mappings=[_record(s, p)])
    _save(sd, entry)
    spec = {"files": [{"path": f.path, "content": f.new, "mode": f.mode,
                       "expect": relayproto.digest(f.old)} for f in todo]}
    await _run(opts, s, "write", json.dumps(spec))
    entry.mappings[0]["state"] = "made"
    _save(sd, entry)
    done.extend(f"wrote {f.what} {f.path} on the relay" for f in todo)
    return done


# --------------------------------------------------------------------------- the unit
NOT_ALLOWED_EXIT = 77      # the start command's own status: this login may not use sudo


def start_steps(p: RelayPlan, unit_path: Path) -> list[str]:
    """The systemctl commands that run the relay's unit after this apply: daemon-reload, then
    enable and start it; restart it when the unit was there before and the plan changes what
    a running router reads (its config, unit or certificate). A unit outside systemd's folder
    is enabled by its path (systemctl links it) and then named."""
    moved = unit_path.parent != UNIT_DIR
    before = next((f.old for f in p.files if f.path == str(unit_path)), None)
    restart = p.changed and before is not None
    if not moved and not restart:
        return ["systemctl daemon-reload", f"systemctl enable --now {UNIT_NAME}"]
    enable = shlex.quote(str(unit_path)) if moved else UNIT_NAME
    return ["systemctl daemon-reload", f"systemctl enable {enable}",
            f"systemctl {'restart' if restart else 'start'} {UNIT_NAME}"]


def start_line(p: RelayPlan, unit_path: Path) -> str:
    """What a person runs on the relay (sudo for a login that is not root)."""
    sudo = "" if p.look.user == "root" else "sudo "
    return " && ".join(sudo + step for step in start_steps(p, unit_path))


async def start_unit(s: Settings, opts: SshOptions | None, p: RelayPlan,
                     unit_path: Path) -> tuple[bool | None, str]:
    """Run :func:`start_steps` on the relay over SSH, as root or through ``sudo -n``. True: done;
    None: this login may not (not root, and sudo asks for a password or refuses); False: a step
    failed. The words say which."""
    return await _systemctl(s, opts, p.look.user, start_steps(p, unit_path))


async def _systemctl(s: Settings, opts: SshOptions | None, user: str,
                     steps: list[str]) -> tuple[bool | None, str]:
    """*steps* (systemctl commands) on the relay, as :func:`start_unit` says."""
    if user == "root":
        cmd = " && ".join(steps)
    else:
        cmd = (f"sudo -n true 2>/dev/null || exit {NOT_ALLOWED_EXIT}; "
               + " && ".join(f"sudo -n {step}" for step in steps))
    res = await ssh_run(opts, relay_peer(s), cmd, timeout=STEP_TIMEOUT_S)
    if res.failure:
        return False, f"{hop_words(s)} failed ({res.failure}): {res.detail}"
    if res.exit_status == NOT_ALLOWED_EXIT and user != "root":
        return None, f"the relay's user {user} is not root and sudo asks it for a password"
    if res.exit_status != 0:
        tail = " | ".join((res.stderr or res.stdout or "").strip().splitlines()[-3:])
        return False, (f"on the relay {s.relay.host}, systemctl failed (exit status "
                       f"{res.exit_status}{': ' + tail if tail else ''})")
    return True, f"ran `{' && '.join(steps)}` on the relay {s.relay.host}"


# --------------------------------------------------------------------------- undo
def undo_steps(files: list[dict]) -> tuple[list[str], list[str]]:
    """The systemctl steps (before, after) putting the relay's *files* back (an undo entry's):
    a unit the apply made is stopped and disabled first, while its file is there to say how (its
    router would run on, and start again at the next boot, with no unit left); a unit or config
    put back to its older text is read again, and the router restarted if it runs."""
    unit = next((f for f in files if str(f.get("path") or "").endswith("/" + UNIT_NAME)), None)
    if unit is not None and unit.get("before") is None:
        return [f"systemctl disable --now {UNIT_NAME}"], ["systemctl daemon-reload"]
    return [], ["systemctl daemon-reload", f"systemctl try-restart {UNIT_NAME}"]


async def _undo_one(change: dict, force: bool) -> str:
    s = Settings()
    s.relay.host, s.relay.ssh_user = str(change.get("host")), str(change.get("user"))
    s.relay.ssh_port = int(change.get("port") or 22)
    files = [f for f in change.get("files") or [] if isinstance(f, dict)]
    look = RelayLook.from_report(await _run(None, s, "look",
                                            *[str(f.get("path")) for f in files]))
    now = look.files
    changed = [str(f["path"]) for f in files
               if relayproto.digest(now.get(str(f["path"]))) not in (f.get("after"),
                                                                     relayproto.digest(
                                                                         f.get("before")))]
    if changed and not force:
        raise ManagedFileError("changed on the relay since rosnet-tui wrote it: "
                               + ", ".join(changed) + "; nothing was changed there (force it "
                               "to put them back anyway)")
    before, after = undo_steps(files) if look.systemd else ([], [])
    said: list[str] = []
    if before:      # the router stopped first: refused, the undo changes nothing (unless forced)
        ok, words = await _unit_words(s, look.user, before)
        if not ok and not force:
            raise RelayApplyError(words)
        said.append(words)
    spec = {"files": [{"path": str(f["path"]), "content": f.get("before"),
                       "mode": int(f.get("mode") or 0o644), "expect": None} for f in files]}
    await _run(None, s, "write", json.dumps(spec))
    change["state"] = "removed"
    if after:
        said.append((await _unit_words(s, look.user, after))[1])
    return (f"the relay {s.relay.host}: " + ", ".join(
        f"{f['path']} {'put back' if f.get('before') is not None else 'removed'}"
        for f in files) + "".join(f"; {w}" for w in said))


async def _unit_words(s: Settings, user: str, steps: list[str]) -> tuple[bool, str]:
    """*steps* run on the relay for an undo: (done, what ran or what to run there by hand)."""
    ok, words = await _systemctl(s, None, user, steps)
    if ok:
        return True, words
    sudo = "" if user == "root" else "sudo "
    return False, (f"{words}: run on the relay `{' && '.join(sudo + x for x in steps)}` (its "
                   f"router may run as {UNIT_NAME} until then)")


def _blocking(change: dict, force: bool) -> str:
    """:func:`_undo_one` to its end, from a caller that may be in an event loop (the wizard's
    undo): then on a thread of its own."""
    try:
        asyncio.get_running_loop()
    except RuntimeError:
        return asyncio.run(_undo_one(change, force))
    with ThreadPoolExecutor(1) as pool:
        return pool.submit(asyncio.run, _undo_one(change, force)).result()


def undo_records(changes: list[dict], force: bool) -> list[str]:
    """Put the relay's files back as they were (the undo journal's handler for :data:`KIND`)."""
    said = []
    for change in changes:
        if change.get("state") not in ("made", "planned"):
            continue
        try:
            said.append(_blocking(change, force))
        except RelayApplyError as exc:
            if not force:
                raise ManagedFileError(f"{exc}; nothing was changed on the relay (run the undo "
                                       "again when it answers, or force it to forget)") from None
            change["state"] = "forgotten"
            said.append(f"the relay's files: forgotten, not put back ({exc})")
    return said


def describe(change: dict) -> str:
    paths = ", ".join(str(f.get("path")) for f in change.get("files") or [])
    return f"on the relay {change.get('host')}: {paths} put back as they were"


uj.register_undo(KIND, undo_records)   # rosnet-tui undo of an entry with the relay's files
