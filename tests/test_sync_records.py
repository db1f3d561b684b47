"""The address records' verdicts at their bounds (issue 36: each check here fails when a guard
of core/saved/sync_records.py or sync_applied.py is dropped or moved): what a record may hold,
how its time is read, which copy wins, which may follow the one applied, and the applied list
kept across restarts."""

from __future__ import annotations

import json
import math
import os
import time

import pytest

from rosnet_tui.core.saved import sync_applied as applied
from rosnet_tui.core.saved import sync_records as sr
from rosnet_tui.core.saved.sync_records import Candidate, Record, RecordError

T = 1740830400.0                  # 2025-03-01T12:00:00Z


def rec(**kw) -> Record:
    args = {"name": "sami", "local_ip": "192.168.1.10", "public_ip": "198.51.100.2",
            "role": "member", "seq": 5, "timestamp": T, **kw}
    return Record(**args)


def refused(r: Record, why: str, now: float = T) -> None:
    with pytest.raises(RecordError, match=why):
        sr.check_record(r, now=now)


# --------------------------------------------------------------------------- forms
def test_the_forms_of_a_record():
    r = rec()
    assert r.to_json() == {"version": 1, "name": "sami", "role": "member",
                           "local_ip": "192.168.1.10", "public_ip": "198.51.100.2", "seq": 5,
                           "timestamp": "2025-03-01T12:00:00.000Z"}
    full = rec(seq_epoch=int(T) - 10, sig="c2ln")
    assert full.to_json()["seq_epoch"] == int(T) - 10 and full.to_json()["sig"] == "c2ln"
    assert r.to_text() == json.dumps(r.to_json(), indent=2) + "\n"
    assert r.to_text().endswith("}\n") and '\n  "name": "sami"' in r.to_text()
    assert " " not in r.to_compact() and json.loads(r.to_compact()) == r.to_json()
    assert sr.parse_record(full.to_text(), now=T) == full
    assert r.describe() == ("sami (member): local 192.168.1.10, public 198.51.100.2, #5 of "
                            "2025-03-01T12:00:00.000Z")
    assert "local ?, public ?" in rec(local_ip="", public_ip="").describe()


def test_content_rank_and_the_next_record():
    r = rec(seq_epoch=7)
    assert r.rank == (7, 5, int(T * 1000))
    assert r.same_content(rec(seq=9, timestamp=T + 5)) and not r.same_content(None)
    for change in ({"name": "bob"}, {"local_ip": "192.168.1.11"},
                   {"public_ip": "198.51.100.3"}, {"role": "master"}):
        assert not r.same_content(rec(**change)), change
    n = rec(sig="x", version=2).next(local_ip="192.168.1.20", public_ip="", role="master",
                                      now=T + 60)
    assert (n.seq, n.timestamp, n.sig, n.version) == (6, T + 60, "", sr.RECORD_VERSION)
    assert (n.local_ip, n.public_ip, n.role, n.name) == ("192.168.1.20", "", "master", "sami")
    before = time.time()
    assert before - 1 <= rec().next(local_ip="192.168.1.20", public_ip="",
                                    role="member").timestamp <= time.time() + 1
    fresh = sr.new_record("sami", local_ip="192.168.1.10", public_ip="", role="member")
    assert fresh.seq == 1 and fresh.seq_epoch == 0 and abs(fresh.timestamp - time.time()) < 60
    made = sr.new_record("sami", local_ip="192.168.1.10", public_ip="", role="member", seq=3,
                         now=T, seq_epoch=int(T))
    assert (made.seq, made.timestamp, made.seq_epoch) == (3, T, int(T))
    with pytest.raises(RecordError, match="no address"):
        sr.new_record("sami", local_ip="", public_ip="", role="member", now=T)


# --------------------------------------------------------------------------- time
def test_times_are_written_in_utc_whatever_the_local_zone(monkeypatch):
    monkeypatch.setenv("TZ", "Asia/Kolkata")
    time.tzset()
    try:
        assert sr.format_time(T) == "2025-03-01T12:00:00.000Z"
        assert sr.parse_time("2025-03-01T12:00:00Z") == T
    finally:
        monkeypatch.undo()
        time.tzset()


