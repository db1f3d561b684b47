"""The safe editor: our block only, every other byte kept, atomic, undoable, crash-safe."""

from __future__ import annotations

import os
import random
import select
import shutil
import signal
import stat
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rosnet_tui.core.files import managed_file as mf
from rosnet_tui.core.files import managed_text as mt
from rosnet_tui.core.files import managed_write as mw
from rosnet_tui.core.files import undo_journal as uj

REPO = Path(__file__).resolve().parent.parent
BODY_A = ["10.10.10.1\tturtlebot", "198.51.100.2\tsami"]
BODY_B = ["10.10.10.1\tturtlebot", "192.168.1.10\tsami"]


# --------------------------------------------------------------------------- generated files
_SAMPLE_LINES = [
    "", "# a comment", "\t# tab-indented comment", "127.0.0.1\tlocalhost",
    "::1     localhost ip6-localhost ip6-loopback", "fe80::1%eth0 router6",
    "ff02::2 ip6-allrouters", "192.168.0.5   nas  nas.local   # the NAS",
    "export PATH=$HOME/bin:$PATH", "  alias ll='ls -l'\t", "if [ -f x ]; then", "fi",
    "# BEGINNING of something else", "#END rosnet-tuitorial", "   ", "\t\t",
]
_line_text = st.text(st.characters(blacklist_characters="\n", blacklist_categories=("Cs",)),
                     max_size=40).filter(lambda s: not mt._MARKER_RE.match(s))
_line = st.one_of(st.sampled_from(_SAMPLE_LINES), _line_text)


@st.composite
def generated_files(draw) -> bytes:
    """A text file: mixed LF/CRLF endings, maybe no final newline, maybe a block already,
    maybe a few bytes that are not UTF-8."""
    lines = draw(st.lists(_line, max_size=15))
    crlf = draw(st.sampled_from(["never", "always", "mixed"]))
    out = []
    for line in lines:
        nl = {"never": "\n", "always": "\r\n"}.get(crlf) or draw(st.sampled_from(["\n", "\r\n"]))
        out.append(line + nl)
    if draw(st.booleans()) and lines:
        pos = draw(st.integers(0, len(out)))
        old_body = draw(st.lists(st.sampled_from(["1.2.3.4 old", "# old note"]), max_size=3))
        nl = "\r\n" if crlf == "always" else "\n"
        out[pos:pos] = [x + nl for x in (mt.BEGIN_MARKER, *old_body, mt.END_MARKER)]
    text = "".join(out)
    if text and draw(st.booleans()):
        text = text.rstrip("\n").rstrip("\r") if not text.endswith(mt.END_MARKER + "\n") else text
    data = mt.encode(text)
    if draw(st.booleans()):
        data += (b"" if not data or data.endswith(b"\n") else b"\n") + draw(st.sampled_from([b"\xff\xfe bad utf-8\n", b"caf\xe9\n", b"\x00nul\n"]))
    return data


def outside_block(data: bytes, raw: bool = False) -> list[str]:
    """Lines outside our block (terminators dropped unless *raw*)."""
    lines = mt.split_lines(mt.decode(data))
    span = mt.find_block(lines)
    return [x if raw else mt.line_content(x) for i, x in enumerate(lines)
            if not (span and span[0] <= i <= span[1])]


PROP = settings(max_examples=60, deadline=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture,
                                       HealthCheck.too_slow])


# --------------------------------------------------------------------------- compose
def test_new_block_at_end_and_top():
    assert mt.compose_block("a\nb\n", ["x"]) == f"a\nb\n{mt.BEGIN_MARKER}\nx\n{mt.END_MARKER}\n"
    assert mt.compose_block("a\n", ["x"], position="top") == \
        f"{mt.BEGIN_MARKER}\nx\n{mt.END_MARKER}\na\n"
    assert mt.compose_block(None, []) == f"{mt.BEGIN_MARKER}\n{mt.END_MARKER}\n"


def test_missing_final_newline_gets_one_before_the_block_and_nothing_else_changes():
    out = mt.compose_block("a\r\nlast", ["x"])
    assert out == f"a\r\nlast\r\n{mt.BEGIN_MARKER}\r\nx\r\n{mt.END_MARKER}\r\n"


