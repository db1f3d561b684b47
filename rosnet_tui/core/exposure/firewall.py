"""ROS 1: only the peers reach the forwarded ports (an nftables table of our own).

The forwards a ROS 1 network needs (the range, 22 and the master's port) let anyone on the internet
talk to the master and every node. This module keeps one table, ``table inet rosnet_tui``, with
sets of addresses and an input chain of its own, hooked before the distribution's filter
(priority -10). On the forwarded TCP ports it accepts loopback, established/related traffic and:

- the peers (sets peers4/peers6): every forwarded port; the sync service follows their addresses;
- this machine's LAN (lan4/lan6): the private, link-local and ULA networks of its interfaces'
  addresses, every forwarded port. The modem's forward never delivers such a source address (it
  rewrites the destination only), so they are the LAN's hosts, not the internet. A network
  outside those blocks (a public address block, the carrier's 100.64.0.0/10) and point-to-point
  links (ppp, wwan, VPN tunnels) do not count as LAN;
- ``[firewall] allow`` (allow4/allow6): more addresses or networks, SSH (port 22) only;
- the SSH session that runs ``firewall apply`` (session4/session6: address . port), so the
  technician who loads the table is never locked out: its address and the sshd port it is
  connected to, read on the user's side (SSH_CONNECTION, SSH_CLIENT, ...) and part of the
  previewed ruleset, so the digest covers it. It stays until the next ``firewall apply`` replaces
  the table (the sync service leaves it alone); ``[firewall] allow`` keeps an address for good.

It refuses the rest on those ports with a TCP reset (at most RESET_RATE of them; beyond it,
during a scan, silence): a stranger learns "closed" at once, so ``security.outsider``'s port
checker gives its verdict in one round trip instead of waiting out a silence, and a peer whose
new address the table does not know yet is told so at once (the advisor names this table for a
refusal from a peer's address that is not the one the table holds). docs/SECURITY.md weighs a
reset against a silence. Nothing outside that table is read or changed.

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
from rosnet_tui.core.addresses import KIND_WORDS, address_kind, parse_ip
from rosnet_tui.core.config.settings_model import PORT_MAX, PORT_MIN, Settings, validate_network
from rosnet_tui.core.exposure import nft_text
from rosnet_tui.core.files import privilege
from rosnet_tui.core.files import undo_journal as uj
from rosnet_tui.core.files.managed_text import ManagedFileError
from rosnet_tui.core.net.netinfo import collapse, lan_networks
from rosnet_tui.core.ssh.origin import SSH_PORT, Session, SessionError, detect_session

FAMILY = "inet"
NAME = "rosnet_tui"
TABLE = f"{FAMILY} {NAME}"
SET4, SET6 = "peers4", "peers6"
LAN4, LAN6 = "lan4", "lan6"
ALLOW4, ALLOW6 = "allow4", "allow6"
SESSION4, SESSION6 = "session4", "session6"
SET_NAMES = (SET4, SET6, LAN4, LAN6, ALLOW4, ALLOW6, SESSION4, SESSION6)
CHAIN = "input"
RESET_RATE = "limit rate 20/second burst 40 packets"   # resets to strangers; beyond: dropped
PRIORITY = -10            # before the distribution's filter (priority 0)
KIND = "nft_table"        # the journal entry's kind (managed_file's undo dispatches on it)
NFT_TIMEOUT_S = 10.0
LABEL = "firewall: peers only on the forwarded ports"

MODES = ("mtls", "firewall", "none")
SESSION_STAYS = ("until the next `rosnet-tui firewall apply` replaces the table; to keep it for "
                 "good, add it to [firewall] allow")


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
        kind = address_kind(ip)
        if kind == "invalid":
            problems.append((f"peers[{i}] ({p.name})", f"'{ip[:40]}' is not an IP address"))
            continue
        if kind in ("unspecified", "multicast", "broadcast", "loopback"):
            problems.append((f"peers[{i}] ({p.name})", f"{ip} cannot be a peer's address "
                             f"({KIND_WORDS[kind]})"))
            continue
        a = str(parse_ip(ip))
        if a not in out:
            out.append(a)
    if not settings.peers:
        problems.append(("peers", "no peers: the table would shut everyone out"))
    if problems:
        raise FirewallSettingsError(problems)
    return out


def allow_networks(settings: Settings) -> list[str]:
    """[firewall] allow, merged; refuses (FirewallSettingsError) an entry that is no address or
    network (the settings loader refuses those already; settings made in code may hold one)."""
    problems = [(f"firewall.allow[{i}]", why) for i, e in enumerate(settings.firewall.allow)
                if (why := validate_network(e))]
    if problems:
        raise FirewallSettingsError(problems)
    return collapse([e.strip() for e in settings.firewall.allow])


# --------------------------------------------------------------------------- who gets in
@dataclass
class Admission:
    """Who the table lets in on the forwarded ports (besides loopback and replies)."""

    peers: list[str]                              # addresses: every forwarded port
    lan: list[str] = field(default_factory=list)  # networks: every forwarded port
    allow: list[str] = field(default_factory=list)  # addresses/networks: SSH (port 22)
    sessions: list[Session] = field(default_factory=list)  # address . port: that port


def _within(addr: str, entries: list[str]) -> str:
    a = ipaddress.ip_address(addr)
    for e in entries:
        net = ipaddress.ip_interface(e).network       # 10.0.0.1/8 is the network 10.0.0.0/8
        if a.version == net.version and a in net:
            return e
    return ""


def admitted(adm: Admission, address: str, port: int = SSH_PORT) -> str:
    """Why *address* gets in on TCP *port* under *adm* ("": it does not)."""
    try:
        a = ipaddress.ip_address(address)
    except ValueError:
        return ""
    if address_kind(str(a)) == "loopback":
        return "loopback"
    if str(a) in adm.peers:
        return "a peer"
    net = _within(str(a), adm.lan)
    if net:
        return f"this machine's LAN ({net})"
    net = _within(str(a), adm.allow)
    if net and port == SSH_PORT:
        return f"[firewall] allow ({net})"
    if any(x.address == str(a) and x.port == port for x in adm.sessions):
        return "the SSH session that loaded the table"
    return ""


def split_families(addresses: list[str]) -> tuple[list[str], list[str]]:
    """(IPv4, IPv6) of addresses, networks and set elements ("address . port")."""
    v4 = [a for a in addresses if ipaddress.ip_interface(a.partition(" ")[0]).version == 4]
    return v4, [a for a in addresses if a not in v4]


def _set(name: str, kind: str, elements: list[str], interval: bool = False) -> list[str]:
    return [f"\tset {name} {{", f"\t\ttype {kind}", *(["\t\tflags interval"] if interval else []),
            *([f"\t\telements = {{ {', '.join(elements)} }}"] if elements else []), "\t}"]


def render_ruleset(settings: Settings, adm: Admission) -> str:
    """The table as nft reads it (also what `firewall show` prints)."""
    p4, p6 = split_families(adm.peers)
    l4, l6 = split_families(adm.lan)
    a4, a6 = split_families(adm.allow)
    s4, s6 = split_families([x.element for x in adm.sessions])
    ports = ", ".join(forwarded_ports(settings))
    lines = [
        f"table {TABLE} {{",
        *_set(SET4, "ipv4_addr", p4), *_set(SET6, "ipv6_addr", p6),
        *_set(LAN4, "ipv4_addr", l4, True), *_set(LAN6, "ipv6_addr", l6, True),
        *_set(ALLOW4, "ipv4_addr", a4, True), *_set(ALLOW6, "ipv6_addr", a6, True),
        *_set(SESSION4, "ipv4_addr . inet_service", s4),
        *_set(SESSION6, "ipv6_addr . inet_service", s6),
        f"\tchain {CHAIN} {{",
        f"\t\ttype filter hook input priority filter - {-PRIORITY}; policy accept;",
        '\t\tiif "lo" accept',
        "\t\tct state established,related accept",
        f"\t\ttcp dport {{ {ports} }} ip saddr @{SET4} accept",
        f"\t\ttcp dport {{ {ports} }} ip6 saddr @{SET6} accept",
        f"\t\ttcp dport {{ {ports} }} ip saddr @{LAN4} accept",
        f"\t\ttcp dport {{ {ports} }} ip6 saddr @{LAN6} accept",
        f"\t\ttcp dport {SSH_PORT} ip saddr @{ALLOW4} accept",
        f"\t\ttcp dport {SSH_PORT} ip6 saddr @{ALLOW6} accept",
        f"\t\tip saddr . tcp dport @{SESSION4} accept",
        f"\t\tip6 saddr . tcp dport @{SESSION6} accept",
    ]
    lines += [f"\t\ttcp dport {p} accept" for p in open_ports(settings)]
    lines += [f"\t\ttcp dport {{ {ports} }} {RESET_RATE} reject with tcp reset",
              f"\t\ttcp dport {{ {ports} }} drop", "\t}", "}"]
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


def _elem_text(e: object) -> str:
    """One set element of nft's JSON listing as the ruleset writes it."""
    if isinstance(e, (str, int)):
        return str(e)
    if isinstance(e, dict):
        if "elem" in e and isinstance(e["elem"], dict):        # an element with options
            return _elem_text(e["elem"].get("val"))
        p = e.get("prefix")
        if isinstance(p, dict):
            return f"{p.get('addr')}/{p.get('len')}"
        c = e.get("concat")
        if isinstance(c, list):
            return " . ".join(_elem_text(x) for x in c)
        r = e.get("range")
        if isinstance(r, list) and len(r) == 2:
            return f"{_elem_text(r[0])}-{_elem_text(r[1])}"
    return ""


