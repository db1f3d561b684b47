"""Issue 29 section 5: a torn /etc/hosts that the next run did not complete.

/etc/hosts is a bind mount here (as in a container), so the writers rewrite it in place. `hosts
apply` and `undo` are killed (SIGKILL) on a small and a 2 MB file: at random moments, inside the
one write of the new bytes, and at the writer's own crash point just before the truncation. After
each kill the next run of rosnet-tui must find the old or the new file, leave it so on disk and
leave no journal behind: `hosts show`, `check`, a run that stops before it reads the file (its
settings are missing), and a user who may not write /etc/hosts (who must be told plainly that the
file is torn and which command completes it; root's next run then completes it).

Reproduced before the fix: the run that stopped before reading left the file torn (new bytes at
the head, old ones after), and the user's `hosts show` said nothing and left it torn.
"""

from __future__ import annotations

import json
import os
import random
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from rosnet_tui.core.files import cut_writes
from rosnet_tui.core.files import managed_write as mw
from tests.builders import ROBOT_CONFIG, random_hosts
from tests.hardening_tally import tally
from tests.writers_support.bench import NOBODY, HostsBench, bench_problem

AREA = "writers under SIGKILL"
BENCH = pytest.mark.skipif(bench_problem() is not None, reason=str(bench_problem()))
ROOT = pytest.mark.skipif(os.geteuid() != 0, reason="needs root (to act as another user)")


def _big(n_bytes: int, seed: int) -> bytes:
    """A 2 MB hosts file: its own lines, then long comment lines (the bytes make the write long;
    few lines keep each command quick)."""
    rng = random.Random(seed)
    letters = bytes(b"abcdefghij "[i % 11] for i in range(256))
    head = b"127.0.0.1\tlocalhost\n::1\tip6-localhost\n" + random_hosts(20_000, seed)
    lines, size = [], len(head)
    while size < n_bytes:
        line = b"# " + rng.randbytes(1000).translate(letters) + b"\n"
        lines.append(line)
        size += len(line)
    return head + b"".join(lines)


SMALL = b"127.0.0.1\tlocalhost\n::1\tip6-localhost\n10.0.0.9\tprinter\n"


class Judge:
    """Old or new: what the file may hold after a run that was not killed."""

    def __init__(self, bench: HostsBench) -> None:
        self.bench = bench
        self.plain = bench.src.read_bytes()          # no rosnet-tui block
        self.block: bytes | None = None              # with our block (learned from the apply)

    def kind(self) -> str:
        data = self.bench.src.read_bytes()
        return "plain" if data == self.plain else "block" if data == self.block else "torn"


def _kill_plan(rng: random.Random, big: bool, i: int) -> list:
    if i % 10 == 3:
        return ["truncate"]                               # the writer's own crash point
    roll = rng.random()
    if roll < 0.35:
        return ["cut", rng.random()]                      # inside the one write call
    if roll < 0.85:                                       # near the writes, a random moment
        return ["mark", rng.randint(1, 4), rng.uniform(0, 0.012 if big else 0.002)]
    return ["timer", rng.uniform(0.0, 0.25 if big else 0.12)]    # anywhere in the command


def _next_run(bench: HostsBench, judge: Judge, which: int, before: str) -> None:
    """One run after a kill; the file must be old or new after it, and so must its view be."""
    cfg = bench.cfg()
    if which == 0:
        r = bench.run("hosts", "show", *cfg)
        assert r.rc == 0, r.err
        now = judge.kind()
        want = "has no rosnet-tui block yet" if now == "plain" else "set is active"
        assert want in r.out, (now, r.out[-600:], r.err)
    elif which == 1:
        r = bench.run("check", "--step", "linux", "--json", "-q", *cfg)
        checks = {c["id"]: c for c in json.loads(r.out)["checks"]}
        now = judge.kind()
        want = "fail" if now == "plain" else "pass"
        assert checks["linux.hosts"]["status"] == want, (now, checks["linux.hosts"])
        if now == "block":   # the resolver read the whole file too (glibc, not our reader)
            assert checks["linux.resolve"]["status"] == "pass", checks["linux.resolve"]
    elif which == 2:   # stops before it reads the hosts file: no settings there
        r = bench.run("hosts", "show", "--config", str(bench.dir / "missing.toml"))
        assert r.rc == 2, r.err
    else:              # a user who may not write /etc/hosts, then root
        r = bench.run("hosts", "show", *cfg, uid=NOBODY)
        if before == "torn":
            # said at start-up, with the exact command that completes it as root
            assert "rosnet-tui: /etc/hosts is torn" in r.err, r.err
            assert f"run: sudo {sys.executable} -m rosnet_tui hosts show --config " \
                   f"{bench.config}" in r.err, r.err
            assert "/etc/hosts is torn" in r.out                  # and where show looks at it
            assert r.rc == 1, r.out                               # a failed state
            assert judge.kind() == "torn"                     # the user could not complete it
        else:
            assert r.rc == 0, r.err
        r = bench.run("hosts", "show", *cfg)
        assert r.rc == 0, r.err
        if before == "torn":
            assert "completed" in r.err, r.err
    after = judge.kind()
    assert after in ("plain", "block"), f"after the next run ({which}) the file is {after}"
    assert bench.journals() == [], bench.journals()


