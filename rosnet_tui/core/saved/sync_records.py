"""Address records: what each component publishes about itself, and how copies are judged.

One record per component: its name, local IP, public IP, role, a sequence number that grows with
every new content, a timestamp, the record format version and ``sig``, its owner's signature
(:mod:`.signing`: a record counts only when signed by the key pinned for its name); optionally
``seq_epoch``, the time
(whole seconds since 1970) at which the component started counting ``seq`` (absent: 0). A
component that lost its counter starts again at 1 with a later ``seq_epoch``. Stores (a shared
folder, DNS) hold copies that may be partial, stale or in conflict; :func:`parse_record` refuses
anything malformed (it is never applied; it raises RecordError and nothing else, whatever the
bytes) and :func:`choose_best` picks among valid copies: the highest ``(seq_epoch, seq)``, then
the newest ``timestamp``. :func:`successor_problem` says whether a record may follow the one
already applied (a lower seq is an old copy, unless a verified counter restart).
"""

from __future__ import annotations

import contextlib
import json
import math
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace
from datetime import datetime, timezone
from typing import Any

from rosnet_tui.core.addresses import KIND_WORDS, address_kind
from rosnet_tui.core.config.settings_model import ROLES, validate_ip, validate_name
from rosnet_tui.core.jsonsafe import JsonInputError, loads_bounded

RECORD_VERSION = 1
MAX_RECORD_BYTES = 4096
MAX_SEQ = 2**53                   # what a JSON number holds exactly everywhere
MAX_FUTURE_S = 24 * 3600          # a record from further in the future is refused (clock or forgery)
MAX_FUTURE_GUESS = 4102444800.0   # 2100-01-01: the span in which a number in another unit is named
MIN_TIMESTAMP = 946684800.0       # 2000-01-01: anything older is not a real clock
MAX_TIMESTAMP = 253402300799.0    # 9999-12-31T23:59:59Z: the last second datetime can show
MAX_DEPTH = 16                    # arrays/objects inside each other (a record needs 1)
_FIELDS = ("version", "name", "role", "local_ip", "public_ip", "seq", "timestamp")


class RecordError(ValueError):
    """A record that must not be used; the message says why, in a few words."""


@dataclass(frozen=True)
class Record:
    name: str
    local_ip: str
    public_ip: str
    role: str
    seq: int
    timestamp: float              # seconds since the epoch (UTC)
    version: int = RECORD_VERSION
    seq_epoch: int = 0            # when this component started counting seq (0: not said)
    sig: str = ""                 # its owner's signature (base64; core/sync/signing.py)

    # ------------------------------------------------------------------ forms
    def to_json(self) -> dict[str, Any]:
        d = {"version": self.version, "name": self.name, "role": self.role,
             "local_ip": self.local_ip, "public_ip": self.public_ip, "seq": self.seq,
             "timestamp": format_time(self.timestamp)}
        if self.seq_epoch:
            d["seq_epoch"] = self.seq_epoch
        if self.sig:
            d["sig"] = self.sig
        return d

    def to_text(self) -> str:
        """The record file's text: small, stable key order, one trailing newline."""
        return json.dumps(self.to_json(), indent=2) + "\n"

    def to_compact(self) -> str:
        return json.dumps(self.to_json(), separators=(",", ":"))

    # ------------------------------------------------------------------ comparisons
    def same_content(self, other: Record | None) -> bool:
        """Same addresses and role (seq and timestamp aside)."""
        return other is not None and (self.name, self.local_ip, self.public_ip, self.role) == (
            other.name, other.local_ip, other.public_ip, other.role)

    @property
    def rank(self) -> tuple[int, int, int]:
        return (self.seq_epoch, self.seq, millis(self.timestamp))

    def next(self, *, local_ip: str, public_ip: str, role: str,
             now: float | None = None) -> Record:
        """The record that follows this one with new content (seq + 1, fresh timestamp)."""
        return replace(self, local_ip=local_ip, public_ip=public_ip, role=role, seq=self.seq + 1,
                       timestamp=now if now is not None else time.time(), version=RECORD_VERSION,
                       sig="")

    def describe(self) -> str:
        return (f"{self.name} ({self.role}): local {self.local_ip or '?'}, "
                f"public {self.public_ip or '?'}, #{self.seq} of {format_time(self.timestamp)}")


