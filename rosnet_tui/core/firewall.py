"""ROS 1: only the peers reach the forwarded ports (an nftables table of our own).

The forwards a ROS 1 network needs (the range, 22 and the master's port) let anyone on the internet
talk to the master and every node. This module keeps one table, ``table inet rosnet_tui``, with a
set of the peers' addresses and an input chain of its own, hooked before the distribution's
filter (priority -10): on the forwarded TCP ports it accepts loopback, established/related traffic
and the peers, and drops the rest. Nothing outside that table is read or changed.

- :func:`render_ruleset` is the text applied; :func:`preview` compares it with what is loaded now.
- :func:`apply` loads it as ONE ``nft -f`` transaction (create-delete-define: our table is
  replaced whole, or nothing changes) and records an undo journal entry (``kind`` nft_table) that
  :func:`undo_entry` reverses: our table deleted, or the previous one put back.
- :func:`follow_peers` (the sync service) replaces the set's elements in one transaction
  (``flush set`` + ``add element`` in the same file) when a peer's address changes.

Root is needed for all of it (listing included); the CLI re-runs itself through sudo like the
hosts writer does.
"""

from __future__ import annotations

import difflib
import hashlib
import ipaddress
import logging
import os
import re
import shutil
import subprocess
from dataclasses import dataclass, field
from pathlib import Path

from rosnet_tui.core import jsonsafe
from rosnet_tui.core import undo_journal as uj
from rosnet_tui.core.settings_model import PORT_MAX, PORT_MIN, Settings

FAMILY = "inet"
NAME = "rosnet_tui"
TABLE = f"{FAMILY} {NAME}"
SET4, SET6 = "peers4", "peers6"
CHAIN = "input"
PRIORITY = -10            # before the distribution's filter (priority 0)
SSH_PORT = 22
KIND = "nft_table"        # the journal entry's kind (managed_file's undo dispatches on it)
NFT_TIMEOUT_S = 10.0
LABEL = "firewall: peers only on the forwarded ports"

MODES = ("mtls", "firewall", "none")


class FirewallError(Exception):
    """nft is missing, refused our ruleset, or may not be run by this user."""


class FirewallSettingsError(FirewallError):
    """The settings do not give a usable ruleset; *problems* lists (key, why)."""

    def __init__(self, problems: list[tuple[str, str]]) -> None:
        super().__init__("; ".join(f"{k}: {w}" for k, w in problems))
        self.problems = problems


# --------------------------------------------------------------------------- what is wanted
def wanted(settings: Settings) -> bool:
    """True when this component should have the peers-only table (ROS 1, security firewall)."""
    return not settings.ros2 and settings.ros.security == "firewall"


def forwarded_ports(settings: Settings) -> list[str]:
    """The TCP ports the forward exposes, as nft writes them: 22, the range, the master's port
    (when outside the range)."""
    out = [str(SSH_PORT), f"{PORT_MIN}-{PORT_MAX}"]
    if not PORT_MIN <= settings.ros.port <= PORT_MAX and settings.ros.port != SSH_PORT:
        out.append(str(settings.ros.port))
    return out


def open_ports(settings: Settings) -> list[int]:
    """Ports left open to anyone inside the range: the port checker's test port (probe.port),
    which only rosnet-tui's own listener answers, during router.port_open."""
    p = settings.probe.port
    return [p] if PORT_MIN <= p <= PORT_MAX and p != settings.ros.port else []


def peer_address(settings: Settings, name: str, profile: str | None = None) -> str:
    """The address *name* (a peer) connects from: its public IP on the remote profile, its LAN
    address on office/portable."""
    profile = profile or settings.this.profile
    p = settings.peer(name)
    if p is None:
        return ""
    if profile == "remote":
        return p.public_ip
    if profile == "office":
        return p.office_ip or p.local_ip
    return p.portable_ip or p.local_ip