def test_existing_block_is_replaced_where_it_stands_in_its_own_line_endings():
    text = f"a\n{mt.BEGIN_MARKER}\r\nold\r\n{mt.END_MARKER}\r\nb\tc\n# z"
    out = mt.compose_block(text, ["new"])
    assert out == f"a\n{mt.BEGIN_MARKER}\r\nnew\r\n{mt.END_MARKER}\r\nb\tc\n# z"


def test_block_at_end_of_file_without_final_newline_stays_so():
    text = f"a\n{mt.BEGIN_MARKER}\nold\n{mt.END_MARKER}"
    assert mt.compose_block(text, ["n"]) == f"a\n{mt.BEGIN_MARKER}\nn\n{mt.END_MARKER}"


B, E = mt.BEGIN_MARKER, mt.END_MARKER


@pytest.mark.parametrize(("text", "why"), [
    (f"a\n{B}\nx\n", "block that starts at line 2 has no '# END rosnet-tui' line"),
    (f"a\n{E}\n", "line 2 ends a rosnet-tui block that never began"),
    (f"{B}\n{E}\n{B}\n{E}\n", "line 3 starts a second rosnet-tui block .the first starts at "
                              "line 1."),                                     # two blocks
    (f"{B}\nx\n{B}\ny\n{E}\n", "line 3 starts a second rosnet-tui block"),  # half-deleted
    (f"{B}\n{E}\nx\n{E}\n", "line 4 ends the rosnet-tui block a second time"),
])
def test_damaged_block_is_refused_and_the_file_is_left_alone(tmp_path, text, why):
    f = tmp_path / "hosts"
    f.write_text(text)
    with pytest.raises(mt.DamagedBlockError, match=why) as e:
        mf.preview_block(f, ["x"])
    assert "by hand" in str(e.value)
    assert f.read_text() == text
    with pytest.raises(mt.DamagedBlockError, match=why):
        mt.extract_block(text)


def test_a_line_inside_our_block_is_not_replaced_as_a_line_outside_it():
    text = f"a\n{B}\nx\n{E}\nb\n"
    for i in (1, 2, 3):                       # BEGIN, a body line, END
        with pytest.raises(ValueError, match=f"line index {i} is not a line outside"):
            mt.compose_block(text, ["y"], replace_lines={i: "# z"})
    for i in (-1, 5):
        with pytest.raises(ValueError, match="not a line outside"):
            mt.compose_block(text, ["y"], replace_lines={i: "# z"})
    assert mt.compose_block(text, ["y"], replace_lines={0: "# a", 4: "# b"}) == \
        f"# a\n{B}\ny\n{E}\n# b\n"
    with pytest.raises(ValueError, match="newline"):
        mt.compose_block(text, ["y"], replace_lines={0: "a\rb"})


def test_block_lines_cannot_smuggle_newlines_or_markers():
    with pytest.raises(ValueError):
        mt.compose_block("", ["a\nb"])
    with pytest.raises(ValueError):
        mt.compose_block("", [mt.END_MARKER])


def test_diff_shows_changes_and_no_newline_marker(tmp_path):
    f = tmp_path / "h"
    f.write_bytes(b"a\nb")
    p = mf.preview_block(f, ["x"])
    d = p.diff()
    assert f"+{mt.BEGIN_MARKER}" in d and "\\ No newline at end of file" in d
    assert p.digest == mt.file_digest(b"a\nb") and p.changed


# --------------------------------------------------------------------------- properties
@PROP
@given(data=generated_files(), top=st.booleans())
def test_apply_then_undo_restores_byte_for_byte(data, top):
    with tempfile.TemporaryDirectory() as d:
        f, sd = Path(d) / "file", Path(d) / "state"
        f.write_bytes(data)
        p = mf.preview_block(f, BODY_A, position="top" if top else "end")
        mf.apply_preview(p, state_dir=sd)
        assert f.read_bytes() == p.new
        if p.changed:
            mf.undo_last(sd)
        assert f.read_bytes() == data
        with pytest.raises(mt.NothingToUndoError):
            mf.undo_last(sd)