def _kill_many(bench: HostsBench, kills: int, seed: int, big: bool) -> dict:
    judge = Judge(bench)
    cfg = bench.cfg()
    apply = ["hosts", "apply", "--yes", "--no-checks", *cfg]
    undo = ["undo", "--yes", "--no-checks", *cfg]
    r = bench.run(*apply)                                 # learn the new content once
    assert r.rc == 0, r.err
    judge.block = bench.src.read_bytes()
    rng = random.Random(seed)
    stats = {"kills": 0, "torn": 0, "apply": 0, "undo": 0, "truncate": 0, "runs": 0}
    started = time.monotonic()
    for _ in range(3 * kills):            # a kill that came after the command's end is no kill
        if stats["kills"] == kills:
            break
        state = judge.kind()
        assert state in ("plain", "block"), state
        cmd = apply if state == "plain" else undo
        crash = _kill_plan(rng, big, stats["kills"])
        r = bench.run(*cmd, crash=crash)
        if not r.killed:                                  # the kill came after its end
            assert r.rc == 0, (crash, r.err)
            continue
        stats["kills"] += 1
        stats[cmd[0] if cmd[0] == "undo" else "apply"] += 1
        stats["truncate"] += crash[0] == "truncate"
        before = judge.kind()
        stats["torn"] += before == "torn"
        _next_run(bench, judge, stats["kills"] % 4, before)
        stats["runs"] += 1
    stats["seconds"] = round(time.monotonic() - started, 1)
    return stats


KILLS = {"small": 135, "2MB": 70}     # 205 in all


@BENCH
@pytest.mark.parametrize("size", list(KILLS))
def test_kills_of_apply_and_undo_in_place_leave_old_or_new_after_the_next_run(size):
    big = size == "2MB"
    with HostsBench(_big(2_000_000, 29) if big else SMALL, ROBOT_CONFIG) as bench:
        stats = _kill_many(bench, kills=KILLS[size], seed=29 + big, big=big)
    print(stats)
    assert stats["kills"] == KILLS[size], stats
    assert stats["apply"] >= 20 and stats["undo"] >= 20, stats
    assert stats["truncate"] >= KILLS[size] // 10, stats
    assert stats["torn"] >= 10, f"too few kills left the file torn to test its completion: {stats}"
    tally(AREA, stats["kills"], stats["kills"], f"apply/undo in place, {size}, next run")


# --------------------------------------------------------------------------- in process
class _Crash(BaseException):
    """Stands for the process dying at that instant (nothing after it runs)."""


def _crash() -> None:
    raise _Crash


def _cut(target: Path, new: bytes, monkeypatch, journal_dir: Path | None = None) -> bytes:
    """Rewrite *target* in place with *new*, dying before the truncation: the torn bytes."""
    monkeypatch.setattr(mw, "is_mount_point", lambda p: True)   # as a bind mount would
    monkeypatch.setattr(mw, "_before_truncate", _crash)
    with pytest.raises(_Crash):
        mw.write_file(target, new, journal_dir=journal_dir)
    monkeypatch.setattr(mw, "_before_truncate", None)
    monkeypatch.setattr(mw, "is_mount_point", lambda p: False)
    return target.read_bytes()


OLD = b"127.0.0.1\tlocalhost\n" + b"10.9.9.9\tsomething-long-enough\n" * 200
NEW = b"127.0.0.1\tlocalhost\n# rosnet-tui was here\n"


