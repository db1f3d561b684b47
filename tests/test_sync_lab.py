"""`rosnet-tui sync` on the network lab: the robot modem restarts with a new public address and
the laptop's hosts entry follows, with linux.ssh and ros.master passing again, through the
folder store (a folder both namespaces see) and the DNS store (BIND in the internet namespace,
TSIG-signed updates). Also: a peer's garbage record is refused, SIGKILL in the middle of a write
leaves the hosts file whole, and netlink reports an address change at once.

Real Syncthing between namespaces is not used: the shared folder stands in for it.
"""

from __future__ import annotations

import json
import os
import select
import signal
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import pytest

from rosnet_tui.core.files import managed_text as mt
from rosnet_tui.core.files.hosts import parse_hosts
from rosnet_tui.core.saved.sync_records import format_time, new_record
from rosnet_tui.core.sync import FolderStore, StoreError
from rosnet_tui.core.sync.dnsstore import DnsStore
from rosnet_tui.core.sync.signing import sign_record
from rosnet_tui.core.sync.watcher import NetlinkMonitor
from tests.builders import signed_record, sync_key
from tests.lab import ADDR
from tests.sync_support.bench import measure_change_latency, summarize
from tests.sync_support.bind import (
    DEFAULT_IP,
    DEFAULT_ZONE,
    KEY_NAME,
    bind_available,
    new_secret,
    query_a,
    start_bind,
    stop_bind,
    write_key_file,
)
from tests.sync_support.lab_sync import (
    AFFECTED_PASS,
    STOCK_HOSTS,
    SyncRig,
    checks_of,
    hosts_entry,
    prepare_lab,
    resolve,
    sync_argv,
    sync_env,
    wait_for,
    write_sync_config,
)
from tests.sync_support.slow_writer import MARK

pytest_plugins = ["tests.lab.fixtures"]
pytestmark = pytest.mark.lab

REPO = Path(__file__).resolve().parents[1]
WAIT = 30.0          # every wait is bounded; a change takes about 2 s (see the bench)


@pytest.fixture
def rig_lab(lab):
    prepare_lab(lab)
    yield lab
    lab.reset()
    lab.stop_roscore()


def settle(rig: SyncRig) -> None:
    """Both services up, both records published, the laptop's first write checked."""
    lab = rig.lab
    assert rig.published("robot", ADDR.ROBOT_PUBLIC, WAIT), rig.log("robot")
    assert rig.published("laptop", ADDR.LAPTOP_PUBLIC, WAIT), rig.log("laptop")
    assert wait_for(lambda: hosts_entry(lab, "laptop", "turtlebot") == ADDR.ROBOT_PUBLIC, WAIT), \
        rig.log("laptop")
    assert rig.wait_status("laptop", lambda st: st["last_change"].get("checked_at"), WAIT)


def follow_a_modem_restart(rig: SyncRig, new_ip: str) -> dict:
    """Change the robot's public address; the laptop must follow and its checks pass."""
    lab = rig.lab
    t0 = time.time()
    lab.set_robot_wan(new_ip)
    st = rig.followed(new_ip, WAIT, since=t0)
    assert st is not None, f"robot:\n{rig.log('robot')[-4000:]}\nlaptop:\n{rig.log('laptop')[-4000:]}"
    assert hosts_entry(lab, "laptop", "turtlebot") == new_ip
    assert resolve(lab, "laptop", "turtlebot") == new_ip
    # The first round of checks can meet the network mid-change; the service re-runs failing
    # checks after 5 s, so they must pass again within the bounded wait.
    def all_pass(status: dict) -> bool:
        return all(checks_of(status).get(c) == "pass" for c in AFFECTED_PASS)

    st = rig.wait_status("laptop", all_pass, WAIT) or st
    checks = checks_of(st)
    assert all(checks.get(c) == "pass" for c in AFFECTED_PASS), \
        (checks, st["last_change"], rig.log("laptop")[-3000:])
    log = rig.log("laptop")
    assert f"applying: turtlebot {ADDR.ROBOT_PUBLIC} -> {new_ip}" in log
    assert f"+{new_ip}" in log.replace(" ", "")                     # the diff is in the log
    assert "check PASS linux.ssh" in log and "check PASS ros.master" in log
    return st


