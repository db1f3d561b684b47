"""Issue 15, the writers under SIGKILL: in place (a bind-mounted file, as /etc/hosts in containers
and under ``ip netns exec``) and by rename, with real processes killed at random moments.

Reproduced: a SIGKILL during ``hosts apply`` of a large bind-mounted file left the first bytes new
and the rest old; a kill during ``undo`` between the padded write and the truncation left blank
lines, after which undo refused ("changed by someone else"); temp files of killed writers stayed
(in the state folder, and a full copy of ~/.bashrc beside it). Now an in-place write is journaled
and the next run completes it; the next run removes the temp files that are ours.

The kill tests run each writer in its own mount namespace (``unshare -m``) with a private bind
mount of a large file, so nothing leaks into the machine's mounts.
"""

from __future__ import annotations

import os
import random
import select
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from rosnet_tui.core.files import managed_file as mf
from rosnet_tui.core.files import managed_text as mt
from rosnet_tui.core.files import managed_write as mw
from tests.builders import ROBOT_CONFIG, random_hosts
from tests.hardening_tally import tally

REPO = Path(__file__).resolve().parents[1]
AREA = "writers under SIGKILL"
ROOT_AND_MOUNT = pytest.mark.skipif(
    os.geteuid() != 0 or not shutil.which("unshare") or not shutil.which("mount"),
    reason="needs root, unshare(1) and mount(8)")
BODY = [f"203.0.113.{i % 250 + 1}  peer-{i}  # a peer of the test" for i in range(3000)]


_CHILD = textwrap.dedent("""
    import sys
    from pathlib import Path
    from rosnet_tui.core.files import managed_file as mf
    from rosnet_tui.core.files import managed_text as mt
    from rosnet_tui.core.files import managed_write as mw
    from rosnet_tui.core.files import undo_journal as uj
    mode, dst, state, fa, fb = sys.argv[1:6]
    dst, state = Path(dst), Path(state)
    A, B = Path(fa).read_bytes(), Path(fb).read_bytes()
    out = sys.stdout
    def cls(x):
        return "A" if x == A else "B" if x == B else "X%d" % (len(x) if x is not None else -1)
    out.write("S %s\\n" % cls(mw.read_bytes(dst))); out.flush()   # the next run: recovered?
    if mode == "check":
        sys.exit(0)
    write_all = mw.write_all
    def marked(fd, data):            # a mark before every large write: the parent kills then
        if len(data) > 100000:
            out.write("W\\n"); out.flush()
        write_all(fd, data)
    mw.write_all = marked
    uj.JOURNAL_KEEP = 3
    body = __BODY__
    for i in range(100000):
        cur = mw.read_bytes(dst)
        if cls(cur)[0] == "X":
            out.write("BAD %s\\n" % cls(cur)); out.flush(); sys.exit(3)
        if mode == "raw":
            mw.write_file(dst, B if cur == A else A)
        elif cur == A:
            mf.apply_preview(mf.preview_block(dst, body, position="top"), state_dir=state)
        else:
            plan = mf.plan_undo(state)
            if plan.conflicts:
                out.write("BAD undo conflict\\n"); out.flush(); sys.exit(4)
            mf.apply_undo(plan)
""").replace("__BODY__", repr(BODY))


class KillBench:
    """Writers in private mount namespaces, each with SRC bind-mounted on DST, killed at will."""

    def __init__(self, tmp_path: Path, a: bytes, b: bytes) -> None:
        self.dir = tmp_path
        self.src, self.dst, self.state = tmp_path / "netns-hosts", tmp_path / "hosts", \
            tmp_path / "state"
        self.fa, self.fb = tmp_path / "a.bin", tmp_path / "b.bin"
        self.a, self.b = a, b
        self.fa.write_bytes(a)
        self.fb.write_bytes(b)
        self.src.write_bytes(a)
        self.dst.write_bytes(b"the file underneath the mount\n")
        self.underneath = self.dst.read_bytes()
        self.script = tmp_path / "writer.py"
        self.script.write_text(_CHILD)

    def spawn(self, mode: str) -> subprocess.Popen:
        inner = " ".join([sys.executable, "-S", str(self.script), mode, str(self.dst),
                          str(self.state), str(self.fa), str(self.fb)])
        script = f"mount --bind {self.src} {self.dst} && exec {inner}"
        return subprocess.Popen(["unshare", "-m", "--propagation", "private", "sh", "-c", script],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                env=dict(os.environ, PYTHONPATH=str(REPO)), cwd=REPO)

    def classify(self, data: bytes) -> str:
        return "A" if data == self.a else "B" if data == self.b else "torn"

    def journals(self) -> list[str]:
        return [p.name for p in self.dir.iterdir() if p.name.endswith(".inplace")]