def test_with_nothing_pending_start_up_only_looks(tmp_path):
    """The look-ahead every command runs costs a few stats: the writer is not even imported."""
    code = ("import sys\nfrom rosnet_tui.cli.common import complete_cut_writes\n"
            "complete_cut_writes(['hosts', 'show', '--file', sys.argv[1]])\n"
            "print('rosnet_tui.core.files.managed_write' in sys.modules)\n")
    target = tmp_path / "hosts"
    target.write_bytes(OLD)
    env = dict(os.environ, HOME=str(tmp_path), XDG_STATE_HOME=str(tmp_path / "state"))
    r = subprocess.run([sys.executable, "-c", code, str(target)], capture_output=True,
                       text=True, timeout=60, env=env)
    assert (r.returncode, r.stdout.strip(), r.stderr) == (0, "False", "")
    assert cut_writes.pending([target, tmp_path / "missing"], [tmp_path / "state"]) == []


def test_a_command_that_never_reads_the_file_completes_its_cut_write_first(tmp_path,
                                                                          monkeypatch, capsys):
    """`hosts show` with no usable settings stops before it reads the hosts file: the start-up
    completes the cut write all the same, and says so."""
    from rosnet_tui.cli import main

    target = tmp_path / "hosts"
    target.write_bytes(OLD)
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "state"))
    assert _cut(target, NEW, monkeypatch) not in (OLD, NEW)
    assert cut_writes.pending([target], []) == [(str(target), None)]
    assert main(["hosts", "show", "--file", str(target), "--config",
                 str(tmp_path / "missing.toml")]) == 2
    assert target.read_bytes() == NEW
    err = capsys.readouterr().err
    assert f"rosnet-tui: {target} was torn (a write of rosnet-tui was cut short): completed" in err
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".inplace")]


def test_a_cut_write_journaled_in_a_state_dir_is_found_by_the_journal_alone(tmp_path,
                                                                           monkeypatch, capsys):
    """Where the file's folder may not be written, the journal lies in the writer's state dir
    and names its file: the start-up of a run given that state dir completes it, though the
    run names no file."""
    from rosnet_tui.cli import main

    folder, sd = tmp_path / "etc", tmp_path / "sd"
    folder.mkdir()
    target = folder / "hosts"
    target.write_bytes(OLD)
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "elsewhere"))
    real_access = os.access
    monkeypatch.setattr(os, "access", lambda p, m, **kw: False if Path(p) == folder
                        else real_access(p, m, **kw))
    assert _cut(target, NEW, monkeypatch, journal_dir=sd / cut_writes.INPLACE_DIR) \
        not in (OLD, NEW)
    assert cut_writes.pending([], [sd]) == [(str(target), str(sd / cut_writes.INPLACE_DIR))]
    main(["undo", "--dry-run", "--state-dir", str(sd)])
    assert target.read_bytes() == NEW
    assert "was torn" in capsys.readouterr().err
    assert list((sd / cut_writes.INPLACE_DIR).iterdir()) == []


def test_the_torn_window_is_one_write_and_one_truncation(tmp_path, monkeypatch):
    """In place, other programs may read a mix only from the write of the new bytes to the
    truncation: one write call of the whole buffer, the truncation right after it, no fsync in
    between (it was write, fsync, truncate, fsync)."""
    target = tmp_path / "hosts"
    target.write_bytes(OLD)
    calls: list[str] = []
    for name in ("pwrite", "write", "ftruncate", "fsync"):
        real = getattr(os, name)

        def spy(fd, *a, _real=real, _name=name):
            try:
                same = os.path.samestat(os.fstat(fd), os.stat(target))
            except OSError:
                same = False
            if same:
                calls.append(_name if _name != "pwrite" else f"pwrite {len(a[0])}")
            return _real(fd, *a)
        monkeypatch.setattr(os, name, spy)
    monkeypatch.setattr(mw, "is_mount_point", lambda p: True)
    mw.write_file(target, NEW)
    monkeypatch.undo()
    assert target.read_bytes() == NEW
    assert calls == [f"pwrite {len(NEW)}", "ftruncate", "fsync"], calls