def current_sets() -> dict[str, list[str]] | None:
    """Each set of our table now and its elements (sorted), or None when our table is not
    loaded."""
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
    out: dict[str, list[str]] = {}
    for it in items:
        s = it.get("set") if isinstance(it, dict) else None
        if isinstance(s, dict) and isinstance(s.get("name"), str):
            elems = s.get("elem")
            texts = (_elem_text(e) for e in (elems if isinstance(elems, list) else []))
            out[s["name"]] = sorted(t for t in texts if t)
    return out


def current_allowed() -> list[str] | None:
    """The peers' addresses in our sets now, or None when our table is not loaded."""
    sets = current_sets()
    if sets is None:
        return None
    return sorted(sets.get(SET4, []) + sets.get(SET6, []))


def loaded_admission(sets: dict[str, list[str]]) -> Admission:
    """Who the loaded table lets in, from its sets (current_sets)."""
    sessions = []
    for e in sets.get(SESSION4, []) + sets.get(SESSION6, []):
        addr, _, port = e.partition(" . ")
        if port.isdigit():
            sessions.append(Session(addr, int(port), "the loaded table"))
    return Admission(peers=sorted(sets.get(SET4, []) + sets.get(SET6, [])),
                     lan=sets.get(LAN4, []) + sets.get(LAN6, []),
                     allow=sets.get(ALLOW4, []) + sets.get(ALLOW6, []), sessions=sessions)


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
    addresses: list[str]         # the peers'
    readable: bool = True        # False: this user could not read the current table
    notes: list[str] = field(default_factory=list)   # `who` first, then the rest
    session: Session | None = None   # the SSH session running this (kept in, or already in)
    session_in: str = ""             # why that session gets in without an entry of its own
    who: list[str] = field(default_factory=list)     # who gets in (who_gets_in)

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