def test_folder_store_follows_a_modem_restart(rig_lab, tmp_path):
    lab = rig_lab
    folder = tmp_path / "shared"
    folder.mkdir()
    rig = SyncRig(lab, tmp_path, "folder", folder=folder)
    rig.start()
    try:
        settle(rig)
        follow_a_modem_restart(rig, "203.0.113.77")
        robot_record = json.loads((folder / "turtlebot.json").read_text())
        assert robot_record["public_ip"] == "203.0.113.77" and robot_record["seq"] == 2
        # The settings file learned the address too (so `check` and `hosts apply` agree).
        assert 'public_ip = "203.0.113.77"' in rig.configs["laptop"].read_text()
        # `sync status` on the laptop says what happened.
        r = lab.rosnet("laptop", "sync", "status", "--state-dir", str(rig.states["laptop"]),
                       env=sync_env(lab, "laptop"))
        assert r.returncode == 0, r.stdout + r.stderr
        assert "Sync service: running" in r.stdout
        assert "turtlebot: master: local 10.10.10.1, public 203.0.113.77, record #2" in r.stdout
        assert "Last change:" in r.stdout and "203.0.113.2 -> 203.0.113.77" in r.stdout
        assert "PASS ros.master" in r.stdout
    finally:
        codes = rig.stop()
    assert codes == {"robot": 0, "laptop": 0}, codes                  # SIGTERM: a clean stop
    assert rig.status("laptop")["stopped_at"]


@pytest.mark.skipif(not bind_available()[0], reason=bind_available()[1])
def test_dns_store_recovers_from_a_dead_server_and_follows_a_modem_restart(rig_lab, tmp_path):
    lab = rig_lab
    bind_dir = tmp_path / "bind"
    bind_dir.mkdir()
    secret = new_secret()
    target = SimpleNamespace(ip=DEFAULT_IP, zone=DEFAULT_ZONE,
                             key_file=write_key_file(bind_dir / "tsig.key", KEY_NAME, secret))
    rig = SyncRig(lab, tmp_path, "dns", bind=target)  # type: ignore[arg-type]
    rig.start()
    server = None
    try:
        # No DNS server yet: both keep going, say why, and back off.
        for h in ("robot", "laptop"):
            assert lab.wait_output(rig.procs[h], r"store: cannot read the records", WAIT), rig.log(h)
        assert wait_for(lambda: hosts_entry(lab, "laptop", "turtlebot") == ADDR.ROBOT_PUBLIC,
                        WAIT)                                       # from the settings
        # (the status is saved a moment after the hosts file: the settings are written between)
        st = rig.wait_status("laptop", lambda s: "store" in s["errors"], WAIT)
        assert st is not None and "did not answer" in st["errors"]["store"]["message"], st
        server = start_bind(lab, bind_dir, secret=secret)
        # ... and recover by themselves.
        for h in ("robot", "laptop"):
            assert lab.wait_output(rig.procs[h], r"the store answers again", WAIT), rig.log(h)
        settle(rig)
        assert rig.status("laptop")["errors"] == {}
        follow_a_modem_restart(rig, "203.0.113.78")
        assert query_a(lab, server, "turtlebot") == ["203.0.113.78"]  # the A record, for anyone
        assert query_a(lab, server, "sami") == [ADDR.LAPTOP_PUBLIC]
        assert "/key rosnet-sync: updating zone" in server.log()     # signed updates
        # A wrong key is refused by the server: nobody without the key moves a name.
        forger = DnsStore(server.ip, server.zone,
                          write_key_file(tmp_path / "wrong.key", KEY_NAME, new_secret()),
                          timeout_s=2.0)
        with pytest.raises(StoreError, match="refused our TSIG signature"):
            lab.call_in("laptop", forger.publish, new_record(
                "turtlebot", local_ip=ADDR.ROBOT_LOCAL, public_ip="203.0.113.99", role="master",
                seq=10**6))
        assert query_a(lab, server, "turtlebot") == ["203.0.113.78"]
        r = lab.rosnet("laptop", "sync", "status", "--state-dir", str(rig.states["laptop"]),
                       env=sync_env(lab, "laptop"))
        assert "Last error:" in r.stdout and "store:" in r.stdout   # the outage is remembered
        assert f"DNS zone {DEFAULT_ZONE}. on {DEFAULT_IP}" in r.stdout
    finally:
        rig.stop()
        if server is not None:
            stop_bind(server)