def allowed_addresses(settings: Settings, profile: str | None = None) -> list[str]:
    """Every peer's address for *profile*; refuses (FirewallSettingsError) a bad or missing one."""
    problems: list[tuple[str, str]] = []
    out: list[str] = []
    for i, p in enumerate(settings.peers):
        ip = peer_address(settings, p.name, profile)
        if not ip:
            problems.append((f"peers[{i}] ({p.name})", "no address known for the "
                             f"{profile or settings.this.profile} profile"))
            continue
        try:
            a = ipaddress.ip_address(ip)
        except ValueError:
            problems.append((f"peers[{i}] ({p.name})", f"'{ip[:40]}' is not an IP address"))
            continue
        if a.is_unspecified or a.is_multicast or a.is_loopback:
            problems.append((f"peers[{i}] ({p.name})", f"{ip} cannot be a peer's address"))
            continue
        if str(a) not in out:
            out.append(str(a))
    if not settings.peers:
        problems.append(("peers", "no peers: the table would shut everyone out"))
    if problems:
        raise FirewallSettingsError(problems)
    return out


def split_families(addresses: list[str]) -> tuple[list[str], list[str]]:
    v4 = [a for a in addresses if ipaddress.ip_address(a).version == 4]
    return v4, [a for a in addresses if a not in v4]


def _elements(addrs: list[str]) -> str:
    return f"elements = {{ {', '.join(addrs)} }}" if addrs else ""


def render_ruleset(settings: Settings, addresses: list[str]) -> str:
    """The table as nft reads it (also what `firewall show` prints)."""
    v4, v6 = split_families(addresses)
    ports = ", ".join(forwarded_ports(settings))
    lines = [
        f"table {TABLE} {{",
        f"\tset {SET4} {{",
        "\t\ttype ipv4_addr",
        *([f"\t\t{_elements(v4)}"] if v4 else []),
        "\t}",
        f"\tset {SET6} {{",
        "\t\ttype ipv6_addr",
        *([f"\t\t{_elements(v6)}"] if v6 else []),
        "\t}",
        f"\tchain {CHAIN} {{",
        f"\t\ttype filter hook input priority filter - {-PRIORITY}; policy accept;",
        '\t\tiif "lo" accept',
        "\t\tct state established,related accept",
        f"\t\ttcp dport {{ {ports} }} ip saddr @{SET4} accept",
        f"\t\ttcp dport {{ {ports} }} ip6 saddr @{SET6} accept",
    ]
    lines += [f"\t\ttcp dport {p} accept" for p in open_ports(settings)]
    lines += [f"\t\ttcp dport {{ {ports} }} drop", "\t}", "}"]
    return "\n".join(lines) + "\n"


def transaction_text(ruleset: str) -> str:
    """ONE transaction replacing our table whole: create it if absent, delete it, define it."""
    return f"table {TABLE}\ndelete table {TABLE}\n{ruleset}"