def admission(settings: Settings, profile: str | None = None,
              session: Session | None = None) -> tuple[Admission, str]:
    """Who the table for *settings* lets in, with *session* kept in on its sshd port unless it
    gets in already; and why it does ("" when it got an entry of its own, or there is none)."""
    adm = Admission(peers=allowed_addresses(settings, profile), lan=lan_networks(),
                    allow=allow_networks(settings))
    why = admitted(adm, session.address, session.port) if session else ""
    if session is not None and not why:
        adm.sessions.append(session)
    return adm, why


def who_gets_in(settings: Settings, adm: Admission, profile: str | None = None,
                session: Session | None = None, session_in: str = "") -> list[str]:
    """The preview's words for *adm*: who reaches the forwarded ports, and for how long."""
    profile = profile or settings.this.profile
    names = {peer_address(settings, p.name, profile): p.name for p in settings.peers}
    peers = ", ".join(f"{a} ({names[a]})" if a in names else a for a in adm.peers) or "none"
    out = [f"On TCP {', '.join(forwarded_ports(settings))} only these get in "
           "(the rest is refused there):",
           f"  the peers ({profile} profile; SSH and ROS): {peers}",
           f"  this machine's LAN (SSH and ROS): {', '.join(adm.lan) or 'none found'}",
           f"  [firewall] allow (SSH): {', '.join(adm.allow) or 'none'}"]
    if session is None:
        out.append("  no SSH session runs this (no SSH_CONNECTION): no other address is kept in")
    elif session_in:
        out.append(f"  this SSH session, {session.address}: gets in already ({session_in})")
    else:
        out.append(f"  this SSH session, {session.address} (to sshd port {session.port}; "
                   f"{session.source}): SSH only, {SESSION_STAYS}")
    out.append("  loopback, and replies to this machine's own connections")
    return out