def test_a_peers_garbage_record_is_refused_and_never_applied(rig_lab, tmp_path):
    lab = rig_lab
    folder = tmp_path / "shared"
    folder.mkdir()
    robot = FolderStore(folder)           # the test writes the robot's records itself
    robot.publish(signed_record("turtlebot", local_ip=ADDR.ROBOT_LOCAL,
                             public_ip=ADDR.ROBOT_PUBLIC, role="master", seq=3))
    rig = SyncRig(lab, tmp_path, "folder", folder=folder)
    rig.start("laptop", extra=("--no-checks",))
    try:
        assert wait_for(lambda: hosts_entry(lab, "laptop", "turtlebot") == ADDR.ROBOT_PUBLIC,
                        WAIT), rig.log("laptop")
        good = lab.hosts_path("laptop").read_bytes()
        garbage = {"version": 1, "name": "turtlebot", "role": "master", "local_ip": "10.10.10.1",
                   "public_ip": "0.0.0.0", "seq": 1000, "timestamp": format_time(time.time())}
        (folder / "turtlebot.json").write_text(json.dumps(garbage))
        (folder / "turtlebot (conflicted copy 2026-01-01).json").write_text('{"version": 1, "na')
        proc = rig.procs["laptop"]
        assert lab.wait_output(proc, r"refused the record turtlebot\.json .*0\.0\.0\.0", WAIT)
        assert lab.wait_output(proc, r"refused the record turtlebot \(conflicted copy "
                                     r"2026-01-01\)\.json .*not valid JSON", WAIT)
        time.sleep(1.5)                    # several read rounds: still nothing applied
        assert lab.hosts_path("laptop").read_bytes() == good
        st = rig.status("laptop")
        assert {r["source"] for r in st["refused"]} >= {"turtlebot.json",
                                                        "turtlebot (conflicted copy 2026-01-01).json"}
        assert st["peers"]["turtlebot"]["record"]["seq"] == 3       # the last good one stands
        # Another writer of the folder (the laptop's own key, not the robot's) forges the
        # robot's record with a far higher seq: refused, and it blocks nothing after it.
        forged = sign_record(new_record("turtlebot", local_ip=ADDR.ROBOT_LOCAL,
                                        public_ip="203.0.113.66", role="master", seq=10**6),
                             sync_key("sami"))
        (folder / "turtlebot.json").write_text(forged.to_text())
        assert lab.wait_output(proc, r"refused the record turtlebot\.json .*not by "
                                     r"turtlebot's key", WAIT), rig.log("laptop")
        (folder / "turtlebot.json").write_text(new_record(   # unsigned
            "turtlebot", local_ip=ADDR.ROBOT_LOCAL, public_ip="203.0.113.67", role="master",
            seq=10**6 + 1).to_text())
        assert lab.wait_output(proc, r"refused the record turtlebot\.json .*unsigned", WAIT)
        assert lab.hosts_path("laptop").read_bytes() == good
        r = lab.rosnet("laptop", "sync", "status", "--state-dir", str(rig.states["laptop"]),
                       env=sync_env(lab, "laptop"))
        assert "Last refused record" in r.stdout and "turtlebot.json: unsigned" in r.stdout, \
            r.stdout
        assert any("not by turtlebot's key" in x["why"] for x in rig.status("laptop")["refused"])
        # A valid newer record is taken as usual: the service is not stuck on the garbage.
        robot.publish(signed_record("turtlebot", local_ip=ADDR.ROBOT_LOCAL,
                                 public_ip="203.0.113.79", role="master", seq=1001))
        assert wait_for(lambda: hosts_entry(lab, "laptop", "turtlebot") == "203.0.113.79", WAIT)
    finally:
        rig.stop()