def digest(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()


# --------------------------------------------------------------------------- nft
def nft_path() -> str | None:
    return shutil.which("nft") or next((p for p in ("/usr/sbin/nft", "/sbin/nft")
                                        if Path(p).exists()), None)


def _nft(args: list[str], *, stdin: str | None = None, timeout: float = NFT_TIMEOUT_S
         ) -> subprocess.CompletedProcess:
    nft = nft_path()
    if nft is None:
        raise FirewallError("nft is not installed (Debian/Ubuntu: sudo apt install nftables)")
    try:
        return subprocess.run([nft, *args], input=stdin, capture_output=True, text=True,
                              timeout=timeout)
    except subprocess.TimeoutExpired:
        raise FirewallError(f"nft did not answer within {timeout:g} s") from None
    except OSError as exc:
        raise FirewallError(f"cannot run nft: {exc.strerror}") from None


def _no_table(stderr: str) -> bool:
    s = stderr.lower()
    return "no such file or directory" in s or "does not exist" in s


def _denied(stderr: str) -> bool:
    s = stderr.lower()
    return "operation not permitted" in s or "permission denied" in s


def current_ruleset() -> str | None:
    """Our table as loaded now (``nft -s list table``), or None when there is none."""
    r = _nft(["-s", "list", "table", FAMILY, NAME])
    if r.returncode == 0:
        return r.stdout
    if _denied(r.stderr):
        raise FirewallError("reading the firewall needs root (nft: Operation not permitted)")
    if _no_table(r.stderr):
        return None
    raise FirewallError(f"nft list table {TABLE}: {r.stderr.strip()[:300]}")


def current_allowed() -> list[str] | None:
    """The addresses in our sets now, or None when our table is not loaded."""
    r = _nft(["-j", "list", "table", FAMILY, NAME])
    if r.returncode != 0:
        if _denied(r.stderr):
            raise FirewallError("reading the firewall needs root (nft: Operation not permitted)")
        if _no_table(r.stderr):
            return None
        raise FirewallError(f"nft list table {TABLE}: {r.stderr.strip()[:300]}")
    try:
        items = jsonsafe.loads_bounded(r.stdout, unique_keys=False).get("nftables") or []
    except (jsonsafe.JsonInputError, AttributeError):
        raise FirewallError("nft printed JSON that does not parse") from None
    out: list[str] = []
    for it in items:
        s = it.get("set") if isinstance(it, dict) else None
        if isinstance(s, dict) and s.get("name") in (SET4, SET6):
            for e in s.get("elem") or []:
                if isinstance(e, str):
                    out.append(e)
    return sorted(out)


def load(text: str) -> None:
    """Run *text* as ONE nft transaction (all or nothing)."""
    r = _nft(["-f", "-"], stdin=text)
    if r.returncode != 0:
        if _denied(r.stderr):
            raise FirewallError("changing the firewall needs root (nft: Operation not permitted)")
        raise FirewallError(f"nft refused the ruleset; nothing was changed: "
                            f"{r.stderr.strip()[:400]}")


# --------------------------------------------------------------------------- preview and apply
@dataclass
class FirewallPreview:
    ruleset: str                 # what apply loads
    current: str | None          # what is loaded now (None: no table of ours)
    addresses: list[str]
    readable: bool = True        # False: this user could not read the current table
    notes: list[str] = field(default_factory=list)

    @property
    def digest(self) -> str:
        return digest(self.ruleset)

    @property
    def changed(self) -> bool:
        return not self.readable or normalize(self.current) != normalize(self.ruleset)

    @property
    def path(self) -> str:            # what the wizard's write screen names
        return f"the firewall (nft table {TABLE})"

    @property
    def needs_privilege(self) -> bool:
        return os.geteuid() != 0

    def diff(self) -> str:
        old = (self.current or "").splitlines(keepends=True)
        new = self.ruleset.splitlines(keepends=True)
        return "".join(difflib.unified_diff(old, new, f"nft: {TABLE} (now)",
                                            f"nft: {TABLE} (new)"))


def normalize(text: str | None) -> str:
    """Rulesets compared without the differences of layout nft's listing adds."""
    if not text:
        return ""
    flat = " ".join(text.replace(",", " ").split())

    def sort_elements(m: re.Match) -> str:
        return "elements = { " + " ".join(sorted(m.group(1).split())) + " }"
    return re.sub(r"elements = \{([^}]*)\}", sort_elements, flat)


def preview(settings: Settings, profile: str | None = None) -> FirewallPreview:
    addresses = allowed_addresses(settings, profile)
    ruleset = render_ruleset(settings, addresses)
    notes = []
    if not wanted(settings):
        notes.append(f"[ros] security is '{settings.ros.security}'"
                     + (" (ROS 2: mTLS protects the Zenoh port)" if settings.ros2 else "")
                     + "; the table is written because you asked for it")
    try:
        current, readable = current_ruleset(), True
    except FirewallError as exc:
        current, readable = None, False
        notes.append(f"the table loaded now is not shown: {exc}")
    return FirewallPreview(ruleset, current, addresses, readable, notes)


def apply_command(*, config: Path, profile: str, digest: str, state_dir: Path) -> list[str]:
    """The exact sudo command that loads the previewed table (and nothing else)."""
    from rosnet_tui.core import privilege

    def ab(p: Path) -> str:
        return str(Path(p).expanduser().absolute())
    return privilege.sudo_argv(["--config", ab(config), "firewall", "apply", "--profile", profile,
                                "--expect-digest", digest, "--yes", "--state-dir", ab(state_dir),
                                "--no-checks"])


def apply(pv: FirewallPreview, *, state_dir: Path | None = None) -> str | None:
    """Load *pv* in one transaction and journal it; the journal entry id (None: no change)."""

    before = current_ruleset()
    if normalize(before) == normalize(pv.ruleset):
        return None
    load(transaction_text(pv.ruleset))
    record = {"kind": KIND, "table": TABLE, "state": "made", "before": before,
              "after": digest(pv.ruleset)}
    return uj.record_entry(LABEL, [record], state_dir=state_dir)


def _restore(record: dict) -> str:
    before = record.get("before")
    if isinstance(before, str) and before.strip():
        if not only_our_table(before):
            raise FirewallError(f"the journal's copy is not a table {TABLE}; not loaded")
        load(transaction_text(before))
        return f"the firewall table {TABLE}: put back as it was before"
    if current_ruleset() is not None:
        load(f"delete table {TABLE}\n")
    return f"the firewall table {TABLE}: removed (rosnet-tui created it)"


def only_our_table(text: str) -> bool:
    """True when *text* defines our table and nothing else (a journal copy is checked before
    root loads it)."""
    top = [ln.rstrip() for ln in text.splitlines() if ln.strip() and not ln[:1].isspace()]
    return top == [f"table {TABLE} {{", "}"]


def undo_records(records: list[dict], force: bool = False) -> list[str]:
    """Reverse recorded firewall changes (the undo journal's handler for KIND)."""
    from rosnet_tui.core.managed_text import ManagedFileError

    said = []
    for rec in records:
        if rec.get("kind") == KIND and rec.get("state") == "made":
            try:
                said.append(_restore(rec))
            except FirewallError as exc:
                raise ManagedFileError(f"the firewall table {TABLE} was not restored: {exc}"
                                       ) from None
            rec["state"] = "undone"
    return said


uj.register_undo(KIND, undo_records)   # an undo of an entry with our table in it


def describe(record: dict) -> str:
    before = record.get("before")
    return (f"the firewall table {TABLE}: "
            + ("put back as it was before" if before else "removed (rosnet-tui created it)"))


def remove(*, state_dir: Path | None = None) -> str | None:
    """Delete our table (nothing else) and journal it, so `rosnet-tui undo` can load it again;
    the journal entry id (None: there was no table of ours)."""

    before = current_ruleset()
    if before is None:
        return None
    load(f"delete table {TABLE}\n")
    record = {"kind": KIND, "table": TABLE, "state": "made", "before": before, "after": None}
    return uj.record_entry(f"firewall: table {TABLE} removed", [record], state_dir=state_dir)


# --------------------------------------------------------------------------- address sync
def set_update_text(addresses: list[str]) -> str:
    """ONE transaction replacing both sets' elements (no window without a peer)."""
    v4, v6 = split_families(addresses)
    lines = []
    for name, addrs in ((SET4, v4), (SET6, v6)):
        lines.append(f"flush set {TABLE} {name}")
        if addrs:
            lines.append(f"add element {TABLE} {name} {{ {', '.join(addrs)} }}")
    return "\n".join(lines) + "\n"


def follow_peers(addresses: list[str]) -> tuple[list[str], list[str]] | None:
    """Make our sets hold exactly *addresses* when our table is loaded: (before, after) when the
    set changed, None when nothing was to do (no table, or the same addresses)."""
    clean = sorted({str(ipaddress.ip_address(a)) for a in addresses if a})
    now = current_allowed()
    if now is None or now == clean or not clean:
        return None
    load(set_update_text(clean))
    return now, clean


def follow_for_sync(settings: Settings, addresses: list[str], log: logging.Logger) -> None:
    """The sync service's hook (its apply step): keep our set equal to the peers' addresses it
    just planned. Only when the settings want the table, this process is root and our table is
    loaded; never creates the table. Failures are logged, never raised."""
    if not wanted(settings) or os.geteuid() != 0 or nft_path() is None:
        return
    try:
        changed = follow_peers([a for a in addresses if a])
    except (FirewallError, ValueError) as exc:
        log.warning("firewall: the allowed set was not updated: %s", exc)
        return
    if changed:
        log.info("firewall: allowed set %s -> %s (table %s, one transaction)",
                 ", ".join(changed[0]) or "-", ", ".join(changed[1]), TABLE)
