"""The forwards this component needs, made on its modem with consent, recorded, renewed, undone.

What is needed comes from :func:`rosnet_tui.core.exposure.forwarding.required_ports` (the one answer for
the Router step): under ROS 2 the master's ``zenoh_port`` (one TCP port), plus the test port for a
short while so the checks can prove the path; a ROS 2 member needs nothing; ROS 1 needs the whole
range 1024-65000, which no protocol can map (each request maps one port), so it is refused with
the manual and DMZ paths instead.
"""

from __future__ import annotations

import contextlib
import copy
import functools
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

from rosnet_tui.core.addresses import KIND_WORDS, PUBLIC_KINDS, address_kind
from rosnet_tui.core.config.settings_model import Settings
from rosnet_tui.core.exposure.forwarding import required_ports
from rosnet_tui.core.upnp import journal
from rosnet_tui.core.upnp.modem import LEASE_MAX_S, LEASE_MIN_S, Forward, Modem, find_modem
from rosnet_tui.core.upnp.wire import ModemError, Refused, label

LEASE_S = 24 * 3600        # a forward we make lasts a day unless renewed (the sync service does)
TEST_LEASE_S = 15 * 60     # the test port: only while the checks run
DESCRIPTION = "rosnet-tui"


@dataclass(frozen=True)
class Wanted:
    protocol: str
    port: int
    lease_s: int
    why: str
    temporary: bool = False   # the test port: not renewed, left to expire


@dataclass
class Needs:
    forwards: list[Wanted] = field(default_factory=list)
    refusal: str = ""         # why nothing can be mapped for these settings (ROS 1: a range)
    note: str = ""            # why nothing needs to be mapped (a ROS 2 member, a relay)


def range_refusal(settings: Settings, first: int, last: int) -> str:
    ip = settings.this.local_ip or "this machine's local IP"
    return (f"ROS 1 needs TCP {first}-{last} forwarded (every node listens on a port of its own), "
            "and no protocol maps a range: UPnP IGD, NAT-PMP and PCP each forward one port per "
            "request. Do it by hand in the modem's web page: forward TCP "
            f"{first}-{last} to {ip} (often under Firewall, NAT, Port forwarding or Virtual "
            f"server), or make {ip} the DMZ host; reserve {ip} for this machine by DHCP. ROS 2 "
            "over rmw_zenoh needs a single port, which rosnet-tui can forward for you.")


def needs(settings: Settings, *, lease_s: int = LEASE_S, test_port: bool = True) -> Needs:
    """The forwards *settings* call for on this component's modem."""
    out = Needs()
    for p in required_ports(settings):
        if p.first != p.last:
            out.refusal = range_refusal(settings, p.first, p.last)
            return Needs(refusal=out.refusal)
        out.forwards.append(Wanted(p.protocol, p.first, lease_s, p.why))
    if not out.forwards:
        who = settings.this.name or "this component"
        out.note = (f"under the relay every router connects out to {settings.relay.host}, "
                    f"{who}'s too, so its modem needs no forward" if settings.relayed else
                    f"{who} is a ROS 2 member: its router connects out to the master's, so "
                    "its modem needs no forward")
        return out
    tp = settings.probe.port
    if test_port and all(w.port != tp for w in out.forwards):
        out.forwards.append(Wanted("TCP", tp, TEST_LEASE_S, "the test port, while the checks "
                                   "run (expires by itself)", temporary=True))
    return out


def description(settings: Settings, w: Wanted) -> str:
    what = "test port" if w.temporary else ("Zenoh router" if settings.ros2 else "ROS")
    if not w.temporary and settings.hosts_rosbridge and w.port == settings.rosbridge.port:
        what = "rosbridge"
    return f"{DESCRIPTION} {settings.this.name or ''} {what}".replace("  ", " ")[:63]


def is_ours(f: Forward, modem: Modem, recorded: set[tuple[str, int]]) -> bool:
    return f.internal_client == modem.local_ip and (
        (f.protocol, f.external_port) in recorded or f.description.startswith(DESCRIPTION))