def test_times_are_written_and_shown_in_milliseconds():
    assert sr.millis(1.0006) == 1001 and sr.millis(1.0004) == 1000 and sr.millis(2.5) == 2500
    assert sr.format_time(T + 0.123) == "2025-03-01T12:00:00.123Z"
    assert sr.format_time(T + 0.9996) == "2025-03-01T12:00:01.000Z"
    assert sr.format_time(T + 0.0004) == "2025-03-01T12:00:00.000Z"
    assert sr.show_time(sr.MIN_TIMESTAMP) == "2000-01-01T00:00:00.000Z"
    assert sr.show_time(sr.MAX_TIMESTAMP) == "9999-12-31T23:59:59.000Z"
    assert sr.show_time(sr.MIN_TIMESTAMP - 1) == "9.46685e+08"
    assert sr.show_time(sr.MAX_TIMESTAMP + 1) == "2.53402e+11"
    assert sr.show_time(math.inf) == "inf"


@pytest.mark.parametrize("value, seconds", [
    (T, T), (int(T), T), ("2025-03-01T12:00:00Z", T), (" 2025-03-01T12:00:00.250z ", T + 0.25),
    ("2025-03-01T13:00:00+01:00", T), (sr.MIN_TIMESTAMP, sr.MIN_TIMESTAMP),
    (sr.MAX_TIMESTAMP, sr.MAX_TIMESTAMP), (int(sr.MIN_TIMESTAMP), sr.MIN_TIMESTAMP),
])
def test_times_read(value, seconds):
    assert sr.parse_time(value) == seconds


@pytest.mark.parametrize("value, why", [
    (True, "not true/false"), (False, "not true/false"), (None, "missing or not a time"),
    ([T], "missing or not a time"), (math.nan, "not a finite number"),
    (math.inf, "not a plausible time"), (-math.inf, "before the year 2000"),
    (10**400, "not a plausible time"), (-(10**400), "before the year 2000"),
    (sr.MIN_TIMESTAMP - 1, "before the year 2000"), (sr.MAX_TIMESTAMP + 1, "not a plausible"),
    (T * 1e3, "looks like milliseconds"), (sr.MIN_TIMESTAMP * 1e3, "looks like milliseconds"),
    (sr.MAX_FUTURE_GUESS * 1e3, "looks like milliseconds"),
    (sr.MAX_FUTURE_GUESS * 1e3 + 1e3, "not a plausible"),
    (T * 1e6, "looks like microseconds"), (T * 1e9, "looks like nanoseconds"),
    (sr.MIN_TIMESTAMP * 1e6, "looks like microseconds"),
    (sr.MIN_TIMESTAMP * 1e9, "looks like nanoseconds"),
    (sr.MAX_FUTURE_GUESS * 1e9, "looks like nanoseconds"),
    (sr.MAX_FUTURE_GUESS * 1e9 * 2, "not a plausible"),
    ("2025-03-01T12:00:00", "no time zone"), ("yesterday", "not an ISO 8601 time"),
    ("2025-03-01T12:00:00Z" + " " * 10 + "x" * 50, "is not an ISO 8601 time"),
])
def test_times_refused(value, why):
    with pytest.raises(RecordError, match=why):
        sr.parse_time(value)


def test_a_long_time_text_is_cut_in_the_message():
    with pytest.raises(RecordError) as e:
        sr.parse_time("x" * 65)
    assert "x" * 40 + "'..." in str(e.value) and "x" * 41 not in str(e.value)
    with pytest.raises(RecordError) as e:
        sr.parse_time("x" * 64)                             # at the bound: read, then refused
    assert "'..." not in str(e.value) and "not an ISO 8601 time" in str(e.value)
    assert "x" * 40 + "'" in str(e.value) and "x" * 41 not in str(e.value)
    with pytest.raises(RecordError) as e:                  # the text as given, cut
        sr.parse_time(" " * 30 + "2025-03-01T12:00:00")
    assert str(e.value) == f"timestamp {' ' * 30 + '2025-03-01'!r} has no time zone (write " \
        "it in UTC, ...Z)"


# --------------------------------------------------------------------------- what a record holds
def test_addresses_a_record_may_hold():
    assert sr.address_problem("192.168.1.10") is None
    assert sr.address_problem("100.64.0.1") is None                  # a LAN behind CGNAT
    assert sr.address_problem("198.51.100.2", public=True) is None   # documentation: labs
    assert sr.address_problem("8.8.8.8", public=True) is None
    assert "never a public one" in sr.address_problem("192.168.1.10", public=True)
    assert "carrier-grade NAT" in sr.address_problem("100.64.0.1", public=True)
    for a in ("127.0.0.1", "169.254.1.1", "240.0.0.1"):
        assert sr.address_problem(a) and sr.address_problem(a, public=True), a
    assert "loopback" in sr.address_problem("127.0.0.1")
    assert sr.address_problem("") and sr.address_problem("sami")