def new_record(name: str, *, local_ip: str, public_ip: str, role: str, seq: int = 1,
               now: float | None = None, seq_epoch: int = 0) -> Record:
    """A fresh record (validated: raises RecordError when it would be refused by peers).

    A component that starts counting again (it lost its last seq) passes ``seq_epoch`` = the
    whole second it started counting, so peers that applied a higher seq of the old counter
    accept the new one."""
    rec = Record(name, local_ip, public_ip, role, seq, now if now is not None else time.time(),
                 seq_epoch=seq_epoch)
    check_record(rec)
    return rec


# --------------------------------------------------------------------------- time
def millis(ts: float) -> int:
    """A timestamp in whole milliseconds: the precision records are written and compared at."""
    return int(round(ts * 1000))


def format_time(ts: float) -> str:
    """ISO 8601 UTC with milliseconds, e.g. 2025-03-01T12:00:00.123Z."""
    secs, ms = divmod(millis(ts), 1000)
    dt = datetime.fromtimestamp(secs, tz=timezone.utc)
    return dt.strftime("%Y-%m-%dT%H:%M:%S.") + f"{ms:03d}Z"


def show_time(ts: float) -> str:
    """A timestamp for a message: ISO 8601 when datetime can show it, else the number."""
    if MIN_TIMESTAMP <= ts <= MAX_TIMESTAMP:
        with contextlib.suppress(ValueError, OverflowError, OSError):
            return format_time(ts)
    return f"{ts:.6g}"


def parse_time(value: Any) -> float:
    """Seconds since the epoch from an ISO 8601 string (UTC 'Z' or an offset) or a number of
    seconds. Raises RecordError (never anything else) for anything that is not a plausible
    time: another unit (milliseconds, as JavaScript writes), an overflow, a non-finite number."""
    if isinstance(value, bool):
        raise RecordError("timestamp must be a time, not true/false")
    if isinstance(value, (int, float)):
        try:
            ts = float(value)
        except OverflowError:
            ts = math.inf if value > 0 else -math.inf
        if math.isnan(ts):
            raise RecordError("timestamp is not a finite number")
        if ts > MAX_TIMESTAMP:
            for unit, factor in (("milliseconds", 1e3), ("microseconds", 1e6),
                                 ("nanoseconds", 1e9)):
                if MIN_TIMESTAMP * factor <= ts <= MAX_FUTURE_GUESS * factor:
                    raise RecordError(f"timestamp {ts:.6g} looks like {unit} since 1970; a "
                                      "record gives seconds, or an ISO 8601 time (...Z)")
            raise RecordError(f"timestamp {ts:.6g} is not a plausible time")
        if ts < MIN_TIMESTAMP:
            raise RecordError(f"timestamp {ts:.6g} is before the year 2000")
    elif isinstance(value, str):
        text = value.strip()
        if len(text) > 64:
            raise RecordError(f"timestamp {value[:40]!r}... is not an ISO 8601 time")
        if text.endswith(("Z", "z")):
            text = text[:-1] + "+00:00"
        try:
            dt = datetime.fromisoformat(text)
        except ValueError:
            raise RecordError(f"timestamp {value[:40]!r} is not an ISO 8601 time") from None
        if dt.tzinfo is None:
            raise RecordError(f"timestamp {value[:40]!r} has no time zone (write it in UTC, ...Z)")
        try:
            ts = dt.timestamp()
        except (OverflowError, ValueError, OSError):
            raise RecordError(f"timestamp {value[:40]!r} is not a plausible time") from None
    else:
        raise RecordError("timestamp is missing or not a time")
    if not math.isfinite(ts):
        raise RecordError("timestamp is not a finite number")
    return ts


