"""Issue 15, sync records: what an adversarial run broke, each case reproduced.

- a record with a timestamp in milliseconds, 1e20/-1e20 or 2,000 nested brackets escaped
  ``parse_record`` as ValueError/OverflowError/RecursionError and stopped every peer's update;
- a private or carrier-grade ``public_ip`` was accepted;
- duplicate keys: the last silently won;
- sequence numbers did not protect: ``sync --once`` kept no memory, the service took a lower seq
  with a newer timestamp. Now the applied record of each peer is kept in the state dir and a
  lower seq is refused unless the record shows a verified counter restart (``seq_epoch``).
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rosnet_tui.core.config.paths import Paths
from rosnet_tui.core.saved.settings import (
    render_settings,
)
from rosnet_tui.core.saved.sync_records import (
    MAX_RECORD_BYTES,
    RecordError,
    format_time,
    new_record,
    parse_record,
)
from rosnet_tui.core.sync import FolderStore, SyncService
from rosnet_tui.core.sync.dnsstore import TXT_TAG, record_from_txt
from rosnet_tui.core.sync.watcher import LocalAddress, PublicLookup
from tests.builders import folder_sync_settings, pinned, signed
from tests.hardening_tally import tally

NOW = time.time()
REPO = Path(__file__).resolve().parents[1]
AREA = "sync records"


def base(**kw) -> dict:
    d = {"version": 1, "name": "turtlebot", "role": "master", "local_ip": "10.10.10.1",
         "public_ip": "203.0.113.2", "seq": 1, "timestamp": format_time(NOW)}
    d.update(kw)
    return d


def rec(name="turtlebot", local="10.10.10.1", public="203.0.113.2", role="master", seq=1,
        ts=None, **kw):
    return signed(new_record(name, local_ip=local, public_ip=public, role=role, seq=seq,
                             now=NOW if ts is None else ts, **kw))


# =========================================================================== parse_record
BAD_TIMESTAMPS = [
    (1763800000000, "milliseconds"),        # as JavaScript's Date.now() writes it
    (1763800000000.5, "milliseconds"),
    (1763800000000000, "microseconds"),
    (1763800000000000000, "nanoseconds"),
    (1e20, "not a plausible time"),
    (-1e20, "before the year 2000"),
    (1e308, "not a plausible time"),
    (-1e308, "before the year 2000"),
    (10**400, "not a plausible time"),      # an int no float holds
    (-(10**400), "before the year 2000"),
    (-1, "before the year 2000"),
    (0, "before the year 2000"),
    (253402300800, "not a plausible time"),  # year 10000
    ("1763800000000", "ISO 8601"),
    ("+275760-09-13T00:00:00Z", "ISO 8601"),
    ("9999-12-31T23:59:59+14:00", "future"),
    ("0001-01-01T00:00:00+14:00", "before the year 2000"),
    ("2025-01-01T00:00:00Z" + "0" * 3000, "ISO 8601"),
    ([NOW], "not a time"),
    ({"s": NOW}, "not a time"),
    (None, "not a time"),
]


@pytest.mark.parametrize("ts, why", BAD_TIMESTAMPS, ids=[str(i) for i in range(len(BAD_TIMESTAMPS))])
def test_a_timestamp_in_any_wrong_unit_or_size_is_a_record_error(ts, why):
    text = json.dumps(base(timestamp=ts))
    if len(text.encode()) > MAX_RECORD_BYTES:
        pytest.skip("over the size cap: refused as too big before its content is read")
    with pytest.raises(RecordError) as e:
        parse_record(text)
    assert why in str(e.value)
    assert len(str(e.value)) < 200
    tally(AREA, 1, 1, "timestamp")


NESTED = [
    "[" * 2000 + "]" * 2000,                                        # 4 KB, under the cap
    "{" + '"a":{' * 680 + "}" * 681,
    json.dumps(base())[:-1] + ', "extra": ' + "[" * 1900 + "]" * 1900 + "}",
    "[" * 100000,                                                    # text, not bytes: no cap
]


@pytest.mark.parametrize("text", NESTED, ids=["brackets", "objects", "in-a-field", "unclosed"])
def test_deep_nesting_is_a_record_error(text):
    with pytest.raises(RecordError, match="nested|too big"):
        parse_record(text)
    with pytest.raises(RecordError, match="nested|too big"):
        parse_record(text.encode())
    tally(AREA, 2, 2, "nesting")


def test_duplicate_keys_are_refused_not_last_wins():
    text = json.dumps(base(seq=2))[:-1] + ', "seq": 9}'
    with pytest.raises(RecordError, match="'seq' appears twice"):
        parse_record(text)
    inner = json.dumps(base())[:-1] + ', "extra": {"a": 1, "a": 2}}'
    with pytest.raises(RecordError, match="'a' appears twice"):
        parse_record(inner)
    tally(AREA, 2, 2, "duplicate keys")


@pytest.mark.parametrize("ip", ["10.0.0.1", "10.255.255.254", "172.16.0.1", "172.31.255.254",
                                "192.168.0.1", "192.168.255.254", "100.64.0.1",
                                "100.127.255.254"])
def test_a_private_or_carrier_grade_public_ip_is_refused(ip):
    with pytest.raises(RecordError, match="public_ip"):
        parse_record(json.dumps(base(public_ip=ip)))
    assert parse_record(json.dumps(base(local_ip=ip))).local_ip == ip   # fine as a LAN address
    tally(AREA, 2, 2, "private public_ip")


@pytest.mark.parametrize("ip", ["192.0.2.7", "198.51.100.2", "203.0.113.9", "172.32.0.1",
                                "100.128.0.1", "11.0.0.1", "8.8.4.4"])
def test_public_and_documentation_addresses_stay_valid(ip):
    assert parse_record(json.dumps(base(public_ip=ip))).public_ip == ip


def test_dns_txt_with_a_bad_timestamp_is_a_record_error():
    data = json.dumps(base(timestamp=1763800000000), separators=(",", ":")).encode()
    with pytest.raises(RecordError, match="milliseconds"):
        record_from_txt([TXT_TAG, data[:255], data[255:]], "turtlebot")
    tally(AREA, 1, 1, "dns txt")


# --------------------------------------------------------------------------- property tests
_UNITS = st.sampled_from([1e-3, 1.0, 1e3, 1e6, 1e9])
_scalars = st.one_of(
    st.none(), st.booleans(),
    st.integers(min_value=-(10**30), max_value=10**30),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(alphabet=st.characters(codec="utf-8"), max_size=40),
    st.text(alphabet=st.characters(max_codepoint=0x2030, categories=["Cc", "Cf", "Zl", "Zp",
                                                                     "Nd", "No"]), max_size=20),
)
_values = st.recursive(_scalars, lambda kids: st.one_of(
    st.lists(kids, max_size=4), st.dictionaries(st.text(max_size=5), kids, max_size=4)),
    max_leaves=20)


@st.composite
def _records(draw):
    d = base()
    for key in draw(st.lists(st.sampled_from(sorted(d)), unique=True, max_size=4)):
        d[key] = draw(_values)
    if draw(st.booleans()):
        d["timestamp"] = draw(st.floats(min_value=9e8, max_value=2e9)) * draw(_UNITS)
    if draw(st.booleans()):
        depth = draw(st.integers(min_value=1, max_value=3000))
        d["extra"] = "NEST"
        text = json.dumps(d).replace('"NEST"', "[" * depth + "]" * depth)
    else:
        text = json.dumps(d, allow_nan=True)
    return text


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(_records())
def test_property_any_record_text_is_a_record_or_a_record_error(text):
    for data in (text, text.encode()):
        try:
            r = parse_record(data)
        except RecordError as exc:
            assert str(exc) and len(str(exc)) < 300
        else:
            assert math.isfinite(r.timestamp) and 0 <= r.seq <= 2**53
    tally(AREA, 2, 2, "property: fields")


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=300) | st.text(max_size=300).map(str.encode))
def test_property_any_bytes_are_a_record_or_a_record_error(data):
    try:
        parse_record(data)
    except RecordError:
        pass
    tally(AREA, 1, 1, "property: bytes")


# =========================================================================== the folder store
def test_one_bad_file_never_stops_the_others_in_the_folder_store(tmp_path):
    store = FolderStore(tmp_path)
    (tmp_path / "turtlebot.json").write_text(json.dumps(base(timestamp=1763800000000)))
    (tmp_path / "turtlebot (conflicted copy).json").write_text("[" * 2000 + "]" * 2000)
    (tmp_path / "turtlebot.sync-conflict-1.json").write_text(json.dumps(base(timestamp=-1e20)))
    (tmp_path / "rover.json").write_text(
        rec(name="rover", role="member", public="198.51.100.40", seq=3).to_text())
    res = store.fetch(["turtlebot", "rover"], "sami", pinned("turtlebot", "rover", "sami"))
    assert res.records["rover"].record.public_ip == "198.51.100.40"
    refused = {r.source: r.why for r in res.refused}
    assert "milliseconds" in refused["turtlebot.json"]
    assert "nested" in refused["turtlebot (conflicted copy).json"]
    assert "before the year 2000" in refused["turtlebot.sync-conflict-1.json"]
    tally(AREA, 3, 3, "folder store")


# =========================================================================== the service
class Two:
    """A laptop following two peers through a shared folder in tmp_path."""

    def __init__(self, tmp_path: Path) -> None:
        self.folder = tmp_path / "shared"
        self.folder.mkdir()
        self.config = tmp_path / "config.toml"
        self.config.write_text(render_settings(folder_sync_settings(self.folder, 2, peers=2)))
        self.hosts = tmp_path / "hosts"
        self.hosts.write_text("127.0.0.1\tlocalhost\n")
        self.state = tmp_path / "state"
        self.svc = self.service()

    def service(self) -> SyncService:
        paths = Paths(config_path=self.config, state_dir=self.state, hosts_path=self.hosts)
        return SyncService(paths, run_checks=False, netlink=False,
                           save_learned=False,
                           local_source=lambda s: LocalAddress("eth0", "192.168.1.10", ""),
                           public_source=lambda s: PublicLookup("198.51.100.2", "test"))

    def round(self):
        s = self.svc
        s.publisher.next_fetch = s.publisher.next_publish = s.applier.next_apply = 0.0
        return s.round()

    def entry(self, name: str) -> str | None:
        for line in self.hosts.read_text().splitlines():
            f = line.split("#", 1)[0].split()
            if len(f) >= 2 and name in f[1:]:
                return f[0]
        return None

    def put(self, file: str, text: str) -> None:
        (self.folder / file).write_text(text)

    def cli_once(self) -> subprocess.CompletedProcess:
        return subprocess.run(
            [sys.executable, "-m", "rosnet_tui", "sync", "--once", "--config", str(self.config),
             "--state-dir", str(self.state), "--hosts-file", str(self.hosts), "--no-bashrc",
             "--no-checks", "--no-save-settings"],
            capture_output=True, text=True, timeout=60,
            env=dict(os.environ, PYTHONPATH=str(REPO)), cwd=REPO)


@pytest.mark.parametrize("bad", [json.dumps(base(timestamp=1763800000000)),
                                 json.dumps(base(timestamp=1e20)),
                                 json.dumps(base(timestamp=-1e20)),
                                 "[" * 2000 + "]" * 2000],
                         ids=["ms", "1e20", "-1e20", "nested"])
def test_sync_once_refuses_the_bad_file_names_it_and_applies_the_others(tmp_path, bad):
    w = Two(tmp_path)
    w.svc.close()
    w.put("turtlebot.json", bad)
    w.put("rover.json", rec(name="rover", role="member", public="198.51.100.40", seq=3).to_text())
    r = w.cli_once()
    assert "Traceback" not in r.stderr, r.stderr
    assert r.returncode in (0, 1), r.stderr         # 1: no public IP on loopback port 9
    assert "refused the record turtlebot.json" in r.stderr
    assert w.entry("rover") == "198.51.100.40"      # the good peer's change is applied
    assert w.entry("turtlebot") == "203.0.113.2"    # the bad one: the settings' address
    tally(AREA, 1, 1, "sync --once")


def test_the_running_service_keeps_applying_other_peers_while_a_bad_file_sits_there(tmp_path):
    w = Two(tmp_path)
    w.put("turtlebot.json", "[" * 2000 + "]" * 2000)
    for i in range(3):
        w.put("rover.json", rec(name="rover", role="member", public=f"198.51.100.{40 + i}",
                                seq=3 + i).to_text())
        res = w.round()
        assert w.entry("rover") == f"198.51.100.{40 + i}", res.errors
    assert "round" not in w.svc.report.errors()
    tally(AREA, 3, 3, "service rounds")


# --------------------------------------------------------------------------- sequence numbers
def test_sync_once_remembers_the_applied_seq_an_old_copy_is_refused(tmp_path):
    w = Two(tmp_path)
    w.svc.close()
    w.put("turtlebot.json", rec(seq=8, public="203.0.113.8", ts=NOW - 60).to_text())
    r = w.cli_once()
    assert w.entry("turtlebot") == "203.0.113.8", r.stderr
    # An old copy (seq 2, three days old) comes back, as a sync tool restoring a file would.
    w.put("turtlebot.json", rec(seq=2, public="203.0.113.22", ts=NOW - 3 * 86400).to_text())
    r = w.cli_once()
    assert "Traceback" not in r.stderr
    assert w.entry("turtlebot") == "203.0.113.8", r.stderr
    assert "#2" in r.stderr and "#8" in r.stderr
    tally(AREA, 1, 1, "seq: --once")


def test_the_service_refuses_a_lower_seq_even_with_a_newer_timestamp(tmp_path):
    w = Two(tmp_path)
    w.put("turtlebot.json", rec(seq=5, public="203.0.113.5", ts=NOW - 100).to_text())
    w.round()
    assert w.entry("turtlebot") == "203.0.113.5"
    w.put("turtlebot.json", rec(seq=4, public="203.0.113.4", ts=NOW - 1).to_text())
    w.round()
    assert w.entry("turtlebot") == "203.0.113.5"
    # the same seq with other content is no successor either
    w.put("turtlebot.json", rec(seq=5, public="203.0.113.55", ts=NOW - 1).to_text())
    w.round()
    assert w.entry("turtlebot") == "203.0.113.5"
    w.put("turtlebot.json", rec(seq=6, public="203.0.113.6", ts=NOW - 1).to_text())
    w.round()
    assert w.entry("turtlebot") == "203.0.113.6"
    tally(AREA, 2, 2, "seq: service")


def test_the_applied_seq_survives_a_restart_of_the_service(tmp_path):
    w = Two(tmp_path)
    w.put("turtlebot.json", rec(seq=8, public="203.0.113.8", ts=NOW - 60).to_text())
    w.round()
    w.svc.close()
    data = json.loads((w.state / "sync" / "applied.json").read_text())
    assert data["peers"]["turtlebot"]["seq"] == 8
    w.put("turtlebot.json", rec(seq=2, public="203.0.113.22", ts=NOW - 1).to_text())
    w.svc = w.service()
    w.round()
    assert w.entry("turtlebot") == "203.0.113.8"
    tally(AREA, 1, 1, "seq: restart")


def test_a_verified_counter_restart_is_accepted_and_a_false_one_refused(tmp_path):
    w = Two(tmp_path)
    w.put("turtlebot.json", rec(seq=9, public="203.0.113.9", ts=NOW - 100).to_text())
    w.round()
    # A restart claimed before the record already applied was written: not believable.
    w.put("turtlebot.json", rec(seq=1, public="203.0.113.66", ts=NOW - 10,
                                seq_epoch=int(NOW - 1000)).to_text())
    w.round()
    assert w.entry("turtlebot") == "203.0.113.9"
    # The robot lost its state and started counting again after that record: accepted.
    w.put("turtlebot.json", rec(seq=1, public="203.0.113.10", ts=NOW - 5,
                                seq_epoch=int(NOW - 50)).to_text())
    w.round()
    assert w.entry("turtlebot") == "203.0.113.10"
    # From then on, the old counter is over: its copies (even with a higher seq) are refused.
    w.put("turtlebot.json", rec(seq=10, public="203.0.113.11", ts=NOW - 1).to_text())
    w.round()
    assert w.entry("turtlebot") == "203.0.113.10"
    tally(AREA, 3, 3, "seq: counter restart")


def test_seq_epoch_is_checked_and_round_trips():
    r = rec(seq=1, seq_epoch=int(NOW - 5))
    back = parse_record(r.to_text())
    assert back.seq_epoch == int(NOW - 5)
    assert "seq_epoch" not in rec().to_json()           # version-1 records look as before
    for bad in (True, -1, 1.5, "1", 2**60):
        with pytest.raises(RecordError, match="seq_epoch"):
            parse_record(json.dumps(dict(base(), seq_epoch=bad)))
    with pytest.raises(RecordError, match="seq_epoch"):      # counting began after it was written
        parse_record(json.dumps(dict(base(), seq_epoch=int(NOW + 3600))))
    tally(AREA, 6, 6, "seq_epoch field")