def _lines(proc: subprocess.Popen, deadline: float):
    """Lines the child writes, as they come, until *deadline* or its end."""
    fd = proc.stdout.fileno()
    buf = b""
    while time.monotonic() < deadline:
        r, _, _ = select.select([fd], [], [], max(0.0, deadline - time.monotonic()))
        if not r:
            return
        chunk = os.read(fd, 4096)
        if not chunk:
            return
        buf += chunk
        while b"\n" in buf:
            line, buf = buf.split(b"\n", 1)
            yield line.decode(errors="replace")


def run_kills(bench: KillBench, mode: str, kills: int, seed: int) -> dict:
    """*kills* SIGKILLs, however long they take (a budget of seconds made the count, and so the
    verdict, depend on how busy the machine was)."""
    rng = random.Random(seed)
    stats = {"kills": 0, "torn_seen": 0, "recovered": 0, "old": 0, "new": 0, "starts": 0}
    started = time.monotonic()
    prev = "A"
    while stats["kills"] < kills:
        proc = bench.spawn(mode)
        try:
            lines = _lines(proc, time.monotonic() + 20)
            first = next(lines, "")
            assert first.startswith("S "), (first, proc.stderr.read()[-2000:] if proc.poll()
                                            is not None else "")
            got = first.split()[1]
            # the next run found the old or the new content, or completed the torn write
            assert got in ("A", "B"), f"after kill {stats['kills']}: the next run read {got}"
            stats["starts"] += 1
            if prev == "torn":
                stats["recovered"] += 1
            want = rng.randint(1, 4)
            seen = 0
            for line in lines:
                assert not line.startswith("BAD"), line
                if line == "W":
                    seen += 1
                    if seen >= want:
                        break
            time.sleep(rng.uniform(0, 0.004))
        finally:
            proc.send_signal(signal.SIGKILL)
            proc.wait(timeout=10)
            proc.stdout.close()
            proc.stderr.close()
        stats["kills"] += 1
        prev = bench.classify(bench.src.read_bytes())
        if prev == "torn":
            stats["torn_seen"] += 1
            assert bench.journals(), "a torn file without a journal to complete it"
        else:
            stats["old" if prev == "A" else "new"] += 1
    # One last run: whatever the last kill left is completed.
    proc = bench.spawn("check")
    out, err = proc.communicate(timeout=30)
    assert out.decode().split()[1] in ("A", "B"), (out, err[-2000:])
    if prev == "torn":
        stats["recovered"] += 1
    stats["seconds"] = round(time.monotonic() - started, 1)
    return stats


@ROOT_AND_MOUNT
def test_hundreds_of_sigkills_during_in_place_writes_of_a_large_bind_mounted_file(tmp_path):
    """Raw writes, large file (2 MB and 2.5 MB versions): 120 kills, each at a random moment of
    a large write (the journal's or the file's)."""
    bench = KillBench(tmp_path, random_hosts(2_000_000, 1), random_hosts(2_500_000, 2))
    stats = run_kills(bench, "raw", kills=120, seed=15)
    print(stats)
    assert stats["kills"] == 120, stats
    # Few kills land inside the rewrite itself now that it is one write and the truncation (no
    # fsync between them): tests/test_hosts_torn.py kills inside that write on purpose.
    assert stats["recovered"] == stats["torn_seen"], stats
    assert not bench.journals()
    assert not [p.name for p in tmp_path.iterdir() if p.name.endswith(".tmp")]
    assert bench.dst.read_bytes() == bench.underneath           # the mount never leaked
    tally(AREA, stats["kills"], stats["kills"], "in place, raw, 2 MB")


@ROOT_AND_MOUNT
def test_hundreds_of_sigkills_during_apply_and_undo_in_place(tmp_path):
    """hosts apply / undo of a 3,000-line block on top of a 1 MB bind-mounted file: 60 kills;
    after each, the next run reads the old or the new file and undo never finds a conflict."""
    a = random_hosts(1_000_000, 3)
    b = mt.encode(mt.compose_block(mt.decode(a), BODY, position="top"))
    bench = KillBench(tmp_path, a, b)
    stats = run_kills(bench, "apply", kills=60, seed=16)
    print(stats)
    assert stats["kills"] == 60, stats
    assert stats["recovered"] == stats["torn_seen"], stats
    assert not bench.journals()
    assert bench.dst.read_bytes() == bench.underneath
    tally(AREA, stats["kills"], stats["kills"], "in place, apply/undo, 1 MB")


