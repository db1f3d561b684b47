"""The DNS store: RFC 2136 dynamic updates, TSIG-signed, on an authoritative server the user runs.

Each component owns two record sets at ``NAME.ZONE``:

- ``A``: its public IP, so anything on the internet can use the name (``ssh turtlebot.ZONE``);
- ``TXT``: its whole record, ``"rosnet-tui" "<JSON in chunks of at most 255 bytes>"``, which
  peers read and validate like a record file (seq, timestamp, addresses).

Both change in one UPDATE message (the server applies it whole or not at all). Peers ask the
server itself (not a caching resolver) so a change is seen at once; a query of the zone's SOA
serial first tells whether anything changed since the last read. A TSIG key is required (the
store refuses to start without one): updates and queries are signed, and the answers'
signatures checked: a forged answer is refused like a garbage record. Each TXT record is also
signed by its component's own key (:mod:`.signing`): another holder of the TSIG key (every
member has it) cannot make one that counts.
"""

from __future__ import annotations

import base64
import binascii
import re
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import dns.exception
import dns.message
import dns.name
import dns.query
import dns.rcode
import dns.rdataclass
import dns.rdatatype
import dns.rdtypes.ANY.TXT
import dns.tsig
import dns.update

from rosnet_tui.core.files.regular_file import FileRefusedError, read_regular
from rosnet_tui.core.saved.sync_records import Candidate, Record, RecordError, parse_record

from .store import FetchResult, Refusal, StoreConfigError, StoreError

TXT_TAG = b"rosnet-tui"
TTL = 60
REREAD_S = 30.0          # read the records again at least this often, even if the serial stands
ALGORITHMS = ("hmac-sha256", "hmac-sha512", "hmac-sha384", "hmac-sha224", "hmac-sha1", "hmac-md5")


# --------------------------------------------------------------------------- the TSIG key
@dataclass(frozen=True)
class TsigKey:
    name: str
    algorithm: str
    secret: str   # base64, as in the key file

    def to_dns(self) -> dns.tsig.Key:
        return dns.tsig.Key(self.name, self.secret, self.algorithm)


# A quoted string (kept whole: base64 secrets hold "//"), else a comment: # or // to the end of
# the line, or /* ... */.
_BIND_COMMENT = re.compile(r'("[^"\n]*")|#[^\n]*|//[^\n]*|/\*.*?\*/', re.S)
_BIND_KEY = re.compile(r'key\s+"?([A-Za-z0-9._-]+)"?\s*\{(.*?)\}\s*;', re.S)
_BIND_ALG = re.compile(r'algorithm\s+"?([A-Za-z0-9.-]+)"?\s*;')
_BIND_SECRET = re.compile(r'secret\s+"([^"]*)"\s*;')
_Y_FORM = re.compile(r"^(?:([A-Za-z0-9.-]+):)?([A-Za-z0-9._-]+):([A-Za-z0-9+/=]+)$")


def parse_tsig_key(text: str) -> TsigKey:
    """A TSIG key from a BIND-style key file (what ``tsig-keygen NAME`` prints), or from the
    one-line ``[algorithm:]name:secret`` form of ``nsupdate -y``. Raises StoreConfigError."""
    text = _BIND_COMMENT.sub(lambda m: m.group(1) or " ", text)
    m = _BIND_KEY.search(text)
    if m:
        name, body = m.group(1), m.group(2)
        alg = _BIND_ALG.search(body)
        sec = _BIND_SECRET.search(body)
        if not alg or not sec:
            raise StoreConfigError(f"the key {name!r} needs both 'algorithm' and 'secret'")
        algorithm, secret = alg.group(1).lower().rstrip("."), re.sub(r"\s", "", sec.group(1))
    else:
        y = _Y_FORM.match(text.strip())
        if not y:
            raise StoreConfigError("not a TSIG key file: expected key \"NAME\" { algorithm ...; "
                                   "secret \"...\"; }; (tsig-keygen NAME writes one)")
        algorithm, name, secret = (y.group(1) or "hmac-sha256").lower(), y.group(2), y.group(3)
    if algorithm not in ALGORITHMS:
        raise StoreConfigError(f"TSIG algorithm {algorithm!r} is not supported "
                               f"(use one of {', '.join(ALGORITHMS)})")
    try:
        raw = base64.b64decode(secret, validate=True)
    except (binascii.Error, ValueError):
        raise StoreConfigError("the key's secret is not valid base64") from None
    if len(raw) < 16:
        raise StoreConfigError("the key's secret is too short (under 128 bits)")
    return TsigKey(name, algorithm, secret)