def test_a_record_checked_field_by_field():
    sr.check_record(rec(), now=T)
    sr.check_record(rec(public_ip=""), now=T)
    sr.check_record(rec(local_ip=""), now=T)
    sr.check_record(rec(role="master"), now=T)
    refused(rec(version=2), "version 2 is not known")
    refused(rec(version=0), "version 0")
    refused(rec(name=""), "name")
    refused(rec(name="a b"), "name")
    refused(rec(role="boss"), "role 'boss' is not one of master, member")
    with pytest.raises(RecordError) as e:
        sr.check_record(rec(name="n" * 50 + "!"), now=T)
    assert f"name {'n' * 40!r}: " in str(e.value) and "n" * 41 not in str(e.value)
    with pytest.raises(RecordError) as e:
        sr.check_record(rec(role="r" * 30), now=T)
    assert f"role {'r' * 20!r} is not" in str(e.value) and "r" * 21 not in str(e.value)
    refused(rec(local_ip="", public_ip=""), "no address at all")
    refused(rec(local_ip="127.0.0.1"), "local_ip: .*loopback")
    refused(rec(public_ip="10.0.0.1"), "public_ip: .*never a public one")
    refused(rec(local_ip="", public_ip="10.0.0.1"), "public_ip")


@pytest.mark.parametrize("seq, ok", [(0, True), (sr.MAX_SEQ, True), (sr.MAX_SEQ + 1, False),
                                     (-1, False), (True, False), (5.0, False), ("5", False)])
def test_seq_bounds(seq, ok):
    if ok:
        sr.check_record(rec(seq=seq), now=T)
    else:
        refused(rec(seq=seq), "seq must be a whole number from 0 to")


def test_timestamp_and_epoch_bounds():
    refused(rec(timestamp=math.nan), "not a finite number")
    refused(rec(timestamp=True), "not a finite number")
    refused(rec(timestamp="2025"), "not a finite number")
    sr.check_record(rec(timestamp=sr.MIN_TIMESTAMP), now=T)
    refused(rec(timestamp=sr.MIN_TIMESTAMP - 0.5), "before the year 2000")
    sr.check_record(rec(timestamp=T + sr.MAX_FUTURE_S), now=T)
    refused(rec(timestamp=T + sr.MAX_FUTURE_S + 1), "more than a day in the future")
    sr.check_record(rec(timestamp=T + 3600))                         # now: the clock
    refused(rec(timestamp=time.time() + sr.MAX_FUTURE_S + 60), "future", now=None)
    for e in (0, int(sr.MIN_TIMESTAMP), int(T) + 1):
        sr.check_record(rec(seq_epoch=e), now=T)
    for e in (True, 1, int(sr.MIN_TIMESTAMP) - 1, int(sr.MAX_TIMESTAMP) + 1, float(T), -1):
        refused(rec(seq_epoch=e), "seq_epoch must be 0 or")
    refused(rec(seq_epoch=int(T) + 2), "after the record's own timestamp")
    sr.check_record(rec(seq_epoch=int(sr.MAX_TIMESTAMP), timestamp=sr.MAX_TIMESTAMP),
                    now=math.inf)


# --------------------------------------------------------------------------- parse_record
def good() -> dict:
    return rec().to_json()


def test_a_record_parsed_from_each_form():
    want = rec()
    assert sr.parse_record(good(), now=T) == want
    assert sr.parse_record(json.dumps(good()), now=T) == want
    assert sr.parse_record(json.dumps(good()).encode(), now=T) == want
    assert sr.parse_record(bytearray(json.dumps(good()).encode()), now=T) == want
    padded = {**good(), "name": "  sami ", "role": " member\t", "local_ip": " 192.168.1.10 ",
              "public_ip": "\n198.51.100.2 ", "extra": [1, 2]}
    assert sr.parse_record(padded, now=T) == want
    assert sr.parse_record(good(), expect_name="SAMI", now=T) == want
    with pytest.raises(RecordError, match="it names 'sami', not 'bob'"):
        sr.parse_record(good(), expect_name="bob", now=T)
    text = json.dumps(good())
    exact = text + " " * (sr.MAX_RECORD_BYTES - len(text))
    assert sr.parse_record(exact.encode(), now=T) == want and sr.parse_record(exact, now=T) == want
    with pytest.raises(RecordError, match="too big"):
        sr.parse_record((exact + " ").encode(), now=T)
    with pytest.raises(RecordError, match="too big"):
        sr.parse_record(exact + " ", now=T)
    assert sr.parse_record({**good(), "sig": "s" * 200}, now=T).sig == "s" * 200
    assert sr.parse_record({**good(), "seq_epoch": int(T)}, now=T).seq_epoch == int(T)