# --------------------------------------------------------------------------- validation
def address_problem(value: str, *, public: bool = False) -> str | None:
    """Why *value* cannot be a component's address in a record (None: it can); with *public*,
    as its public address (no private or carrier-grade NAT space)."""
    why = validate_ip(value, required=True)
    if why:
        return why
    # The documentation ranges stay valid as public addresses: labs use them (see addresses).
    kind = address_kind(value)
    if public and kind in ("private", "shared"):
        return f"{value} is {KIND_WORDS[kind]}, never a public one"
    if kind in ("loopback", "link-local", "reserved"):
        return f"{value} is {KIND_WORDS[kind]}"
    return None


def check_record(rec: Record, *, now: float | None = None) -> None:
    """Raise RecordError when *rec* must not be used."""
    if rec.version != RECORD_VERSION:
        raise RecordError(f"record format version {rec.version} is not known to this rosnet-tui "
                          f"(it reads version {RECORD_VERSION})")
    why = validate_name(rec.name)
    if why:
        raise RecordError(f"name {rec.name[:40]!r}: {why}")
    if rec.role not in ROLES:
        raise RecordError(f"role {rec.role[:20]!r} is not one of {', '.join(ROLES)}")
    if not rec.local_ip and not rec.public_ip:
        raise RecordError("the record has no address at all")
    for key in ("local_ip", "public_ip"):
        value = getattr(rec, key)
        if value and (why := address_problem(value, public=key == "public_ip")):
            raise RecordError(f"{key}: {why}")
    if isinstance(rec.seq, bool) or not isinstance(rec.seq, int) or not 0 <= rec.seq <= MAX_SEQ:
        raise RecordError(f"seq must be a whole number from 0 to {MAX_SEQ}")
    now = time.time() if now is None else now
    ts = rec.timestamp
    if not isinstance(ts, (int, float)) or isinstance(ts, bool) or math.isnan(ts):
        raise RecordError("timestamp is not a finite number")
    if ts < MIN_TIMESTAMP:
        raise RecordError(f"timestamp {show_time(ts)} is before the year 2000")
    if ts > now + MAX_FUTURE_S:
        raise RecordError(f"timestamp {show_time(ts)} is more than a day in the "
                          "future (a wrong clock, or a forged record)")
    e = rec.seq_epoch
    if isinstance(e, bool) or not isinstance(e, int) or not (e == 0 or MIN_TIMESTAMP <= e
                                                             <= MAX_TIMESTAMP):
        raise RecordError("seq_epoch must be 0 or a whole number of seconds since 1970 "
                          "(from the year 2000 on)")
    if e > ts + 1:
        raise RecordError(f"seq_epoch {show_time(e)} is after the record's own timestamp "
                          f"{show_time(ts)} (counting cannot begin after it was written)")


def parse_record(data: bytes | str | Mapping[str, Any], *, expect_name: str | None = None,
                 now: float | None = None) -> Record:
    """A validated Record from a record file's bytes, text or decoded JSON.

    Raises RecordError (never anything else) for anything malformed: not JSON, not an object,
    too big, a missing or ill-typed field, a bad address, a name other than *expect_name*.
    Unknown extra fields are ignored (a newer minor version may add some).
    """
    if isinstance(data, (bytes, bytearray)):
        if len(data) > MAX_RECORD_BYTES:
            raise RecordError(f"too big ({len(data)} bytes; a record is under {MAX_RECORD_BYTES})")
        try:
            data = bytes(data).decode("utf-8")
        except UnicodeDecodeError:
            raise RecordError("not UTF-8 text") from None
    if isinstance(data, str):
        if len(data) > MAX_RECORD_BYTES:
            raise RecordError(f"too big ({len(data)} characters)")
        if not data.strip():
            raise RecordError("empty (a partial copy?)")
        data = loads_json(data)
    if not isinstance(data, Mapping):
        raise RecordError("not a JSON object")
    missing = [k for k in _FIELDS if k not in data]
    if missing:
        raise RecordError(f"missing field(s): {', '.join(missing)}")
    version = data["version"]
    if isinstance(version, bool) or not isinstance(version, int):
        raise RecordError("version must be a whole number")
    for key in ("name", "role", "local_ip", "public_ip"):
        if not isinstance(data[key], str):
            raise RecordError(f"{key} must be a string")
    seq = data["seq"]
    if isinstance(seq, bool) or not isinstance(seq, int):
        raise RecordError("seq must be a whole number")
    epoch = data.get("seq_epoch", 0)
    if isinstance(epoch, bool) or not isinstance(epoch, int):
        raise RecordError("seq_epoch must be a whole number of seconds since 1970")
    sig = data.get("sig", "")
    if not isinstance(sig, str) or len(sig) > 200:
        raise RecordError("sig must be a signature (base64 text)")
    rec = Record(name=data["name"].strip(), local_ip=data["local_ip"].strip(),
                 public_ip=data["public_ip"].strip(), role=data["role"].strip(), seq=seq,
                 timestamp=parse_time(data["timestamp"]), version=version, seq_epoch=epoch,
                 sig=sig)
    check_record(rec, now=now)
    if expect_name is not None and rec.name.lower() != expect_name.lower():
        raise RecordError(f"it names {rec.name!r}, not {expect_name!r}")
    return rec