MAX_KEY_FILE_BYTES = 64 << 10   # a key file is a few lines


def load_tsig_key(path: Path) -> TsigKey:
    """The key in the file the settings name. Refused at once, without reading: a FIFO (it
    would block until someone writes to it), a device, a folder, a file over 64 KB."""
    try:
        text = read_regular(Path(path), MAX_KEY_FILE_BYTES).decode("utf-8")
    except FileNotFoundError:
        raise StoreConfigError(f"the TSIG key file {path} does not exist") from None
    except FileRefusedError as exc:
        raise StoreConfigError(f"the TSIG key file {path} {exc.why}") from None
    except OSError as exc:
        raise StoreConfigError(f"cannot read the TSIG key file {path}: {exc.strerror}") from None
    except UnicodeDecodeError:
        raise StoreConfigError(f"the TSIG key file {path} is not text") from None
    try:
        return parse_tsig_key(text)
    except StoreConfigError as exc:
        raise StoreConfigError(f"{path}: {exc}") from None


# --------------------------------------------------------------------------- TXT form
def record_to_txt(record: Record) -> list[bytes]:
    """The TXT strings of *record*: the tag, then its compact JSON in chunks of 255 bytes."""
    data = record.to_compact().encode("utf-8")
    return [TXT_TAG] + [data[i:i + 255] for i in range(0, len(data), 255)]


def record_from_txt(strings: Iterable[bytes], expect_name: str) -> Record | None:
    """The record in one TXT RR's strings; None when the RR is not ours (no tag).
    Raises RecordError for a tagged RR that does not hold a valid record."""
    parts = list(strings)
    if not parts or parts[0] != TXT_TAG:
        return None
    return parse_record(b"".join(parts[1:]), expect_name=expect_name)


NO_TSIG = ("the dns store needs sync.tsig_key_file (a TSIG key the name server also has: "
           "`tsig-keygen NAME`): without it anyone who reaches the server could change or read "
           "the records")