def test_sigkill_in_the_middle_of_a_write_leaves_the_hosts_file_whole(rig_lab, tmp_path):
    """The writer's atomicity, proven at its most delicate moment: the new content is on disk in
    the temp file, the rename has not happened, and the process dies by SIGKILL."""
    lab = rig_lab
    folder = tmp_path / "shared"
    folder.mkdir()
    robot = FolderStore(folder)
    robot.publish(signed_record("turtlebot", local_ip=ADDR.ROBOT_LOCAL,
                             public_ip=ADDR.ROBOT_PUBLIC, role="master", seq=1))
    hosts = tmp_path / "etc" / "hosts"       # a regular file: the rename path of the writer
    hosts.parent.mkdir()
    hosts.write_text(STOCK_HOSTS)
    cfg = write_sync_config(lab, "laptop", tmp_path / "laptop.toml", store="folder",
                            folder=folder)
    state = tmp_path / "state"
    args = ("--once", "--hosts-file", str(hosts), "--no-bashrc", "--no-checks")
    env = sync_env(lab, "laptop")
    r = lab.run("laptop", sync_argv(cfg, state, *args), env=env, timeout=60)
    assert r.returncode == 0, r.stderr
    old = hosts.read_bytes()
    assert hosts_entry_in(old, "turtlebot") == ADDR.ROBOT_PUBLIC

    robot.publish(signed_record("turtlebot", local_ip=ADDR.ROBOT_LOCAL, public_ip="203.0.113.80",
                             role="master", seq=2))
    slow = [sys.executable, str(REPO / "tests" / "sync_support" / "slow_writer.py")]
    proc = lab.spawn("laptop", sync_argv(cfg, state, *args, python=slow), env=env)
    try:
        assert lab.wait_output(proc, MARK, WAIT), lab.output(proc)
        temps = [p for p in hosts.parent.iterdir() if p.name.startswith(".hosts.rosnet-tui.")]
        assert len(temps) == 1 and b"203.0.113.80" in temps[0].read_bytes()  # mid-write
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        lab.kill(proc)
    assert proc.returncode == -signal.SIGKILL
    assert hosts.read_bytes() == old                       # whole: the old file, byte for byte
    assert mt.extract_block(old.decode()) is not None

    # The next run finishes the job and clears the dead writer's temp file.
    r = lab.run("laptop", sync_argv(cfg, state, *args), env=env, timeout=60)
    assert r.returncode == 0, r.stderr
    assert hosts_entry_in(hosts.read_bytes(), "turtlebot") == "203.0.113.80"
    assert not [p for p in hosts.parent.iterdir() if p.name.startswith(".hosts.rosnet-tui.")]
    assert hosts.read_text().endswith(STOCK_HOSTS)


def hosts_entry_in(data: bytes, name: str) -> str | None:
    for _, ip, names in parse_hosts(data.decode()):
        if name in names:
            return ip
    return None


def test_netlink_reports_address_and_route_changes_at_once(lab):
    monitor = lab.call_in("robot", NetlinkMonitor.open)
    assert monitor is not None, "no netlink socket in the robot's namespace"
    try:
        assert not monitor.drain()                         # quiet network: nothing pending
        for change in (["ip", "addr", "add", "10.99.0.9/32", "dev", "lo"],
                       ["ip", "route", "add", "10.98.0.0/24", "via", ADDR.ROBOT_GW]):
            assert lab.run("robot", change).returncode == 0
            # the socket is readable by the change itself: an event, no clock (the 5 s bound
            # only ends the wait when no message comes)
            ready, _, _ = select.select([monitor.fileno()], [], [], 5.0)
            assert ready and monitor.drain(), change
    finally:
        lab.run("robot", ["ip", "route", "del", "10.98.0.0/24"])
        lab.run("robot", ["ip", "addr", "del", "10.99.0.9/32", "dev", "lo"])
        monitor.close()