def recorded_here(modem: Modem, state_dir: Path | None) -> dict[tuple[str, int], dict]:
    """Our live records of forwards on this very modem, by (protocol, port)."""
    out = {}
    for _e, m in journal.live(state_dir):
        if modem.same_as(m.get("modem") or {})[0] and m.get("internal_client") == modem.local_ip:
            out[(str(m.get("protocol")), int(m.get("port", 0)))] = m
    return out


# --------------------------------------------------------------------------- explanations
def wan_kind(external_ip: str | None) -> str:
    """'none', 'shared', 'private', 'public' or 'unknown' (None: the modem was not asked)."""
    if external_ip is None:
        return "unknown"
    if not external_ip:
        return "none"
    kind = address_kind(external_ip)
    if kind in PUBLIC_KINDS:
        return "public"
    if kind in ("shared", "private"):
        return kind
    return "unknown" if kind == "invalid" else "none"   # 0.0.0.0, loopback, multicast, ...


def wan_words(external_ip: str | None) -> str:
    none = "reports no public address of its own"
    if external_ip and wan_kind(external_ip) == "none":
        none = f"reports {external_ip} ({KIND_WORDS[address_kind(external_ip)]}): no public address"
    return {"none": none,
            "shared": f"reports {external_ip}, an address of the carriers' shared range "
                      "100.64.0.0/10, as its own",
            "private": f"reports the private address {external_ip} as its internet side"
            }.get(wan_kind(external_ip), f"reports {external_ip}")


CGNAT_ACTIONS = ("Under ROS 2 any component with a public address can be the master (the hub the "
                 "routers link to); or run a Zenoh router on a small public server; or ask the "
                 "provider for a public IP on this line (its networking department).")


def explain_refusal(modem: Modem, exc: Refused, w: Wanted) -> tuple[str, str]:
    """(kind, words) for a modem's refusal of *w*: kind is cgnat, conflict, secure_mode,
    not_allowed or refused."""
    own = f"the modem's own words: {label(exc.protocol)} error {exc.code} ({exc.name})"
    if wan_kind(modem.external_ip) in ("none", "shared", "private") and \
            (exc.protocol, exc.code) in (("upnp", 501), ("upnp", 606), ("natpmp", 3),
                                         ("natpmp", 2), ("pcp", 8), ("pcp", 7)):
        return "cgnat", (f"carrier-grade NAT: the modem {wan_words(modem.external_ip)} and "
                         f"refuses forwards ({own}). The provider shares one public address "
                         "among many customers, so no forward on this modem can be reached from "
                         f"the internet. {CGNAT_ACTIONS}")
    if exc.code == 718 or exc.name == "PortTaken" or (exc.protocol == "pcp" and exc.code == 11):
        holder = None
        if modem.igd is not None:
            with contextlib.suppress(ModemError):
                holder = modem.forward_of(w.protocol, w.port, time.monotonic() + 2.0)
        if holder is not None and holder.internal_client != modem.local_ip:
            return "conflict", (f"{w.protocol} {w.port} is already forwarded to "
                                f"{holder.internal_client}:{holder.internal_port}, another machine "
                                f"on this LAN ('{holder.description}'); {own}. Remove that "
                                "forward in the modem's page, or choose another port in the "
                                "settings for every component")
        if exc.code == 718 and holder is None:
            return "secure_mode", (f"the modem's secure mode refused: it lets a machine forward "
                                   f"ports only to itself, and it does not see this request as "
                                   f"coming from {modem.local_ip} ({own})")
        return "conflict", (f"{w.protocol} {w.port} is taken on the modem: {exc.words} ({own}). "
                            "Choose another port, or free it in the modem's page")
    if exc.code == 606 or (exc.protocol == "pcp" and exc.code == 2) or \
            (exc.protocol == "natpmp" and exc.code == 2):
        return "not_allowed", (f"the modem's rules do not allow forwarding {w.protocol} {w.port} "
                               f"to {modem.local_ip} ({own}): allow it in the modem's UPnP "
                               "settings, or forward it by hand in its page")
    return "refused", f"the modem refused {w.protocol} {w.port}: {exc.words} ({own})"