def loads_json(text: str) -> Any:
    """Decode a record's JSON text: RecordError (only) for anything that is not plain JSON of
    bounded depth, with each key once."""
    try:
        return loads_bounded(text, max_depth=MAX_DEPTH)
    except JsonInputError as exc:
        raise RecordError(f"{exc} (a partial copy, or not a record?)") from None


# --------------------------------------------------------------------------- successors
def successor_problem(prev: Record | None, rec: Record) -> str | None:
    """Why *rec* may not replace *prev*, the record of the same component applied before
    (None: it may).

    A higher seq of the same counter follows; the very same record is no change. A lower (or
    equal, with other content) seq is an old or forged copy. A higher ``seq_epoch`` says the
    component started counting again: believed only when that start is not before *prev* was
    written (its own clock wrote both), so an old copy cannot pass for a restart.
    """
    if prev is None:
        return None
    if rec.seq_epoch < prev.seq_epoch:
        return (f"it counts from an earlier start ({show_time(rec.seq_epoch) if rec.seq_epoch else 'none'}) "
                f"than the record #{prev.seq} already applied ({show_time(prev.seq_epoch)}): an "
                "old copy")
    if rec.seq_epoch > prev.seq_epoch:
        if rec.seq_epoch < math.floor(prev.timestamp):
            return (f"it says its counter started again at {show_time(rec.seq_epoch)}, before "
                    f"the record #{prev.seq} already applied was written "
                    f"({show_time(prev.timestamp)}): not a believable restart")
        return None
    if rec.seq > prev.seq:
        return None
    if rec.seq == prev.seq and rec.rank == prev.rank and rec.same_content(prev):
        return None
    if rec.seq == prev.seq:
        return (f"#{rec.seq} was already applied with other content or time: a conflicting "
                "copy")
    return (f"#{rec.seq} of {show_time(rec.timestamp)} is older than #{prev.seq} already applied"
            " (an old copy)")


# --------------------------------------------------------------------------- choosing
@dataclass(frozen=True)
class Candidate:
    """A valid record and where it was read (a file name, a DNS name)."""

    record: Record
    source: str


def choose_best(candidates: Iterable[Candidate]) -> tuple[Candidate | None, list[str]]:
    """The copy to use: highest (seq_epoch, seq), then newest timestamp; plus notes on
    conflicting copies.

    Ties (same seq and timestamp) with different content are a real conflict: the one from the
    source that sorts first wins (the plain ``NAME.json`` before ``NAME.sync-conflict-...``), so
    every component decides the same way, and a note says so.
    """
    cands = list(candidates)
    if not cands:
        return None, []
    best = sorted(cands, key=lambda c: (-c.record.seq_epoch, -c.record.seq,
                                        -millis(c.record.timestamp), len(c.source), c.source))[0]
    notes = []
    for c in cands:
        if c is not best and c.record.rank == best.record.rank \
                and not c.record.same_content(best.record):
            notes.append(f"{c.source} has the same seq #{c.record.seq} and time as {best.source} "
                         f"but other content; using {best.source}")
    return best, notes