@PROP
@given(data=generated_files(), top=st.booleans())
def test_apply_twice_is_apply_once_and_outside_lines_never_change(data, top):
    with tempfile.TemporaryDirectory() as d:
        f, sd = Path(d) / "file", Path(d) / "state"
        f.write_bytes(data)
        pos = "top" if top else "end"
        mf.apply_preview(mf.preview_block(f, BODY_A, position=pos), state_dir=sd)
        once = f.read_bytes()
        second = mf.preview_block(f, BODY_A, position=pos)
        assert not second.changed
        assert mf.apply_preview(second, state_dir=sd).changed is False
        assert f.read_bytes() == once
        assert outside_block(once) == outside_block(data)
        assert mt.extract_block(mt.decode(once)) == BODY_A
        # byte for byte (terminators too: CRLF, tabs, IPv6 lines, odd bytes), except that a
        # last line without a newline gains one when the block is appended after it
        before, after = outside_block(data, raw=True), outside_block(once, raw=True)
        if before and not before[-1].endswith("\n") and after[-1] != before[-1]:
            assert after[-1] == before[-1] + mt.detect_newline(mt.decode(data))
            before, after = before[:-1], after[:-1]
        assert after == before
        # switching the body changes only the block
        mf.apply_preview(mf.preview_block(f, BODY_B, position=pos), state_dir=sd)
        assert outside_block(f.read_bytes()) == outside_block(data)


# --------------------------------------------------------------------------- apply / undo
def test_stale_preview_is_refused_and_nothing_is_written(tmp_path):
    f, sd = tmp_path / "hosts", tmp_path / "state"
    f.write_text("127.0.0.1 localhost\n")
    p = mf.preview_block(f, BODY_A)
    f.write_text("127.0.0.1 localhost\n10.0.0.9 edited-meanwhile\n")
    with pytest.raises(mt.StalePreviewError, match="changed since the preview"):
        mf.apply_preview(p, state_dir=sd)
    assert f.read_text() == "127.0.0.1 localhost\n10.0.0.9 edited-meanwhile\n"
    assert uj.journal_entries(sd) == []


def test_mode_owner_and_xattrs_are_kept(tmp_path):
    f, sd = tmp_path / "hosts", tmp_path / "state"
    f.write_text("x\n")
    os.chmod(f, 0o640)
    if os.geteuid() == 0:
        os.chown(f, 1234, 5678)
    try:
        os.setxattr(f, "user.rosnet_test", b"label")
        has_xattr = True
    except OSError:
        has_xattr = False
    before = os.stat(f)
    r = mf.apply_preview(mf.preview_block(f, BODY_A), state_dir=sd)
    after = os.stat(f)
    assert r.changed and not r.in_place
    assert after.st_ino != before.st_ino  # really renamed, not rewritten
    assert stat.S_IMODE(after.st_mode) == 0o640
    assert (after.st_uid, after.st_gid) == (before.st_uid, before.st_gid)
    if has_xattr:
        assert os.getxattr(f, "user.rosnet_test") == b"label"
    mf.undo_last(sd)
    assert stat.S_IMODE(os.stat(f).st_mode) == 0o640 and f.read_text() == "x\n"


def test_symlinked_dotfile_stays_a_link(tmp_path):
    target = tmp_path / "dotfiles" / "bashrc"
    target.parent.mkdir()
    target.write_text("alias x=y\n")
    link = tmp_path / ".bashrc"
    link.symlink_to(target)
    mf.apply_preview(mf.preview_block(link, ["export A=1"]), state_dir=tmp_path / "s")
    assert link.is_symlink() and "export A=1" in target.read_text()
    mf.undo_last(tmp_path / "s")
    assert link.is_symlink() and target.read_text() == "alias x=y\n"


def test_created_file_is_removed_by_undo(tmp_path):
    f, sd = tmp_path / "new" / "bashrc", tmp_path / "state"
    p = mf.preview_block(f, ["export A=1"], new_mode=0o644)
    assert p.old is None and p.digest == mt.ABSENT
    r = mf.apply_preview(p, state_dir=sd)
    assert r.backups == [] and stat.S_IMODE(os.stat(f).st_mode) == 0o644
    mf.undo_last(sd)
    assert not f.exists()