class MapRefused(Exception):
    """The modem refused (or the settings call for a range): nothing is left changed."""

    def __init__(self, kind: str, words: str) -> None:
        self.kind, self.words = kind, words
        super().__init__(words)

    def told(self) -> str:
        """The sentence a person is shown (the CLI and the map screen say the same)."""
        return f"refused, nothing was changed: {self.words}"


class MapUnconfirmed(MapRefused):
    """A forward failed and the roll-back of those made before it was not confirmed by the
    modem: they may still be in place. Their journal entry is kept (``entry_id``); the words say
    what may still be forwarded and how to remove it."""

    def __init__(self, cause: str, left: list[str], entry_id: str) -> None:
        self.left, self.entry_id = left, entry_id
        super().__init__("unconfirmed", (
            f"{cause}. Taking back what was already forwarded was not confirmed by the modem, so "
            f"it may still forward: {'; '.join(left)}. It stays recorded: remove it with "
            "`rosnet-tui router unmap` (or `rosnet-tui undo`), or in the modem's page; its "
            "lease ends it in any case"))

    def told(self) -> str:
        return self.words            # something may still be forwarded: never "nothing changed"


# --------------------------------------------------------------------------- mapping
@dataclass
class MapResult:
    made: list[dict]          # the records of the forwards made or refreshed
    entry_id: str | None      # the journal entry (None: only refreshed)
    refreshed: list[int]      # ports already ours, whose lease was renewed
    warnings: list[str]


def check_conflicts(modem: Modem, wanted: list[Wanted]) -> None:
    """Refuse before changing anything when another machine holds one of the ports (UPnP)."""
    if modem.igd is None:
        return
    for w in wanted:
        f = modem.forward_of(w.protocol, w.port, time.monotonic() + 2.0)
        if f is not None and f.internal_client != modem.local_ip:
            raise MapRefused("conflict", (
                f"{w.protocol} {w.port} is already forwarded to {f.internal_client}:"
                f"{f.internal_port}, another machine on this LAN ('{f.description}'). Nothing was "
                "changed. Remove that forward in the modem's page, or choose another port in the "
                "settings of every component"))