def test_a_mix_by_sectors_is_completed_and_a_foreign_change_is_left(tmp_path, monkeypatch):
    """After the machine itself went down, the disk may hold some sectors of the new bytes and
    some of the old, not a clean prefix: still a mix only our write leaves, so it is completed;
    an edit by someone else is not (the journal is dropped, the file left alone)."""
    target = tmp_path / "hosts"
    old, new = random_hosts(8192, 40), random_hosts(8192, 41)[:6000]
    for shape, done in (("sectors", True), ("foreign", False)):
        target.write_bytes(old)
        _cut(target, new, monkeypatch)
        if shape == "sectors":   # sectors 0 and 2 new, 1 and 3 old, the tail old
            mixed = new[:512] + old[512:1024] + new[1024:1536] + old[1536:]
        else:
            mixed = b"# the admin put this here\n" + old[27:]
        target.write_bytes(mixed)
        assert mw.read_bytes(target) == (new if done else mixed), shape
        assert target.read_bytes() == (new if done else mixed), shape
        assert not [p for p in tmp_path.iterdir() if p.name.endswith(".inplace")]


def _cut_by_root_for_a_user(top: Path, monkeypatch) -> tuple[Path, Path, bytes]:
    """Under *top*: root's in-place write of etc/hosts cut before truncation, journalled in a
    state folder of the user nobody's (root may not write etc/, so the journal goes there);
    (the file, that state folder, the torn bytes)."""
    os.chmod(top, 0o755)
    folder, sd = top / "etc", top / "state"
    folder.mkdir(mode=0o755)
    sd.mkdir(mode=0o700)
    os.chown(sd, NOBODY, NOBODY)
    target = folder / "hosts"
    target.write_bytes(OLD)
    os.chmod(target, 0o644)
    real_access = os.access
    monkeypatch.setattr(os, "access", lambda p, m, **kw: False if Path(p) == folder
                        else real_access(p, m, **kw))
    torn = _cut(target, NEW, monkeypatch, journal_dir=sd / cut_writes.INPLACE_DIR)
    monkeypatch.undo()
    return target, sd, torn


@ROOT
def test_roots_journal_in_a_users_state_dir_is_seen_by_that_user(monkeypatch):
    """root (sudo) writing a file whose folder it may not write journals in the user's state
    dir: that folder stays readable to the user (only root may change it), so the user's run
    finds the file torn and says so instead of reading the mix."""
    top = Path(tempfile.mkdtemp(prefix="rosnet-torn-"))
    try:
        target, sd, torn = _cut_by_root_for_a_user(top, monkeypatch)
        jdir = sd / cut_writes.INPLACE_DIR
        assert os.stat(jdir).st_uid == 0 and os.stat(jdir).st_mode & 0o777 == 0o755
        os.setegid(NOBODY)
        os.seteuid(NOBODY)
        try:
            found = cut_writes.pending([], [sd])
            said = mw.complete_cut_writes(found)
            with pytest.raises(mw.TornFileError):
                mw.read_bytes(target, state_dir=sd)
        finally:
            os.seteuid(0)
            os.setegid(0)
        assert found == [(str(target), str(jdir))]
        assert len(said) == 1 and f"{target} is torn" in said[0], said
        assert f"--file {target} --state-dir {sd}" in said[0]
        assert target.read_bytes() == torn
        assert mw.read_bytes(target, state_dir=sd) == NEW                 # root completes it
    finally:
        import shutil

        shutil.rmtree(top, ignore_errors=True)


@ROOT
def test_hosts_show_on_a_torn_file_only_root_may_complete_fails(monkeypatch, capsys):
    """`hosts show` by a user who may not complete the torn file: it says so and exits 1 (a
    failed state, not a usage error), not 0 as if all were well."""
    from rosnet_tui.cli import main

    top = Path(tempfile.mkdtemp(prefix="rosnet-torn-"))
    try:
        target, sd, torn = _cut_by_root_for_a_user(top, monkeypatch)
        cfg = top / "config.toml"
        cfg.write_text(ROBOT_CONFIG)
        os.chmod(cfg, 0o644)
        monkeypatch.setenv("XDG_STATE_HOME", str(sd))
        os.setegid(NOBODY)
        os.seteuid(NOBODY)
        try:
            rc = main(["hosts", "show", "--file", str(target), "--state-dir", str(sd),
                       "--config", str(cfg)])
        finally:
            os.seteuid(0)
            os.setegid(0)
        out = capsys.readouterr()
        assert f"{target} is torn" in out.out + out.err
        assert rc == 1, (out.out, out.err)
        assert target.read_bytes() == torn
    finally:
        import shutil

        shutil.rmtree(top, ignore_errors=True)