def test_undo_goes_back_one_apply_per_call(tmp_path):
    f, sd = tmp_path / "hosts", tmp_path / "state"
    f.write_bytes(b"orig\r\n")
    mf.apply_preview(mf.preview_block(f, BODY_A), state_dir=sd)
    a = f.read_bytes()
    mf.apply_preview(mf.preview_block(f, BODY_B), state_dir=sd)
    plan = mf.plan_undo(sd)
    assert plan.previews[0].new == a and "-192.168.1.10" in plan.diff()
    mf.apply_undo(plan)
    assert f.read_bytes() == a
    mf.undo_last(sd)
    assert f.read_bytes() == b"orig\r\n"
    with pytest.raises(mt.NothingToUndoError, match="nothing to undo"):
        mf.plan_undo(sd)


def test_undo_refuses_to_lose_a_later_edit_unless_forced(tmp_path):
    f, sd = tmp_path / "hosts", tmp_path / "state"
    f.write_text("orig\n")
    mf.apply_preview(mf.preview_block(f, BODY_A), state_dir=sd)
    f.write_text(f.read_text() + "edited later\n")
    plan = mf.plan_undo(sd)
    assert plan.conflicts == [str(f)]
    with pytest.raises(mt.UndoConflictError, match="someone else"):
        mf.apply_undo(plan)
    assert "edited later" in f.read_text()
    mf.apply_undo(mf.plan_undo(sd), force=True)
    assert f.read_text() == "orig\n"


def test_undo_preview_goes_stale_too(tmp_path):
    f, sd = tmp_path / "hosts", tmp_path / "state"
    f.write_text("orig\n")
    mf.apply_preview(mf.preview_block(f, BODY_A), state_dir=sd)
    plan = mf.plan_undo(sd)
    f.write_text("someone\n")
    with pytest.raises(mt.ManagedFileError):
        mf.apply_undo(plan, force=True)
    with pytest.raises(mt.StalePreviewError):
        mf.plan_undo(sd, entry_id="999999")


def test_backups_are_timestamped_in_the_journal(tmp_path):
    f, sd = tmp_path / "hosts", tmp_path / "state"
    f.write_text("orig\n")
    r = mf.apply_preview(mf.preview_block(f, BODY_A, label="hosts: remote"), state_dir=sd)
    (entry,) = uj.journal_entries(sd)
    assert entry.id == r.entry_id and entry.label == "hosts: remote"
    assert entry.created.endswith("Z") and entry.files[0].before == mt.file_digest(b"orig\n")
    assert r.backups[0].read_bytes() == b"orig\n"
    assert stat.S_IMODE(os.stat(r.backups[0]).st_mode) == 0o600


def test_temp_files_of_dead_writers_are_swept(tmp_path):
    f = tmp_path / "hosts"
    f.write_text("x\n")
    dead = subprocess.Popen(["true"])
    dead.wait()
    stale = tmp_path / f".hosts.rosnet-tui.{dead.pid}.abcd1234.tmp"
    stale.write_text("half")
    mine = tmp_path / f".hosts.rosnet-tui.{os.getpid()}.abcd1234.tmp"
    mine.write_text("in use")
    mw.write_file(f, b"y\n")
    assert not stale.exists() and mine.exists()


# --------------------------------------------------------------------------- crash safety
_CHILD = textwrap.dedent("""
    import random, sys, time
    from pathlib import Path
    from rosnet_tui.core.files import managed_file as mf
    from rosnet_tui.core.files import managed_text as mt
    from rosnet_tui.core.files import undo_journal as uj
    from rosnet_tui.core.files import managed_write as mw
    path, state, mode = Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3]
    a, b = Path(sys.argv[4]).read_bytes(), Path(sys.argv[5]).read_bytes()
    def hook():
        sys.stdout.write("T\\n"); sys.stdout.flush()
        time.sleep(random.uniform(0, 0.003))
    mw._before_rename = hook
    sys.stdout.write("R\\n"); sys.stdout.flush()
    for _ in range(10000):
        cur = path.read_bytes()
        if mode == "raw":
            mw.write_file(path, b if cur == a else a)
        else:
            body = ["x 1"] if b"x 1" not in cur else ["y 2"] * 300
            mf.apply_preview(mf.preview_block(path, body), state_dir=state)
""")