def map_forwards(settings: Settings, modem: Modem, wanted: list[Wanted], *,
                 state_dir: Path | None = None, via: str | None = None,
                 timeout: float = 8.0) -> MapResult:
    """Make (or refresh) *wanted* on *modem*, recorded for undo first; all or nothing."""
    via = via or modem.protocol
    if via not in modem.protocols:
        raise MapRefused("usage", f"the modem does not speak {label(via)} (it speaks "
                                  f"{', '.join(label(p) for p in modem.protocols)})")
    deadline = time.monotonic() + timeout
    check_conflicts(modem, wanted)
    ours = recorded_here(modem, state_dir)
    warnings = []
    kind = wan_kind(modem.external_ip)
    if kind == "private":
        warnings.append(f"the modem {wan_words(modem.external_ip)}: another router in front of "
                        "it must forward the same port to it (double NAT)")
    records = []
    for w in wanted:
        rec = {"protocol": w.protocol, "port": w.port, "internal_client": modem.local_ip,
               "via": via, "lease_s": w.lease_s, "temporary": w.temporary, "why": w.why,
               "description": description(settings, w), "modem": modem.identity(via),
               "state": "planned", "made_at": 0, "renewed_at": 0}
        old = ours.get((w.protocol, w.port))
        if old is not None and old.get("via") == via and old.get("nonce"):
            rec["nonce"] = old["nonce"]
        records.append(rec)
    fresh = [r for r in records if (r["protocol"], r["port"]) not in ours]
    what = ", ".join(f"{r['protocol']} {r['port']}" for r in fresh)
    entry = (journal.new_entry(f"forward {what} on the modem {modem.gateway}", fresh, state_dir)
             if fresh else None)
    made: list[dict] = []
    refreshed: list[int] = []
    try:
        for rec in records:
            w = next(x for x in wanted if x.port == rec["port"] and x.protocol == rec["protocol"])
            nonce = bytes.fromhex(rec["nonce"]) if rec.get("nonce") else None
            try:
                got = modem.add(w.protocol, w.port, w.lease_s, rec["description"],
                                max(deadline, time.monotonic() + 1.0), via=via, nonce=nonce)
            except Refused as exc:
                kind, words = explain_refusal(modem, exc, w)
                raise MapRefused(kind, words) from exc
            now = time.time()
            key = (rec["protocol"], rec["port"])
            if key in ours:
                ours[key].update(lease_s=got["lease_s"], renewed_at=now)
                refreshed.append(rec["port"])
            else:
                target = next(m for m in entry.mappings if m["port"] == rec["port"]
                              and m["protocol"] == rec["protocol"]) if entry else rec
                target.update(got, state="made", made_at=now, renewed_at=now)
                made.append(target)
                if entry is not None:  # at once: a crash now still leaves it undoable
                    journal.save(entry, state_dir)
    except BaseException as exc:
        if entry is None:
            raise
        left = roll_back(modem, made)
        if not left:
            journal.close(entry, "rolled back: the modem refused a forward", state_dir)
            raise
        journal.save(entry, state_dir)   # the entry stays: undo and unmap still find them
        if isinstance(exc, (MapRefused, ModemError)):
            raise MapUnconfirmed(str(exc), left, entry.id) from exc
        raise
    if entry is not None:
        journal.save(entry, state_dir)
    if refreshed:
        _save_refreshed(ours.values(), state_dir)
    return MapResult(made, entry.id if entry else None, refreshed, warnings)


def roll_back(modem: Modem, made: list[dict]) -> list[str]:
    """Take back the forwards *made*; what the modem did not confirm it removed, in words (their
    records stay "made")."""
    left = []
    for m in made:
        try:
            modem.remove(m, time.monotonic() + 2.0)
        except (ModemError, ValueError) as exc:
            left.append(f"{journal.describe(m)} (the modem: {exc})")
            continue
        m["state"] = "removed"
    return left


def _save_refreshed(records, state_dir: Path | None) -> None:
    """Write back renewed leases (the records live inside their journal entries)."""
    by_id: dict[str, object] = {}
    wanted = {(r["protocol"], r["port"], r.get("made_at")): r for r in records}
    for e, m in journal.live(state_dir):
        key = (m.get("protocol"), m.get("port"), m.get("made_at"))
        if key in wanted:
            m.update(lease_s=wanted[key]["lease_s"], renewed_at=wanted[key]["renewed_at"])
            by_id[e.id] = e
    for e in by_id.values():
        journal.save(e, state_dir)  # type: ignore[arg-type]


def unmap_ours(*, state_dir: Path | None = None, force: bool = False,
               timeout: float = 8.0) -> list[str]:
    """Remove every live forward we recorded (ours only), closing their journal entries."""
    said: list[str] = []
    entries = {}
    for e, _m in journal.live(state_dir):
        entries[e.id] = e
    for e in entries.values():
        said += journal.remove_recorded(e.mappings, force=force, timeout=timeout)
        if all(m.get("state") != "made" for m in e.mappings):
            journal.close(e, "removed by router unmap", state_dir)
        else:
            journal.save(e, state_dir)
    return said