@pytest.mark.parametrize("data, why", [
    (b"\xff{}", "not UTF-8"), ("", "empty"), (b"  \n", "empty"), ("{", "partial copy"),
    ('{"a": 1, "a": 2}', "partial copy"), ("[1]", "not a JSON object"), (7, "not a JSON object"),
    ("[" * 17 + "]" * 17, "partial copy"),
    ({}, "missing field.*version, name, role, local_ip, public_ip, seq, timestamp"),
    ({"version": True}, "version must be a whole number"),
    ({"version": "1"}, "version must be a whole number"),
    ({"name": 5}, "name must be a string"), ({"role": None}, "role must be a string"),
    ({"local_ip": 1}, "local_ip must be a string"), ({"public_ip": []}, "public_ip must be"),
    ({"seq": True}, "seq must be a whole number$"), ({"seq": 5.0}, "seq must be a whole number$"),
    ({"seq_epoch": True}, "seq_epoch must be a whole number"),
    ({"seq_epoch": "1"}, "seq_epoch must be a whole number"),
    ({"sig": 5}, "sig must be"), ({"sig": "s" * 201}, "sig must be"),
    ({"timestamp": 1}, "before the year 2000"), ({"version": 2}, "version 2"),
    ({"name": "-x-"}, "name"),
])
def test_a_record_refused(data, why):
    if isinstance(data, dict) and data:
        data = {**good(), **data}
    with pytest.raises(RecordError, match=why):
        sr.parse_record(data, now=T)


def test_a_deep_record_is_refused_at_its_bound_not_before():
    deep = {**good(), "extra": json.loads("[" * 15 + "]" * 15)}       # 16 deep with the record
    assert sr.parse_record(json.dumps(deep), now=T) == rec()
    too = {**good(), "extra": json.loads("[" * 16 + "]" * 16)}
    with pytest.raises(RecordError):
        sr.parse_record(json.dumps(too), now=T)


# --------------------------------------------------------------------------- successors
def test_which_record_may_follow_the_one_applied():
    prev = rec(seq=5, seq_epoch=int(T) - 100)
    assert sr.successor_problem(None, prev) is None
    assert sr.successor_problem(prev, prev) is None                        # no change
    assert sr.successor_problem(prev, rec(seq=6, seq_epoch=int(T) - 100)) is None
    old = sr.successor_problem(prev, rec(seq=4, seq_epoch=int(T) - 100))
    assert "#4 of 2025-03-01T12:00:00.000Z is older than #5" in old
    assert "conflicting" in sr.successor_problem(prev, rec(seq=5, seq_epoch=int(T) - 100,
                                                           public_ip="198.51.100.9"))
    assert "conflicting" in sr.successor_problem(prev, rec(seq=5, seq_epoch=int(T) - 100,
                                                           timestamp=T + 1))
    earlier = sr.successor_problem(prev, rec(seq=9))
    assert "earlier start (none)" in earlier and "an old copy" in earlier
    assert "earlier start (2025" in sr.successor_problem(
        prev, rec(seq=9, seq_epoch=int(T) - 101))
    # a restart: believed from the second the applied record was written on
    assert sr.successor_problem(prev, rec(seq=1, seq_epoch=int(T), timestamp=T + 5)) is None
    late = rec(seq=5, seq_epoch=int(T) - 100, timestamp=T + 0.9)
    assert sr.successor_problem(late, rec(seq=1, seq_epoch=int(T), timestamp=T + 5)) is None
    why = sr.successor_problem(prev, rec(seq=1, seq_epoch=int(T) - 1))
    assert "not a believable restart" in why and "#5" in why