def _read_marks(proc: subprocess.Popen, want: int, deadline: float) -> bool:
    seen = 0
    fd = proc.stdout.fileno()
    buf = b""
    while time.monotonic() < deadline:
        r, _, _ = select.select([fd], [], [], max(0.0, deadline - time.monotonic()))
        if not r:
            break
        chunk = os.read(fd, 4096)
        if not chunk:
            return False
        buf += chunk
        seen = buf.count(b"T\n")
        if b"R\n" in buf and seen >= want:
            return True
    return False


def test_killing_the_writer_never_leaves_a_truncated_or_missing_file(tmp_path):
    """SIGKILL a real writer process at random moments (mostly between temp and rename)."""
    a = b"".join(b"127.0.0.%d\thost-%d\r\n" % (i % 250, i) for i in range(400))
    b = b"# a different, shorter version\n10.0.0.1 b"
    fa, fb = tmp_path / "a", tmp_path / "b"
    fa.write_bytes(a)
    fb.write_bytes(b)
    target, state = tmp_path / "hosts", tmp_path / "state"
    target.write_bytes(a)
    env = dict(os.environ, PYTHONPATH=str(REPO))
    rng = random.Random(1234)
    started = time.monotonic()
    for i in range(50):
        mode = "raw" if i % 2 == 0 else "apply"
        ok_contents = {a, b} if mode == "raw" else None
        before = target.read_bytes()
        proc = subprocess.Popen([sys.executable, "-c", _CHILD, str(target), str(state), mode,
                                 str(fa), str(fb)], stdout=subprocess.PIPE, env=env, cwd=REPO)
        try:
            if rng.random() < 0.8:
                _read_marks(proc, rng.randint(1, 4), time.monotonic() + 5)
                time.sleep(rng.uniform(0, 0.003))
            else:
                _read_marks(proc, 0, time.monotonic() + 5)
                time.sleep(rng.uniform(0, 0.05))
        finally:
            proc.send_signal(signal.SIGKILL)
            proc.wait(timeout=5)
            proc.stdout.close()
        now = target.read_bytes()  # exists: a missing file raises here
        if ok_contents is not None:
            assert now in ok_contents, f"iteration {i}: a torn file ({len(now)} bytes)"
        else:
            text = mt.decode(now)
            assert now == before or mt.extract_block(text) in (["x 1"], ["y 2"] * 300), i
            target.write_bytes(a)  # next raw round starts from a known content
    assert time.monotonic() - started < 20
    mw.write_file(target, a)  # the next writer sweeps the dead writers' temp files
    leftovers = [p.name for p in tmp_path.iterdir() if p.name.startswith(".hosts.rosnet-tui")]
    assert leftovers == []


# --------------------------------------------------------------------------- bind mounts
def _bind_mount(src: Path, dst: Path) -> None:
    r = subprocess.run(["mount", "--bind", str(src), str(dst)], capture_output=True, text=True,
                       timeout=10)
    if r.returncode != 0:
        pytest.skip(f"cannot bind-mount here: {r.stderr.strip()}")


@pytest.mark.skipif(os.geteuid() != 0 or not shutil.which("mount"),
                    reason="bind mounts need root and mount(8)")
def test_bind_mounted_file_is_rewritten_in_place_with_a_backup(tmp_path):
    src, dst, sd = tmp_path / "netns-hosts", tmp_path / "hosts", tmp_path / "state"
    src.write_bytes(b"127.0.0.1\tlocalhost\r\n::1 ip6-localhost")
    dst.write_bytes(b"the file underneath\n")
    _bind_mount(src, dst)
    try:
        assert mw.is_mount_point(dst)
        p = mf.preview_block(dst, BODY_A, position="top")
        r = mf.apply_preview(p, state_dir=sd)
        assert r.changed and r.in_place
        assert dst.read_bytes() == p.new == src.read_bytes()  # written through the mount
        assert r.backups[0].read_bytes() == b"127.0.0.1\tlocalhost\r\n::1 ip6-localhost"
        mf.undo_last(sd)
        assert src.read_bytes() == b"127.0.0.1\tlocalhost\r\n::1 ip6-localhost"
    finally:
        subprocess.run(["umount", str(dst)], timeout=10, check=False)
    assert dst.read_bytes() == b"the file underneath\n"


@pytest.mark.skipif(os.geteuid() != 0 or not shutil.which("mount"),
                    reason="bind mounts need root and mount(8)")