def renew_due(settings: Settings, *, state_dir: Path | None = None, now: float | None = None,
              timeout: float = 4.0, modem: Modem | None = None) -> tuple[list[str], float | None]:
    """Renew our lasting forwards whose lease is half gone; (what was done, seconds until the
    next renewal is due, None when nothing is recorded)."""
    now = time.time() if now is None else now
    lasting = [(e, m) for e, m in journal.live(state_dir) if not m.get("temporary")]
    if not lasting:
        return [], None
    due = [(e, m) for e, m in lasting
           if now >= float(m.get("renewed_at", 0)) + int(m.get("lease_s", LEASE_S)) / 2]
    said: list[str] = []
    if due:
        notes: list[str] = []
        modem = modem or find_modem(min(2.0, timeout / 2), notes=notes)
        changed = {}
        for e, m in due:
            if modem is None:
                said.append(f"cannot renew {journal.describe(m)}: no modem answers")
                continue
            same, why = modem.same_as(m.get("modem") or {})
            if not same or modem.local_ip != m.get("internal_client"):
                said.append(f"not renewing {journal.describe(m)}: "
                            f"{why or 'this machine has another address now'}")
                continue
            lease = max(LEASE_MIN_S, min(int(m.get("lease_s") or LEASE_S), LEASE_MAX_S))
            try:
                got = modem.add(m["protocol"], int(m["port"]), lease,
                                str(m.get("description") or DESCRIPTION),
                                time.monotonic() + timeout, via=m.get("via"),
                                nonce=bytes.fromhex(m["nonce"]) if m.get("nonce") else None)
            except (ModemError, ValueError) as exc:
                said.append(f"could not renew {journal.describe(m)}: {exc}")
                continue
            m.update(lease_s=got["lease_s"], renewed_at=now)
            changed[e.id] = e
            said.append(f"renewed {journal.describe(m)} for {got['lease_s']} s")
        for e in changed.values():
            journal.save(e, state_dir)
    left = [float(m.get("renewed_at", 0)) + int(m.get("lease_s", LEASE_S)) / 2 - now
            for _e, m in journal.live(state_dir) if not m.get("temporary")]
    return said, (max(min(left), 60.0) if left else None)


# --------------------------------------------------------------------------- the preview
def lease_words(s: int) -> str:
    if s >= 3600 and s % 3600 == 0:
        return f"{s // 3600} h"
    return f"{s // 60} min" if s >= 60 and s % 60 == 0 else f"{s} s"


@dataclass
class MapPreview:
    """What `router map` (and the wizard's m) would ask the modem, before asking anything."""

    need: Needs
    modem: Modem | None = None
    via: str = ""
    notes: list[str] = field(default_factory=list)   # what was tried to find the modem
    lines: list[str] = field(default_factory=list)   # the modem, then each forward to ask for
    warnings: list[str] = field(default_factory=list)
    blocked: str = ""        # why nothing can be asked ("" when it can)


def modem_lines(modem: Modem) -> list[str]:
    out = [f"Modem: {modem.describe()}."]
    if modem.external_ip is not None:
        kind = wan_kind(modem.external_ip)
        out.append(f"  external address: {modem.external_ip or '(none reported)'}"
                   + ("" if kind == "public" else f" - it {wan_words(modem.external_ip)}"))
    if modem.mac:
        out.append(f"  MAC address: {modem.mac}")
    return out