def test_the_service_asks_for_its_public_ip_at_once_when_the_network_changes(rig_lab, tmp_path):
    """Polled every 60 s here, yet an address or route change makes it ask within a second."""
    lab = rig_lab
    folder = tmp_path / "shared"
    folder.mkdir()
    rig = SyncRig(lab, tmp_path, "folder", folder=folder)
    rig.start("laptop", extra=("--no-checks", "--interval", "60"))
    try:
        st = rig.published("laptop", ADDR.LAPTOP_PUBLIC, WAIT)
        assert st, rig.log("laptop")
        asked = st["own"]["public_checked_at"]
        t0 = time.time()
        assert lab.run("laptop", ["ip", "addr", "add", "10.99.0.9/32", "dev", "lo"]).returncode == 0
        assert lab.wait_output(rig.procs["laptop"], "the kernel reports a link, address or route "
                                                    "change", 5.0), rig.log("laptop")
        st = rig.wait_status("laptop", lambda s: s["own"]["public_checked_at"] > asked, 5.0)
        assert st is not None and st["own"]["public_checked_at"] - t0 < 3.0
    finally:
        lab.run("laptop", ["ip", "addr", "del", "10.99.0.9/32", "dev", "lo"])
        rig.stop()


def test_a_record_change_while_the_checks_wait_is_applied_at_once(rig_lab, tmp_path):
    """Issue 17: the affected checks can wait seconds on a peer that does not answer; a newer
    record meanwhile is applied at once all the same (the checks do not hold the loop), and the
    verdicts recorded are those of the current address."""
    lab = rig_lab
    folder = tmp_path / "shared"
    folder.mkdir()
    robot = FolderStore(folder)            # the test writes the robot's records itself

    def publish(public_ip: str, seq: int) -> None:
        robot.publish(signed_record("turtlebot", local_ip=ADDR.ROBOT_LOCAL, public_ip=public_ip,
                                 role="master", seq=seq))

    publish(ADDR.ROBOT_PUBLIC, 1)
    rig = SyncRig(lab, tmp_path, "folder", folder=folder)
    rig.start("laptop")
    try:
        assert wait_for(lambda: hosts_entry(lab, "laptop", "turtlebot") == ADDR.ROBOT_PUBLIC,
                        WAIT), rig.log("laptop")
        st = rig.wait_status("laptop", lambda st: st["last_change"].get("checked_at"), WAIT)
        assert st and checks_of(st) == {c: "pass" for c in AFFECTED_PASS}, \
            f"{lab.roscore_said()}\n{st and st['last_change']}"    # the baseline; a str: whole
        # Nothing answers at this address: linux.ssh and ros.master wait for their timeouts.
        publish(ADDR.STALE_ROBOT_PUBLIC, 2)
        assert wait_for(lambda: hosts_entry(lab, "laptop", "turtlebot") ==
                        ADDR.STALE_ROBOT_PUBLIC, WAIT), rig.log("laptop")
        time.sleep(0.3)                    # the checks are waiting now
        t_wall = time.time()
        publish(ADDR.ROBOT_PUBLIC, 3)
        t0 = time.monotonic()
        assert wait_for(lambda: hosts_entry(lab, "laptop", "turtlebot") == ADDR.ROBOT_PUBLIC,
                        WAIT, step=0.01), rig.log("laptop")
        took = time.monotonic() - t0
        assert took <= 0.5, (took, rig.log("laptop")[-3000:])
        st = rig.followed(ADDR.ROBOT_PUBLIC, WAIT, since=t_wall)
        assert st is not None, rig.log("laptop")[-3000:]
        assert checks_of(st) == {c: "pass" for c in AFFECTED_PASS}, \
            f"{lab.roscore_said()}\n{st['last_change']}\n{rig.log('laptop')[-3000:]}"
        # Stopping while checks wait on a silent peer is quick and clean all the same.
        publish(ADDR.STALE_ROBOT_PUBLIC, 4)
        assert wait_for(lambda: hosts_entry(lab, "laptop", "turtlebot") ==
                        ADDR.STALE_ROBOT_PUBLIC, WAIT), rig.log("laptop")
        time.sleep(0.3)
        t0 = time.monotonic()
        codes = rig.stop()
        assert codes == {"laptop": 0} and time.monotonic() - t0 < 5.0, (codes, rig.log("laptop"))
    finally:
        rig.stop()