# --------------------------------------------------------------------------- deterministic cuts
class _Crash(BaseException):
    """Stands for the process dying at that instant (nothing after it runs)."""


def _bind(src: Path, dst: Path) -> None:
    r = subprocess.run(["mount", "--bind", str(src), str(dst)], capture_output=True, text=True,
                       timeout=10)
    if r.returncode != 0:
        pytest.skip(f"cannot bind-mount here: {r.stderr.strip()}")


def _umount(dst: Path) -> None:
    subprocess.run(["umount", str(dst)], timeout=10, check=False)


def _crash() -> None:
    raise _Crash


@pytest.mark.skipif(os.geteuid() != 0 or not shutil.which("mount"), reason="needs root, mount(8)")
@pytest.mark.parametrize("hook", ["_before_truncate", "write_all"])
def test_an_undo_cut_short_is_completed_by_the_next_undo_without_force(tmp_path, monkeypatch,
                                                                       hook):
    src, dst, sd = tmp_path / "netns-hosts", tmp_path / "hosts", tmp_path / "state"
    original = b"127.0.0.1\tlocalhost\n" + random_hosts(300_000, 4)
    src.write_bytes(original)
    dst.write_bytes(b"underneath\n")
    _bind(src, dst)
    try:
        mf.apply_preview(mf.preview_block(dst, BODY, position="top"), state_dir=sd)
        applied = src.read_bytes()
        if hook == "write_all":     # die in the middle of the rewrite: half new, half old
            real = mw.write_all

            def half(fd, data):
                if len(data) == len(original) and data == original:
                    real(fd, data[: len(data) // 2])
                    raise _Crash
                real(fd, data)
            monkeypatch.setattr(mw, "write_all", half)
        else:
            monkeypatch.setattr(mw, "_before_truncate", _crash)
        with pytest.raises(_Crash):
            mf.undo_last(sd)
        monkeypatch.undo()
        torn = src.read_bytes()
        assert torn not in (original, applied)                  # really cut short
        plan = mf.plan_undo(sd)                                 # the next run
        assert plan.conflicts == []
        mf.apply_undo(plan)
        assert src.read_bytes() == original
        assert not [p for p in tmp_path.iterdir() if p.name.endswith((".inplace", ".tmp"))]
    finally:
        _umount(dst)
    tally(AREA, 1, 1, f"undo cut at {hook}")


@pytest.mark.skipif(os.geteuid() != 0 or not shutil.which("mount"), reason="needs root, mount(8)")
def test_an_apply_cut_short_is_completed_by_the_next_read(tmp_path, monkeypatch):
    src, dst, sd = tmp_path / "netns-hosts", tmp_path / "hosts", tmp_path / "state"
    src.write_bytes(b"127.0.0.1\tlocalhost\n# keep me\n")
    dst.write_bytes(b"underneath\n")
    _bind(src, dst)
    try:
        long_body = [f"203.0.113.{i}  peer{i}" for i in range(1, 30)]
        mf.apply_preview(mf.preview_block(dst, long_body, position="top"), state_dir=sd)
        short = mf.preview_block(dst, ["203.0.113.7  peer7"], position="top")
        monkeypatch.setattr(mw, "_before_truncate", _crash)
        with pytest.raises(_Crash):
            mf.apply_preview(short, state_dir=sd)
        monkeypatch.undo()
        assert src.read_bytes() != short.new                    # the tail of the old is there
        assert mw.read_bytes(dst) == short.new                  # the next read completes it
        assert src.read_bytes() == short.new
        assert mt.extract_block(src.read_text()) == ["203.0.113.7  peer7"]
    finally:
        _umount(dst)
    tally(AREA, 1, 1, "apply cut before truncate")


@pytest.mark.skipif(os.geteuid() != 0 or not shutil.which("mount"), reason="needs root, mount(8)")
def test_after_a_foreign_change_the_journal_is_dropped_and_the_file_left_alone(tmp_path,
                                                                               monkeypatch):
    src, dst = tmp_path / "netns-hosts", tmp_path / "hosts"
    src.write_bytes(random_hosts(50_000, 5))
    dst.write_bytes(b"underneath\n")
    _bind(src, dst)
    try:
        monkeypatch.setattr(mw, "_before_truncate", _crash)
        with pytest.raises(_Crash):
            mw.write_file(dst, b"short new content\n")
        monkeypatch.undo()
        src.write_bytes(b"the admin fixed it by hand\n")        # someone else, after the kill
        assert mw.read_bytes(dst) == b"the admin fixed it by hand\n"
        assert src.read_bytes() == b"the admin fixed it by hand\n"
        assert not [p for p in tmp_path.iterdir() if p.name.endswith(".inplace")]
    finally:
        _umount(dst)
    tally(AREA, 1, 1, "foreign change")


def _cut_in_place(path: Path, new: bytes, monkeypatch) -> None:
    """Leave *path* as an in-place write of *new* killed before its truncation leaves it."""
    monkeypatch.setattr(mw, "is_mount_point", lambda p: True)   # take the in-place path
    monkeypatch.setattr(mw, "_before_truncate", _crash)
    with pytest.raises(_Crash):
        mw.write_file(path, new)
    monkeypatch.undo()


@pytest.mark.skipif(os.geteuid() != 0, reason="needs root (to read as another user)")
def test_a_user_reading_roots_torn_write_is_told_so_and_changes_nothing(monkeypatch):
    """Issue 29: the user may not complete root's cut write, so reading it is refused, saying
    the file is torn and the root command that completes it (it used to answer with what the
    file would hold, while every other program read the mix)."""
    folder = Path(__import__("tempfile").mkdtemp(prefix="rosnet-h15-"))
    try:
        os.chmod(folder, 0o755)
        target = folder / "hosts"
        old, new = random_hosts(40_000, 6), b"# new\n" + random_hosts(20_000, 7)
        target.write_bytes(old)
        os.chmod(target, 0o644)
        _cut_in_place(target, new, monkeypatch)
        torn = target.read_bytes()
        assert torn not in (old, new)
        os.setegid(65534)
        os.seteuid(65534)                                       # read as the user "nobody"
        try:
            with pytest.raises(mw.TornFileError) as refused:
                mw.read_bytes(target)
        finally:
            os.seteuid(0)
            os.setegid(0)
        said = str(refused.value)
        assert f"{target} is torn" in said
        assert said.endswith(f"run: sudo rosnet-tui hosts show --file {target}")
        assert target.read_bytes() == torn                      # nobody may not write it
        assert mw.read_bytes(target) == new == target.read_bytes()   # root completes it
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    tally(AREA, 1, 1, "reader without write permission")


@pytest.mark.skipif(os.geteuid() != 0, reason="needs root (to read as another user)")
def test_a_user_reading_roots_cut_write_that_is_whole_reads_it_as_it_is(monkeypatch):
    """A cut write that left the old or the new bytes is no mix: the user reads the file as it
    is (root's next run completes it)."""
    folder = Path(__import__("tempfile").mkdtemp(prefix="rosnet-h15-"))
    try:
        os.chmod(folder, 0o755)
        target = folder / "hosts"
        old, new = b"# old\n" * 10, b"# new, longer\n" * 10
        target.write_bytes(old)
        os.chmod(target, 0o644)
        _cut_in_place(target, new, monkeypatch)                 # grew: nothing to truncate
        assert target.read_bytes() == new
        assert [p.name for p in folder.iterdir() if p.name.endswith(".inplace")]
        os.setegid(65534)
        os.seteuid(65534)
        try:
            assert mw.read_bytes(target) == new
        finally:
            os.seteuid(0)
            os.setegid(0)
        assert mw.read_bytes(target) == new
        assert not [p.name for p in folder.iterdir() if p.name.endswith(".inplace")]
    finally:
        shutil.rmtree(folder, ignore_errors=True)


@pytest.mark.skipif(os.geteuid() != 0, reason="needs root (to make another user's file)")
def test_a_journal_that_someone_else_could_have_written_is_not_trusted(tmp_path, monkeypatch):
    target = tmp_path / "hosts"
    old = random_hosts(20_000, 8)
    target.write_bytes(old)
    _cut_in_place(target, b"short\n", monkeypatch)
    torn = target.read_bytes()
    (journal,) = [p for p in tmp_path.iterdir() if p.name.endswith(".inplace")]
    os.chown(journal, 65534, 65534)                              # not root's, not ours
    assert mw.read_bytes(target) == torn
    os.chown(journal, 0, 0)
    os.chmod(journal, 0o666)                                     # anyone could have changed it
    assert mw.read_bytes(target) == torn
    os.chmod(journal, 0o600)
    assert mw.read_bytes(target) == b"short\n"
    tally(AREA, 2, 2, "untrusted journal")


# --------------------------------------------------------------------------- temp files
_TEMP_CHILD = textwrap.dedent("""
    import sys
    from pathlib import Path
    from rosnet_tui.core.files import managed_file as mf
    from rosnet_tui.core.files import managed_text as mt
    from rosnet_tui.core.files import managed_write as mw
    from rosnet_tui.core.files import undo_journal as uj
    from rosnet_tui.core.saved.settings import atomic_write_text
    target, state, status = Path(sys.argv[1]), Path(sys.argv[2]), Path(sys.argv[3])
    big = sys.argv[4]
    write_all = mw.write_all
    def marked(fd, data):
        sys.stdout.write("W\\n"); sys.stdout.flush()
        write_all(fd, data)
    mw.write_all = marked
    uj.JOURNAL_KEEP = 3
    text = Path(big).read_text()
    for i in range(100000):
        cur = target.read_text()
        body = ["# x"] if "# x" not in cur else ["# y"] * 50
        mf.apply_preview(mf.preview_block(target, body), state_dir=state)
        sys.stdout.write("W\\n"); sys.stdout.flush()
        atomic_write_text(status, text + str(i))
""")


def test_temp_files_of_killed_writers_are_removed_by_the_next_run(tmp_path):
    """Rename-path writes of a large ~/.bashrc-like file, its backups in the state dir, and a
    status file: killed at random; the next run removes every temp file that is ours."""
    home, state = tmp_path / "home", tmp_path / "state"
    home.mkdir()
    target = home / ".bashrc"
    target.write_bytes(random_hosts(1_500_000, 9))
    big = tmp_path / "big.txt"
    big.write_text("x" * 1_500_000)
    status = state / "sync" / "status.json"
    status.parent.mkdir(parents=True)
    rng = random.Random(17)
    left_over = 0
    kills = 0
    started = time.monotonic()
    while kills < 40 and time.monotonic() - started < 25:
        proc = subprocess.Popen([sys.executable, "-c", _TEMP_CHILD, str(target), str(state),
                                 str(status), str(big)], stdout=subprocess.PIPE,
                                env=dict(os.environ, PYTHONPATH=str(REPO)), cwd=REPO)
        try:
            want, seen = rng.randint(1, 8), 0
            for line in _lines(proc, time.monotonic() + 15):
                if line == "W":
                    seen += 1
                    if seen >= want:
                        break
            time.sleep(rng.uniform(0, 0.003))
        finally:
            proc.send_signal(signal.SIGKILL)
            proc.wait(timeout=10)
            proc.stdout.close()
        kills += 1
        left_over = max(left_over, len(_temps(tmp_path)))
    assert left_over >= 1, "no kill left a temp file: the test did not test anything"
    # The next run (a normal apply and a status write) removes what killed runs left.
    cur = target.read_text()
    body = ["# z"] if "# z" not in cur else ["# w"]
    mf.apply_preview(mf.preview_block(target, body), state_dir=state)
    from rosnet_tui.core.saved.settings import atomic_write_text

    atomic_write_text(status, "{}\n")
    assert _temps(tmp_path) == []
    tally(AREA, kills, kills, "temp files (rename path)")


def _temps(root: Path) -> list[str]:
    return sorted(str(p.relative_to(root)) for p in root.rglob(".*")
                  if p.is_file() and (p.name.endswith(".tmp") or ".tmp-" in p.name))


@pytest.mark.skipif(os.geteuid() != 0, reason="needs root (to act as another user)")
def test_in_a_folder_the_writer_may_not_write_the_journal_goes_to_the_state_dir(monkeypatch):
    """A user's own file in a folder only root may write: in place, journaled under the state
    dir; after a cut write the next apply through that state dir completes it first."""
    top = Path(__import__("tempfile").mkdtemp(prefix="rosnet-h15-"))
    try:
        os.chmod(top, 0o755)
        folder, sd = top / "etc", top / "state"
        folder.mkdir(mode=0o755)
        sd.mkdir(mode=0o700)
        os.chown(sd, 65534, 65534)
        target = folder / "hosts"
        original = random_hosts(30_000, 10)
        target.write_bytes(original)
        os.chown(target, 65534, 65534)
        new = b"# new first line\n" + original[:10_000]
        os.setegid(65534)
        os.seteuid(65534)
        try:
            monkeypatch.setattr(mw, "write_all", _half_then_crash(mw.write_all, new))
            with pytest.raises(_Crash):
                mw.write_file(target, new, journal_dir=sd / "inplace")
            monkeypatch.undo()
            torn = target.read_bytes()
            assert torn not in (original, new)
            assert list((sd / "inplace").iterdir())                       # its journal
            stale = mf.Preview(target, torn, torn + b"# more\n")
            with pytest.raises(mt.StalePreviewError):                    # the next run
                mf.apply_previews([stale], state_dir=sd)
            assert target.read_bytes() == new                             # completed first
            assert not list((sd / "inplace").iterdir())
            mf.apply_previews([mf.Preview(target, new, new + b"# more\n")], state_dir=sd)
            assert target.read_bytes() == new + b"# more\n"
        finally:
            os.seteuid(0)
            os.setegid(0)
    finally:
        shutil.rmtree(top, ignore_errors=True)
    tally(AREA, 1, 1, "journal in the state dir")


@pytest.mark.parametrize("place", ["in place", "rename"])
def test_an_apply_interrupted_in_a_live_process_is_rolled_back_whole(tmp_path, monkeypatch,
                                                                      place):
    """Ctrl-C (not a kill) in the middle of a write: the apply is rolled back, and the file being
    written when it came is put back too (its entry says rolled back: it must not end up new)."""
    target, sd = tmp_path / "hosts", tmp_path / "state"
    original = random_hosts(200_000, 11)
    target.write_bytes(original)
    if place == "in place":
        monkeypatch.setattr(mw, "is_mount_point", lambda p: True)
    p = mf.preview_block(target, BODY, position="top")
    real, fired = mw.write_all, []

    def interrupted(fd, chunk):
        if chunk == p.new and not fired:
            fired.append(1)
            real(fd, chunk[: len(chunk) // 2])
            raise KeyboardInterrupt
        real(fd, chunk)
    monkeypatch.setattr(mw, "write_all", interrupted)
    with pytest.raises(KeyboardInterrupt):
        mf.apply_preview(p, state_dir=sd)
    monkeypatch.setattr(mw, "write_all", real)
    assert fired
    assert mw.read_bytes(target) == original == target.read_bytes()
    assert mf.last_entry(sd) is None                              # nothing left to undo
    assert not [x for x in tmp_path.iterdir() if x.name.endswith((".inplace", ".tmp"))]
    tally(AREA, 1, 1, f"interrupted apply ({place})")


def _half_then_crash(real, data: bytes):
    def half(fd, chunk):
        if chunk == data:
            real(fd, chunk[: len(chunk) // 2])
            raise _Crash
        real(fd, chunk)
    return half


# --------------------------------------------------------------------------- what is read
def test_a_target_that_is_not_a_regular_file_is_refused_without_reading_it(tmp_path):
    """``hosts apply --file FIFO`` hung and ``--file`` on a link to /dev/zero read until memory
    ran out (siblings of the settings loader's): refused at once, exit 1, no traceback."""
    cfg = tmp_path / "config.toml"
    cfg.write_text(ROBOT_CONFIG)
    fifo, zero = tmp_path / "fifo", tmp_path / "zero"
    os.mkfifo(fifo)
    zero.symlink_to("/dev/zero")
    env = dict(os.environ, PYTHONPATH=str(REPO))
    n = 0
    for target in (fifo, zero):
        for cmd in (["hosts", "apply"], ["ros", "apply"]):
            started = time.monotonic()
            r = subprocess.run([sys.executable, "-m", "rosnet_tui", *cmd, "--config", str(cfg),
                                "--file", str(target), "--yes", "--no-checks", "--state-dir",
                                str(tmp_path / "state")], capture_output=True, text=True,
                               timeout=30, env=env, cwd=REPO, stdin=subprocess.DEVNULL)
            assert r.returncode == 1 and "not a regular file" in r.stderr, (cmd, r.stderr[-800:])
            assert "Traceback" not in r.stderr
            assert time.monotonic() - started < 15
            n += 1
    with pytest.raises(mt.ManagedFileError, match="not a regular file"):
        mw.read_bytes(fifo)
    tally(AREA, n, n, "not a regular file")