# --------------------------------------------------------------------------- choosing
def test_the_copy_chosen_and_the_conflicts_noted():
    assert sr.choose_best([]) == (None, [])
    a = Candidate(rec(seq=5), "sami.json")
    b = Candidate(rec(seq=6), "sami.sync-conflict-1.json")
    c = Candidate(rec(seq=2, seq_epoch=int(T)), "z.json")
    assert sr.choose_best([a, b]) == (b, [])
    assert sr.choose_best(iter([a, b, c]))[0] is c                  # a newer counter first
    newer = Candidate(rec(seq=5, timestamp=T + 0.002), "zz.json")
    assert sr.choose_best([a, newer])[0] is newer
    alike = Candidate(rec(seq=5, timestamp=T + 0.0001), "sami.json.bak")
    assert sr.choose_best([alike, a]) == (a, [])                    # same copy: no note
    other = Candidate(rec(seq=5, public_ip="198.51.100.9"), "sami.sync-conflict-2.json")
    best, notes = sr.choose_best([other, a])
    assert best is a and notes == [
        "sami.sync-conflict-2.json has the same seq #5 and time as sami.json but other "
        "content; using sami.json"]
    same_len = Candidate(rec(seq=5, public_ip="198.51.100.9"), "a.json")
    assert sr.choose_best([Candidate(rec(seq=5), "b.json"), same_len])[0] is same_len
    assert sr.choose_best([a, Candidate(rec(seq=5, timestamp=T - 1), "a")])[0] is a
    short = Candidate(rec(seq=5, public_ip="198.51.100.9"), "z.json")   # shorter name first
    assert sr.choose_best([Candidate(rec(seq=5), "aa.json"), short])[0] is short


# --------------------------------------------------------------------------- the applied list
def test_the_applied_records_survive_a_restart(tmp_path):
    assert applied.load_applied(tmp_path) == {}
    far = rec(name="Bob", timestamp=float(int(time.time()) + 10 * 86400), local_ip="192.168.1.11")
    applied.save_applied(tmp_path, {"sami": rec(), "bob": far})
    path = applied.applied_path(tmp_path)
    assert path == tmp_path / "sync" / "applied.json"
    assert (path.stat().st_mode & 0o777) == 0o600
    assert applied.load_applied(tmp_path) == {"sami": rec(), "bob": far}   # far future kept
    data = json.loads(path.read_text())
    assert data["version"] == applied.APPLIED_VERSION and set(data["peers"]) == {"sami", "bob"}


def test_a_damaged_applied_list_loses_only_what_is_damaged(tmp_path):
    applied.save_applied(tmp_path, {"sami": rec()})
    path = applied.applied_path(tmp_path)
    good_entry = rec().to_json()
    for data in ({"version": 2, "peers": {"sami": good_entry}}, {"peers": {"sami": good_entry}},
                 {"version": 1, "peers": [good_entry]}, [1], {"version": 1}):
        path.write_text(json.dumps(data))
        assert applied.load_applied(tmp_path) == {}, data
    path.write_text(json.dumps({"version": 1, "peers": {
        "SAMI": good_entry, "bob": good_entry, "eve": {"name": "eve"}, "x": 5,
        "carl": {**good_entry, "name": "carl", "seq": -1}}}))
    assert applied.load_applied(tmp_path) == {"sami": rec()}
    path.write_text(json.dumps({"version": 1, "peers": {"bob": good_entry}}))
    assert applied.load_applied(tmp_path) == {}          # sami's record kept as bob's: dropped
    many = {f"p{i}": {**good_entry, "name": f"p{i}"} for i in range(applied.MAX_PEERS + 5)}
    path.write_text(json.dumps({"version": 1, "peers": many}))
    got = applied.load_applied(tmp_path)
    assert len(got) == applied.MAX_PEERS and "p0" in got and f"p{applied.MAX_PEERS}" not in got
    path.write_text('{"version": 1, "peers": ' + "[" * 100000 + "]" * 100000 + "}")
    assert applied.load_applied(tmp_path) == {}


@pytest.mark.skipif(os.geteuid() != 0, reason="needs root (hands files to another user)")
def test_root_hands_the_applied_list_to_the_owner_of_the_state_dir(tmp_path):
    """The system service (root) writes a user's state dir: the files it makes are the user's."""
    state = tmp_path / "state"
    state.mkdir()
    os.chown(state, 4321, 4321)
    applied.save_applied(state, {"sami": rec()})
    for p in (state / "sync", applied.applied_path(state)):
        st = p.stat()
        assert (st.st_uid, st.st_gid) == (4321, 4321), p
    assert applied.load_applied(state) == {"sami": rec()}