# --------------------------------------------------------------------------- the store
class DnsStore:
    kind = "dns"

    def __init__(self, server: str, zone: str, key_file: Path | None, *, port: int = 53,
                 timeout_s: float = 3.0, ttl: int = TTL) -> None:
        if key_file is None:
            raise StoreConfigError(NO_TSIG)
        self.server = server
        self.port = port
        self.zone = dns.name.from_text(zone if zone.endswith(".") else zone + ".")
        self.key_file = key_file
        self.timeout_s = timeout_s
        self.ttl = ttl
        self._key: dns.tsig.Key | None = None
        self._key_mtime: int | None = None
        self._serial: int | None = None
        self._cache: FetchResult | None = None
        self._cache_names: tuple[Any, ...] = ()
        self._cache_at = 0.0

    def describe(self) -> str:
        return f"DNS zone {self.zone.to_text()} on {self.server}, TSIG key {self.key_file}"

    def fqdn(self, name: str) -> str:
        return dns.name.from_text(name, self.zone).to_text()

    def key(self) -> dns.tsig.Key | None:
        """The TSIG key (re-read when its file changes). Raises StoreConfigError."""
        if self.key_file is None:
            return None
        try:
            mtime = self.key_file.stat().st_mtime_ns
        except OSError:
            mtime = None
        if self._key is None or mtime != self._key_mtime:
            self._key = load_tsig_key(self.key_file).to_dns()
            self._key_mtime = mtime
        return self._key

    # ------------------------------------------------------------------ talking to the server
    def _where(self) -> str:
        return f"the DNS server {self.server}" + (f" port {self.port}" if self.port != 53 else "")

    def _ask(self, qname: str, rdtype: str) -> dns.message.Message:
        q = dns.message.make_query(qname, rdtype)
        q.flags &= ~0x0100  # no recursion wanted: we ask the authoritative server itself
        key = self.key()
        if key is not None:
            q.use_tsig(keyring=key)
        try:
            r = dns.query.udp(q, self.server, timeout=self.timeout_s, port=self.port)
            if r.flags & 0x0200:  # truncated: ask again over TCP
                r = dns.query.tcp(q, self.server, timeout=self.timeout_s, port=self.port)
        except dns.exception.Timeout:
            raise StoreError(f"{self._where()} did not answer within {self.timeout_s:g} s") \
                from None
        except dns.tsig.PeerError as exc:
            raise StoreError(f"{self._where()} refused our TSIG signature ({exc}): is the key "
                             "the one the server has?") from None
        except dns.exception.DNSException as exc:
            raise StoreError(f"{self._where()} sent an answer that cannot be used "
                             f"({type(exc).__name__}: {exc})") from None
        except OSError as exc:
            raise StoreError(f"cannot reach {self._where()}: {exc.strerror or exc}") from None
        rc = r.rcode()
        if rc not in (dns.rcode.NOERROR, dns.rcode.NXDOMAIN):
            raise StoreError(f"{self._where()} answered {dns.rcode.to_text(rc)} for {qname} "
                             f"{rdtype}" + (": is the zone served there?"
                                            if rc in (dns.rcode.REFUSED, dns.rcode.SERVFAIL)
                                            else ""))
        return r

    def publish(self, record: Record) -> None:
        rel = dns.name.from_text(record.name, None)
        key = self.key()
        upd = dns.update.UpdateMessage(self.zone, keyring=key) if key is not None \
            else dns.update.UpdateMessage(self.zone)
        txt = dns.rdtypes.ANY.TXT.TXT(dns.rdataclass.IN, dns.rdatatype.TXT, record_to_txt(record))
        upd.replace(rel, self.ttl, txt)
        if record.public_ip:
            upd.replace(rel, self.ttl, "A", record.public_ip)
        try:
            r = dns.query.tcp(upd, self.server, timeout=self.timeout_s, port=self.port)
        except dns.exception.Timeout:
            raise StoreError(f"{self._where()} did not answer the update within "
                             f"{self.timeout_s:g} s") from None
        except dns.tsig.PeerError as exc:
            raise StoreError(f"{self._where()} refused our TSIG signature ({exc}): is the key "
                             "the one the server has?") from None
        except dns.exception.DNSException as exc:
            raise StoreError(f"the update to {self._where()} failed ({type(exc).__name__}: "
                             f"{exc})") from None
        except OSError as exc:
            raise StoreError(f"cannot reach {self._where()} for the update: "
                             f"{exc.strerror or exc}") from None
        rc = r.rcode()
        if rc != dns.rcode.NOERROR:
            hint = {dns.rcode.REFUSED: ": the server does not allow this update (allow-update / "
                                       "update-policy for our key?)",
                    dns.rcode.NOTAUTH: ": the server is not authoritative for the zone, or the "
                                       "key is wrong",
                    dns.rcode.NOTZONE: ": the name is outside the zone"}.get(rc, "")
            raise StoreError(f"{self._where()} answered {dns.rcode.to_text(rc)} to the update of "
                             f"{self.fqdn(record.name)}{hint}")
        self._serial = None  # our own update changed the zone

    def _zone_serial(self) -> int | None:
        r = self._ask(self.zone.to_text(), "SOA")
        for rrset in r.answer:
            if rrset.rdtype == dns.rdatatype.SOA:
                for rd in rrset:
                    return int(rd.serial)
        return None

    def fetch(self, names: Iterable[str], own_name: str,
              keys: Mapping[str, Any]) -> FetchResult:
        names_t = (*dict.fromkeys([*names, own_name]),
                   *sorted((n, k.public_bytes_raw() if k is not None else b"")
                           for n, k in keys.items()))
        serial = self._zone_serial()
        if serial is None:
            raise StoreError(f"{self._where()} has no SOA for {self.zone.to_text()}: it does not "
                             "serve this zone")
        now = time.monotonic()
        if (self._cache is not None and serial == self._serial and names_t == self._cache_names
                and now - self._cache_at < REREAD_S):
            return self._cache
        out = FetchResult(keys=keys)
        for n in dict.fromkeys([*names, own_name]):
            cands: list[Candidate] = []
            qname = self.fqdn(n)
            r = self._ask(qname, "TXT")
            for rrset in r.answer:
                if rrset.rdtype != dns.rdatatype.TXT:
                    continue
                for rd in rrset:
                    try:
                        rec = record_from_txt(rd.strings, n)
                    except RecordError as exc:
                        out.refused.append(Refusal(f"{qname} TXT", n, str(exc)))
                        continue
                    except Exception as exc:  # noqa: BLE001 - one bad RR never stops the others
                        out.refused.append(Refusal(f"{qname} TXT", n, "cannot be read as a "
                                                   f"record ({type(exc).__name__})"))
                        continue
                    if rec is not None:
                        cands.append(Candidate(rec, f"{qname} TXT"))
            out.add_copies(n, cands, own_name)
        self._serial, self._cache, self._cache_names, self._cache_at = serial, out, names_t, now
        return out

    def remove_stale_copies(self, name: str, keep: Record) -> list[str]:
        return []  # an update replaces the whole TXT set: there are no stale copies