def preview(settings: Settings, *, state_dir: Path | None = None, timeout: float = 3.0,
            lease_s: int = LEASE_S, test_port: bool = True, via: str = "auto") -> MapPreview:
    """Find the modem and say what would be asked of it (nothing is asked yet)."""
    out = MapPreview(needs(settings, lease_s=lease_s, test_port=test_port))
    if out.need.refusal:
        out.blocked = out.need.refusal
        return out
    if not out.need.forwards:
        out.blocked = f"Nothing to forward: {out.need.note}."
        return out
    out.modem = find_modem(timeout, notes=out.notes)
    if out.modem is None:
        out.blocked = ("No modem answered UPnP IGD, PCP or NAT-PMP (the default gateway was "
                       "asked): forward the port by hand in the modem's web page, or switch UPnP "
                       "or NAT-PMP on there if it has them.")
        return out
    m = out.modem
    out.via = m.protocol if via == "auto" else via
    out.lines = modem_lines(m)
    if out.via not in m.protocols:
        out.blocked = (f"The modem does not answer {label(out.via)} (it speaks "
                       f"{', '.join(label(p) for p in m.protocols)}).")
        return out
    ours = recorded_here(m, state_dir)
    out.lines.append(f"Forwards to ask for, over {label(out.via)}:")
    for w in out.need.forwards:
        again = " (already ours: the lease is renewed)" if (w.protocol, w.port) in ours else ""
        out.lines.append(f"  {w.protocol} {w.port} -> {m.local_ip}:{w.port}  lease "
                         f"{lease_words(w.lease_s)}  {w.why}{again}")
    if settings.this.local_ip and settings.this.local_ip != m.local_ip:
        out.warnings.append(f"the settings name {settings.this.local_ip} as this machine's local "
                            f"IP, but it reaches the modem from {m.local_ip}: the forward goes "
                            f"to {m.local_ip}")
    if wan_kind(m.external_ip) in ("none", "shared"):
        out.warnings.append(f"the modem {wan_words(m.external_ip)}: a sign of carrier-grade NAT; "
                            "it will probably refuse")
    return out


def card_lines(data: dict | None) -> list[str]:
    """The Router step's words for router.upnp's data (the modem's own word), or nothing."""
    if not data or not data.get("protocols"):
        return []
    speaks = " and ".join(label(str(p)) for p in data["protocols"])
    out = [f"The modem {data.get('gateway')} speaks {speaks}."]
    ip = data.get("external_ip")
    if ip is not None:
        out.append(f"It says its external address is {ip or '(none)'}"
                   + ("" if data.get("wan") in ("public", "unknown") else
                      f": {wan_words(ip)}") + ".")
    for f in data.get("forwards") or []:
        out.append(f"It forwards {f.get('protocol')} {f.get('external_port')} here "
                   f"('{f.get('description')}').")
    if data.get("missing") and not data.get("cgnat"):
        ports = ", ".join(f"TCP {p}" for p in data["missing"])
        out.append(f"It can forward {ports} for you: press m (or `rosnet-tui router map`).")
    return out


class Renewer:
    """The sync service's part: renew our forwards' leases when due, on a thread of its own
    while the service runs (its loop never waits on a modem), in line for a single round."""

    def __init__(self, state_dir: Path, log) -> None:
        self.state_dir = state_dir
        self.log = log
        self.next_at = 0.0                      # time.monotonic() of the next look
        self._thread: threading.Thread | None = None

    def tick(self, settings: Settings | None, *, background: bool) -> None:
        if settings is None or time.monotonic() < self.next_at or \
                (self._thread is not None and self._thread.is_alive()):
            return
        self.next_at = float("inf")
        work = functools.partial(self._renew, copy.deepcopy(settings))
        if not background:
            work()
            return
        self._thread = threading.Thread(target=work, name="forward renewal", daemon=True)
        self._thread.start()

    def _renew(self, settings: Settings) -> None:
        try:
            said, next_in = renew_due(settings, state_dir=self.state_dir)
        except Exception as exc:  # noqa: BLE001 - the modem's trouble must not stop the sync
            said, next_in = [f"renewing the forwards failed: {exc}"], 300.0
        for line in said:
            self.log.info("modem: %s", line)
        self.next_at = time.monotonic() + (next_in if next_in is not None else 600.0)

    def unmap(self, timeout: float = 5.0) -> None:
        """Remove our forwards (the service was asked to, when it stops)."""
        if self._thread is not None:
            self._thread.join(timeout)
        try:
            for line in unmap_ours(state_dir=self.state_dir, timeout=timeout):
                self.log.info("modem: %s", line)
        except Exception as exc:  # noqa: BLE001
            self.log.warning("modem: the forwards were not removed: %s", exc)