def test_rename_over_a_mount_point_falls_back_even_when_not_detected(tmp_path, monkeypatch):
    src, dst, sd = tmp_path / "src", tmp_path / "dst", tmp_path / "state"
    src.write_text("a\n")
    dst.write_text("b\n")
    _bind_mount(src, dst)
    try:
        monkeypatch.setattr(mw, "is_mount_point", lambda p: False)  # detection missed it
        r = mf.apply_preview(mf.preview_block(dst, ["x"]), state_dir=sd)  # rename: EBUSY
        assert r.in_place and mt.extract_block(src.read_text()) == ["x"]
    finally:
        subprocess.run(["umount", str(dst)], timeout=10, check=False)


def test_the_journal_keeps_only_the_most_recent_applies(tmp_path, monkeypatch):
    monkeypatch.setattr(uj, "JOURNAL_KEEP", 3)
    f, sd = tmp_path / "hosts", tmp_path / "state"
    f.write_text("orig\n")
    for i in range(5):
        mf.apply_preview(mf.preview_block(f, [f"# {i}"]), state_dir=sd)
    assert [e.id for e in uj.journal_entries(sd)] == ["000003", "000004", "000005"]
    assert sorted(p.name for p in (sd / "backups").iterdir()) == ["000003", "000004", "000005"]


class _Crash(BaseException):
    """Stands for the process dying at that instant (nothing after it runs)."""


@pytest.mark.skipif(os.geteuid() != 0 or not shutil.which("mount"),
                    reason="bind mounts need root and mount(8)")
def test_a_crash_inside_an_in_place_shrink_is_completed_by_the_next_read(tmp_path, monkeypatch):
    """In place (a bind-mounted /etc/hosts) the write and the truncation are two steps: dying
    between them leaves a tail of old bytes, and the journal beside the file; the next read
    completes the write (issue 15: padding with blank lines was not enough)."""
    src, dst, sd = tmp_path / "netns-hosts", tmp_path / "hosts", tmp_path / "state"
    src.write_bytes(b"127.0.0.1\tlocalhost\n# keep me\n")
    dst.write_bytes(b"underneath\n")
    _bind_mount(src, dst)
    try:
        long_body = [f"203.0.113.{i}  peer{i}" for i in range(1, 30)]
        mf.apply_preview(mf.preview_block(dst, long_body, position="top"), state_dir=sd)
        short = mf.preview_block(dst, ["203.0.113.7  peer7"], position="top")

        def crash() -> None:
            raise _Crash

        monkeypatch.setattr(mw, "_before_truncate", crash)
        with pytest.raises(_Crash):
            mf.apply_preview(short, state_dir=sd)
        monkeypatch.setattr(mw, "_before_truncate", None)
        left = src.read_bytes()
        assert left.startswith(short.new) and left != short.new
        assert [p.name for p in tmp_path.iterdir() if p.name.endswith(".inplace")]
        left = mw.read_bytes(dst)
        assert left == short.new == src.read_bytes()
        assert mt.extract_block(left.decode()) == ["203.0.113.7  peer7"]
        assert b"# keep me" in left and b"peer29" not in left
        assert not [p.name for p in tmp_path.iterdir() if p.name.endswith(".inplace")]
    finally:
        subprocess.run(["umount", str(dst)], timeout=10, check=False)


def test_the_dominant_line_ending_needs_half_the_lines_or_more():
    assert mt.detect_newline("a\r\nb\n") == "\r\n"          # half
    assert mt.detect_newline("a\r\nb\nc\n") == "\n"         # a third
    assert mt.detect_newline("abc") == "\n" and mt.detect_newline("") == "\n"
    assert mt.detect_newline(None) == "\n"


def test_a_block_keeps_its_begin_lines_ending_whatever_the_rest_of_the_file_uses():
    text = f"a\nb\nc\n{B}\r\nold\n{E}\n"
    assert mt.compose_block(text, ["new"]) == f"a\nb\nc\n{B}\r\nnew\r\n{E}\r\n"


def test_bad_block_lines_and_positions_are_refused_in_words():
    with pytest.raises(ValueError, match=r"may not hold a newline or a marker: 'a\\rb'"):
        mt.compose_block("", ["a\rb"])
    with pytest.raises(ValueError, match="position must be 'top' or 'end', not 'middle'"):
        mt.compose_block("x\n", ["y"], position="middle")
