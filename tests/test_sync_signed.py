"""A sync record counts only when signed by its owner's key, pinned in the settings (issue 35,
finding 4): an unsigned, forged or replayed record is refused with a line in `sync status`; the
hosts file keeps the owner's last genuine address; a forged record of our own name with the
highest seq never stops us publishing; the DNS store refuses to run without TSIG."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest

from rosnet_tui.core.config.paths import Paths
from rosnet_tui.core.saved.settings import parse_settings, render_settings
from rosnet_tui.core.saved.sync_records import MAX_SEQ, new_record, parse_record
from rosnet_tui.core.sync import FolderStore, SyncService, load_status
from rosnet_tui.core.sync.choose_store import make_store
from rosnet_tui.core.sync.dnsstore import DnsStore
from rosnet_tui.core.sync.signing import (
    key_path,
    parse_public,
    public_text,
    sign_record,
    signature_problem,
)
from rosnet_tui.core.sync.store import StoreConfigError
from rosnet_tui.core.sync.watcher import LocalAddress, PublicLookup
from tests.builders import (
    folder_sync_settings,
    pinned,
    signed_record,
    sync_key,
    sync_key_text,
    sync_laptop_settings,
    write_sync_key,
)

REPO = Path(__file__).resolve().parents[1]


def robot(seq: int, public: str = "203.0.113.7", **kw):
    return new_record("turtlebot", local_ip="10.10.10.1", public_ip=public, role="master",
                      seq=seq, **kw)


def test_signature_covers_every_field_and_only_the_owners_key_counts():
    rec = sign_record(robot(3), sync_key("turtlebot"))
    pub = sync_key("turtlebot").public_key()
    assert signature_problem(rec, pub) is None
    back = parse_record(rec.to_text())                      # survives the file form
    assert back.sig == rec.sig and signature_problem(back, pub) is None
    for change in ({"public_ip": "203.0.113.66"}, {"seq": MAX_SEQ}, {"local_ip": "10.10.10.2"},
                   {"role": "member"}, {"timestamp": rec.timestamp + 1},
                   {"seq_epoch": int(rec.timestamp) - 10}):
        assert "not by turtlebot's key" in signature_problem(replace(rec, **change), pub)
    assert "unsigned" in signature_problem(robot(3), pub)
    assert "not by" in signature_problem(sign_record(robot(3), sync_key("sami")), pub)
    assert "not by" in signature_problem(replace(rec, sig="!!"), pub)
    assert "no sync key of turtlebot is pinned" in signature_problem(rec, None)
    assert rec.next(local_ip="10.10.10.1", public_ip="203.0.113.8", role="master").sig == ""
    assert public_text(parse_public(sync_key_text("rover"))) == sync_key_text("rover")


def test_the_store_refuses_unsigned_and_forged_copies_before_they_compete(tmp_path):
    store = FolderStore(tmp_path)
    store.publish(signed_record("turtlebot", local_ip="10.10.10.1", public_ip="203.0.113.7",
                                role="master", seq=3))
    forged = sign_record(robot(10**6, "203.0.113.66"), sync_key("sami"))
    (tmp_path / "turtlebot.sync-conflict-20260101-000000-AAAAAAA.json").write_text(
        forged.to_text())
    (tmp_path / "turtlebot (conflicted copy).json").write_text(robot(10**6 + 1).to_text())
    res = store.fetch(["turtlebot"], "sami", pinned("turtlebot", "sami"))
    assert res.records["turtlebot"].record.seq == 3         # the genuine one, not the highest
    whys = {r.source: r.why for r in res.refused}
    assert "not by turtlebot's key" in whys["turtlebot.sync-conflict-20260101-000000-AAAAAAA.json"]
    assert "unsigned" in whys["turtlebot (conflicted copy).json"]
    res = store.fetch(["turtlebot"], "sami", {})            # nothing pinned: nothing counts
    assert "turtlebot" not in res.records and "no sync key" in res.refused[0].why


class World:
    """sami following turtlebot through a shared folder (tmp_path), its own key pinned."""

    def __init__(self, tmp_path: Path) -> None:
        self.folder = tmp_path / "shared"
        self.folder.mkdir()
        self.config = tmp_path / "config.toml"
        self.config.write_text(render_settings(folder_sync_settings(self.folder, 2)))
        write_sync_key(self.config, "sami")
        self.hosts = tmp_path / "hosts"
        self.hosts.write_text("127.0.0.1\tlocalhost\n")
        self.state = tmp_path / "state"
        self.public = "198.51.100.2"
        paths = Paths(config_path=self.config, state_dir=self.state, hosts_path=self.hosts)
        self.svc = SyncService(paths, run_checks=False, netlink=False, watch_folder=False,
                               local_source=lambda s: LocalAddress("eth0", "192.168.1.10",
                                                                   "192.168.1.254"),
                               public_source=lambda s: PublicLookup(self.public, "test"))

    def round(self):
        p = self.svc.publisher
        p.next_fetch = p.next_publish = self.svc.applier.next_apply = 0.0
        return self.svc.round()

    def put(self, rec) -> None:
        (self.folder / f"{rec.name}.json").write_text(rec.to_text())

    def entry(self, name: str) -> str | None:
        for line in self.hosts.read_text().splitlines():
            f = line.split("#", 1)[0].split()
            if len(f) >= 2 and name in f[1:]:
                return f[0]
        return None

    def own(self):
        return parse_record((self.folder / "sami.json").read_text())


def test_a_forged_or_replayed_peer_record_changes_nothing_and_is_named(tmp_path):
    w = World(tmp_path)
    genuine3 = sign_record(robot(3), sync_key("turtlebot"))
    w.put(genuine3)
    w.round()
    assert w.entry("turtlebot") == "203.0.113.7"
    w.put(sign_record(robot(10**6, "203.0.113.66"), sync_key("sami")))   # forged, highest seq
    w.round()
    assert w.entry("turtlebot") == "203.0.113.7"
    st = load_status(w.state)
    assert st["refused"][-1]["source"] == "turtlebot.json"
    assert "not by turtlebot's key" in st["refused"][-1]["why"]
    w.put(robot(10**6 + 1, "203.0.113.67"))                               # unsigned
    w.round()
    assert w.entry("turtlebot") == "203.0.113.7"
    assert "unsigned" in load_status(w.state)["refused"][-1]["why"]
    # The owner publishes again, after the forgeries: followed at once.
    w.put(sign_record(robot(4, "203.0.113.8"), sync_key("turtlebot")))
    w.round()
    assert w.entry("turtlebot") == "203.0.113.8"
    w.put(genuine3)                                                       # replayed
    w.round()
    assert w.entry("turtlebot") == "203.0.113.8"
    assert "older than #4" in load_status(w.state)["refused"][-1]["why"]
    r = subprocess.run([sys.executable, "-m", "rosnet_tui", "sync", "status", "--state-dir",
                        str(w.state)], capture_output=True, text=True, timeout=60, cwd=REPO,
                       env={**os.environ, "PYTHONPATH": str(REPO)})
    assert "Last refused record" in r.stdout and "older than #4" in r.stdout, r.stdout


def test_a_forged_record_of_our_own_name_never_stops_us_publishing(tmp_path):
    w = World(tmp_path)
    w.round()
    mine = w.own()
    assert mine.seq == 1 and signature_problem(mine, sync_key("sami").public_key()) is None
    forged = sign_record(new_record("sami", local_ip="192.168.1.66", public_ip="198.51.100.66",
                                    role="member", seq=MAX_SEQ), sync_key("turtlebot"))
    (w.folder / "sami.json").write_text(forged.to_text())
    w.round()
    own = w.own()
    assert (own.seq, own.public_ip) == (2, "198.51.100.2")     # ours again, counting on
    w.public = "198.51.100.9"
    w.svc.watch.next_public = 0
    w.round()
    assert (w.own().seq, w.own().public_ip) == (3, "198.51.100.9")


def test_sync_key_prints_the_line_a_peer_pins(tmp_path):
    cfg = tmp_path / "config.toml"
    cfg.write_text(render_settings(sync_laptop_settings(store="folder", folder=str(tmp_path))))
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    r = subprocess.run([sys.executable, "-m", "rosnet_tui", "sync", "key", "--config", str(cfg)],
                       capture_output=True, text=True, timeout=60, cwd=REPO, env=env)
    assert r.returncode == 0, r.stderr
    line = r.stdout.strip()
    assert line.startswith('sync_key = "ed25519:') and oct(key_path(cfg).stat().st_mode)[-3:] \
        == "600"
    again = subprocess.run([sys.executable, "-m", "rosnet_tui", "sync", "key", "--config",
                            str(cfg)], capture_output=True, text=True, timeout=60, cwd=REPO,
                           env=env)
    assert again.stdout.strip() == line                       # made once
    value = json.loads(line.split("=", 1)[1])
    text = render_settings(sync_laptop_settings()).replace(
        f'sync_key = "{sync_key_text("turtlebot")}"', line)
    assert parse_settings(text).peers[0].sync_key == value    # the line pastes as it is
    bad = sync_laptop_settings()
    bad.peers[0].sync_key = "ed25519:nope"
    assert [k for k, _ in bad.problems() if k.endswith("sync_key")], bad.problems()


def test_the_dns_store_refuses_to_run_without_tsig(tmp_path):
    s = sync_laptop_settings(store="dns", dns_server="192.0.2.53", zone="fleet.example")
    with pytest.raises(StoreConfigError, match="tsig_key_file"):
        make_store(s)
    with pytest.raises(StoreConfigError, match="TSIG"):
        DnsStore("192.0.2.53", "fleet.example", None)


def test_the_sync_key_file_is_read_as_a_regular_file_only(tmp_path):
    """A FIFO where the key should be (the root service reads the owner's folder) is refused at
    once, never waited on; a link there is not followed."""
    import threading

    from rosnet_tui.core.sync.signing import load_or_make_key

    fifo = tmp_path / "config.sync.key"
    os.mkfifo(fifo)
    got: list[BaseException | None] = []

    def load() -> None:
        try:
            load_or_make_key(fifo)
            got.append(None)
        except (OSError, ValueError) as exc:
            got.append(exc)

    th = threading.Thread(target=load, daemon=True)
    th.start()
    th.join(5.0)
    if th.is_alive():                       # unblock the reader before failing
        os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
        th.join(5.0)
        pytest.fail("load_or_make_key waited on a FIFO")
    assert isinstance(got[0], OSError), got
    fifo.unlink()
    (tmp_path / "elsewhere.key").write_bytes(b"x")
    fifo.symlink_to(tmp_path / "elsewhere.key")
    with pytest.raises(OSError):
        load_or_make_key(fifo)