def test_ten_address_changes_at_random_moments_are_each_followed_within_3_s(rig_lab, tmp_path):
    """Issue 17, done when: interval_s = 2, the folder store; each of ten changes of the robot's
    public address, at random moments of the poll cycle, reaches the laptop's hosts file within
    3 s (the master's poll, at most 2 s, then the member at once). Changes do not wait for the
    previous change's checks: they run meanwhile, and must not hold the member back."""
    t0 = time.monotonic()
    runs = measure_change_latency(rig_lab, "folder", tmp_path, interval_s=2.0, changes=10,
                                  timeout_s=10.0, wait_checks=False)
    took = [r.hosts_s for r in runs]
    summary = summarize(runs)
    print(f"change to member updated (s): {[round(x, 2) if x else x for x in took]}; "
          f"{summary['hosts_s']}")
    assert len(runs) == 10
    assert all(x is not None and x <= 3.0 for x in took), [r.to_json() for r in runs]
    # the member followed the published record at once (within 0.5 s of it being complete)
    lag = [r.member_s for r in runs if r.member_s is not None]
    assert len(lag) == 10 and max(lag) <= 0.5, lag
    assert time.monotonic() - t0 < 75


def test_a_slow_public_ip_lookup_does_not_hold_back_a_peers_record(rig_lab, tmp_path):
    """Issue 17: one of the member's what-is-my-IP services never answers, so each of its own
    public-IP lookups takes most of its timeout (every interval_s = 2 s); a peer's record that
    changes meanwhile is applied at once all the same."""
    import random

    from rosnet_tui.core.config.settings_model import SyncSettings
    from tests.sync_support.lab_sync import write_pinned

    lab = rig_lab
    folder = tmp_path / "shared"
    folder.mkdir()
    robot = FolderStore(folder)
    robot.publish(signed_record("turtlebot", local_ip=ADDR.ROBOT_LOCAL, public_ip=ADDR.ROBOT_PUBLIC,
                             role="master", seq=1))
    s = lab.settings("laptop")
    s.probe.public_ip_urls.append(f"http://{ADDR.STALE_ROBOT_PUBLIC}/ip")   # nothing answers
    s.sync = SyncSettings(store="folder", interval_s=2.0, folder=str(folder))
    s.has_sync = True
    config = write_pinned(s, tmp_path / "laptop.toml")
    proc = lab.spawn("laptop", sync_argv(config, tmp_path / "state", "--no-checks",
                                         "--bashrc", str(lab.bashrc_path("laptop"))),
                     env=sync_env(lab, "laptop"))
    try:
        assert wait_for(lambda: hosts_entry(lab, "laptop", "turtlebot") == ADDR.ROBOT_PUBLIC,
                        WAIT), lab.output(proc)
        assert lab.wait_output(proc, r"services did not answer|public IP", WAIT)
        rng = random.Random()
        took = []
        for seq, ip in enumerate(["203.0.113.77", "203.0.113.78"] * 3, start=2):
            time.sleep(rng.uniform(0.0, 2.0))
            robot.publish(signed_record("turtlebot", local_ip=ADDR.ROBOT_LOCAL, public_ip=ip,
                                     role="master", seq=seq))
            t0 = time.monotonic()
            assert wait_for(lambda ip=ip: hosts_entry(lab, "laptop", "turtlebot") == ip, WAIT,
                            step=0.01), lab.output(proc)
            took.append(round(time.monotonic() - t0, 2))
        assert max(took) <= 0.5, (took, lab.output(proc)[-3000:])
    finally:
        lab.kill(proc)