def preview(settings: Settings, profile: str | None = None, *, session: Session | None = None,
            detect: bool = True) -> FirewallPreview:
    """The table for *settings*, and what is loaded now. *session*: the SSH session to keep in
    (default, with *detect*: the one this process runs in, detect_session)."""
    if session is None and detect:
        session = detect_session()
    adm, session_in = admission(settings, profile, session)
    ruleset = render_ruleset(settings, adm)
    who = who_gets_in(settings, adm, profile, session, session_in)
    notes = list(who)
    if not wanted(settings):
        notes.append(f"[ros] security is '{settings.ros.security}'"
                     + (" (ROS 2: mTLS protects the Zenoh port)" if settings.ros2 else "")
                     + "; the table is written because you asked for it")
    try:
        current, readable = current_ruleset(), True
    except FirewallError as exc:
        current, readable = None, False
        notes.append(f"the table loaded now is not shown: {exc}")
    return FirewallPreview(ruleset, current, adm.peers, readable, notes, session, session_in,
                           who)


def session_args(session: Session | None) -> list[str]:
    """The arguments that hand *session* to the privileged re-run (sudo drops SSH_CONNECTION,
    and root must build the very ruleset previewed)."""
    if session is None:
        return ["--session-ip", "none"]
    return ["--session-ip", session.address, "--session-port", str(session.port)]


def apply_command(*, config: Path, profile: str, digest: str, state_dir: Path,
                  session: Session | None) -> list[str]:
    """The exact sudo command that loads the previewed table (and nothing else)."""
    def ab(p: Path) -> str:
        return str(Path(p).expanduser().absolute())
    return privilege.sudo_argv(["--config", ab(config), "firewall", "apply", "--profile", profile,
                                "--expect-digest", digest, *session_args(session), "--yes",
                                "--state-dir", ab(state_dir), "--no-checks"])


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
        why = nft_text.our_table_problem(before, TABLE, CHAIN, set(SET_NAMES))
        if why:
            raise FirewallError(f"the journal's copy is not our table {TABLE} alone ({why}); "
                                "nothing was loaded")
        load(transaction_text(before))
        return f"the firewall table {TABLE}: put back as it was before"
    if current_ruleset() is not None:
        load(f"delete table {TABLE}\n")
    return f"the firewall table {TABLE}: removed (rosnet-tui created it)"


def only_our_table(text: str) -> bool:
    """True when *text* defines our table and nothing else (a journal copy is checked before
    root loads it): read as nft reads it (:mod:`.nft_text`), not line by line."""
    return nft_text.our_table_problem(text, TABLE, CHAIN, set(SET_NAMES)) is None


def undo_records(records: list[dict], force: bool = False) -> list[str]:
    """Reverse recorded firewall changes (the undo journal's handler for KIND)."""
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


def sets_in_text(text: str) -> dict[str, list[str]]:
    """Each set of a table as nft lists it (or as render_ruleset writes it) and its elements."""
    out: dict[str, list[str]] = {}
    for m in re.finditer(r"\bset (\w+) \{(.*?)\n\s*\}", text, re.S):
        el = re.search(r"elements = \{([^}]*)\}", m.group(2))
        items = el.group(1).split(",") if el else []
        out[m.group(1)] = sorted(" ".join(e.split()) for e in items if e.strip())
    return out


def locks_out_this_session(ruleset: str) -> str:
    """Words for the SSH session running this when *ruleset* would not let it in again ("":
    it would, or this is no SSH session)."""
    try:
        session = detect_session()
    except SessionError:
        return ""
    if session is None or admitted(loaded_admission(sets_in_text(ruleset)), session.address,
                                   session.port):
        return ""
    return (f"it does not let in this SSH session's address, {session.address}: once this "
            "session drops, SSH from there is refused (add it to [firewall] allow, then "
            "rosnet-tui firewall apply)")


def describe(record: dict) -> str:
    """What undoing *record* does to the firewall, and whom it would shut out."""
    before = record.get("before")
    if not before:
        return f"the firewall table {TABLE}: removed (rosnet-tui created it)"
    warning = locks_out_this_session(before) if isinstance(before, str) else ""
    return f"the firewall table {TABLE}: put back as it was before" + (
        f"; {warning}" if warning else "")


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
