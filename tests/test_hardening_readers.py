"""Issue 21, hardening leftovers: every read of a file rosnet-tui writes completes an in-place
write that a SIGKILL cut short, whichever command wrote it.

Reproduced: a real ``rosnet-tui undo`` killed while it rewrote a bind-mounted ``/etc/hosts`` in
place left the file torn (the restored bytes, then the tail of the applied ones). ``check``
(linux.hosts) read the torn file as it was; where ``/etc`` may not be written (a container with a
read-only root) the journal lives in the state dir, and ``hosts show`` and ``hosts apply`` did not
look there either. Now every reader goes through ``managed_write.read_bytes``, which looks beside
the file, in the state dir it is given and in the default one, and completes the write first.

The kill test runs every command in one private mount namespace (a holder process made by
``unshare -m``, entered with ``nsenter``): ``/etc`` there is either read-only (the journal goes to
the state dir) or an overlay whose writes land in the test's folder (the journal goes beside
``/etc/hosts``), and ``/etc/hosts`` is a bind mount of a test file. Nothing leaks into the
machine's mounts or its ``/etc``.
"""

from __future__ import annotations

import asyncio
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from rosnet_tui.core.checks.linux import check_hosts
from rosnet_tui.core.checks.runner import RunOptions, make_context
from rosnet_tui.core.config.paths import Paths
from rosnet_tui.core.files import managed_write as mw
from rosnet_tui.core.files.cut_writes import INPLACE_DIR
from rosnet_tui.core.saved.settings import load_settings
from tests.builders import ROBOT_CONFIG, random_hosts
from tests.hardening_tally import tally

REPO = Path(__file__).resolve().parents[1]
AREA = "readers after SIGKILL"
NS_TOOLS = pytest.mark.skipif(
    os.geteuid() != 0 or not all(shutil.which(t) for t in ("unshare", "nsenter", "mount")),
    reason="needs root (bind mounts in a private mount namespace), unshare(1), nsenter(1) and "
           "mount(8)")


class Container:
    """A private mount namespace where /etc/hosts is a bind mount of ``src`` and /etc is either
    read-only (``etc="ro"``) or an overlay writing into the test's folder (``etc="overlay"``)."""

    def __init__(self, tmp: Path, etc: str, original: bytes) -> None:
        self.tmp, self.etc = tmp, etc
        self.src, self.cfg, self.xdg = tmp / "netns-hosts", tmp / "settings.toml", tmp / "xdg"
        self.src.write_bytes(original)
        self.cfg.write_text(ROBOT_CONFIG)
        if etc == "ro":
            prep = "mount --bind /etc /etc && mount -o remount,bind,ro /etc"
            self.journal_dir = self.xdg / "rosnet-tui" / INPLACE_DIR
        else:
            (tmp / "up").mkdir()
            (tmp / "work").mkdir()
            prep = (f"mount -t overlay overlay -o lowerdir=/etc,upperdir={tmp / 'up'},"
                    f"workdir={tmp / 'work'} /etc")
            self.journal_dir = tmp / "up"
        script = f"{prep} && mount --bind {self.src} /etc/hosts && echo ready && exec sleep 600"
        self.holder = subprocess.Popen(["unshare", "-m", "--propagation", "private", "sh", "-c",
                                        script], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        line = self.holder.stdout.readline()
        if line.strip() != b"ready":
            self.close()
            pytest.skip(f"cannot build the mount namespace here: "
                        f"{self.holder.stderr.read().decode(errors='replace').strip()}")

    def argv(self, *args: str) -> list[str]:
        return ["nsenter", "-t", str(self.holder.pid), "-m", "--", sys.executable, "-m",
                "rosnet_tui", *args]

    @property
    def env(self) -> dict[str, str]:
        return dict(os.environ, PYTHONPATH=str(REPO), XDG_STATE_HOME=str(self.xdg))

    def run(self, *args: str) -> subprocess.CompletedProcess:
        return subprocess.run(self.argv(*args), capture_output=True, text=True, env=self.env,
                              timeout=60)

    def spawn(self, *args: str, pause: bool = False) -> subprocess.Popen:
        """``rosnet-tui ARGS`` in the background; with *pause*, a writer waits a second at its
        crash point between the rewrite and the truncation (a kill there leaves the file torn:
        the rewrite alone is too short to hit by watching the file)."""
        argv = self.argv(*args)
        if pause:
            at = argv.index(sys.executable) + 1            # "-m rosnet_tui" becomes "-c ..."
            argv[at:at + 2] = ["-c", _PAUSED]
        return subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                env=self.env)

    def journals(self) -> list[Path]:
        try:
            return [p for p in self.journal_dir.iterdir() if p.name.endswith(".inplace")]
        except FileNotFoundError:
            return []

    def close(self) -> None:
        if self.holder.poll() is None:
            self.holder.send_signal(signal.SIGKILL)   # the namespace, and its mounts, go with it
        self.holder.wait(timeout=10)
        self.holder.stdout.close()
        self.holder.stderr.close()


_PAUSED = ("import sys, time\nfrom rosnet_tui.core.files import managed_write as mw\n"
           "mw._before_truncate = lambda: time.sleep(1.0)\n"
           "from rosnet_tui.cli import main\nsys.exit(main(sys.argv[1:]))\n")


def show(box: Container) -> str:
    r = box.run("hosts", "show", "--config", str(box.cfg))
    assert r.returncode == 0, r.stderr
    return r.stdout


def check_linux_hosts(box: Container) -> tuple:
    r = box.run("check", "--step", "linux", "--json", "--timeout", "0.5", "--no-upnp", "-q",
                "--config", str(box.cfg))
    assert r.returncode in (0, 1), r.stderr
    (c,) = [c for c in json.loads(r.stdout)["checks"] if c["id"] == "linux.hosts"]
    return c["status"], c["summary"], tuple(c["evidence"]), json.dumps(c["data"], sort_keys=True)


def _kill_undo(box: Container, rng: random.Random, head_b: bytes) -> str:
    """Start a real ``rosnet-tui undo`` and SIGKILL it at a random moment: at a random time, a
    random time after its journal appears, or once the rewrite of the file began (it pauses
    before the truncation then)."""
    how = rng.choice(["time", "journal", "rewrite", "rewrite"])
    proc = box.spawn("undo", "--yes", "--no-checks", "--state-dir", str(box.xdg / "rosnet-tui"),
                     pause=how == "rewrite")
    try:
        deadline = time.monotonic() + 20
        if how == "time":
            time.sleep(rng.uniform(0.0, 0.8))
        else:
            fd = os.open(box.src, os.O_RDONLY)
            try:
                while time.monotonic() < deadline and proc.poll() is None:
                    if how == "journal" and box.journals():
                        time.sleep(rng.uniform(0.0, 0.03))
                        break
                    if how == "rewrite" and os.pread(fd, len(head_b), 0) != head_b:
                        time.sleep(rng.choice([0.0, rng.uniform(0.0, 0.002)]))
                        break
                    time.sleep(0.0002)
            finally:
                os.close(fd)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
    return how


def run_kills(tmp_path: Path, etc: str, kills: int, seed: int) -> dict:
    rng = random.Random(seed)
    a = b"127.0.0.1\tlocalhost\n" + random_hosts(1_500_000, seed)
    box = Container(tmp_path, etc, a)
    stats = {"kills": 0, "torn": 0, "old": 0, "new": 0, "torn_before_show": 0,
             "torn_before_check": 0, "torn_before_apply": 0, "completed": 0}
    try:
        want = {"A": (show(box), check_linux_hosts(box))}
        r = box.run("hosts", "apply", "--yes", "--no-checks", "--config", str(box.cfg))
        assert r.returncode == 0, r.stderr
        b = box.src.read_bytes()
        assert b != a and b.endswith(a) and "in place" in r.stdout
        want["B"] = (show(box), check_linux_hosts(box))
        assert want["A"][0] != want["B"][0] and want["A"][1] != want["B"][1]
        started = time.monotonic()
        while stats["kills"] < kills:                 # a count, not a time: load-proof
            if box.src.read_bytes() == a:       # put the applied set back, to undo again
                r = box.run("hosts", "apply", "--yes", "--no-checks", "--config", str(box.cfg))
                assert r.returncode == 0, r.stderr
            assert box.src.read_bytes() == b
            how = _kill_undo(box, rng, b[:64])
            stats["kills"] += 1
            now = box.src.read_bytes()
            state = "A" if now == a else "B" if now == b else "torn"
            stats[{"A": "new", "B": "old", "torn": "torn"}[state]] += 1
            reader = ("show", "check", "apply")[stats["kills"] % 3]
            if state == "torn":
                assert box.journals(), "a torn file without a journal to complete it"
                stats[f"torn_before_{reader}"] += 1
            if reader == "apply":
                r = box.run("hosts", "apply", "--yes", "--no-checks", "--config", str(box.cfg))
                # It previewed the completed file: no "changed since the preview" refusal.
                assert r.returncode == 0, f"kill {stats['kills']} ({how}): {r.stderr}"
                assert box.src.read_bytes() == b
            else:
                got = show(box) if reader == "show" else check_linux_hosts(box)
            after = box.src.read_bytes()
            final = "A" if after == a else "B" if after == b else "torn"
            # The reader completed the write (or found nothing to complete) and saw the result.
            assert final != "torn", (f"kill {stats['kills']} ({how}): the next {reader} left "
                                     f"the file torn ({state} before it)")
            if reader != "apply":
                assert got == want[final][0 if reader == "show" else 1], \
                    f"kill {stats['kills']} ({how}): the {reader} output is not the {final} file's"
            if state == "torn":
                stats["completed"] += 1
                assert not box.journals()
        stats["seconds"] = round(time.monotonic() - started, 1)
    finally:
        box.close()
    return stats


@NS_TOOLS
@pytest.mark.parametrize("etc", ["ro", "overlay"])
def test_a_killed_undo_is_completed_by_the_next_hosts_show_and_check(tmp_path, etc):
    """A real ``rosnet-tui undo`` of a 1.5 MB bind-mounted /etc/hosts, SIGKILLed at random
    moments; after each kill the next ``hosts show``, ``check`` or ``hosts apply`` (in turn)
    finds the old or the new file, never a mix, and leaves it whole. ``ro``: /etc read-only (a container's read-only
    root), the journal in the state dir; ``overlay``: the journal beside /etc/hosts."""
    stats = run_kills(tmp_path, etc, kills=12, seed=21 if etc == "ro" else 22)
    print(etc, stats)
    assert stats["kills"] == 12, stats
    assert stats["torn"] >= 1, f"no kill landed inside the rewrite: {stats}"
    assert stats["completed"] == stats["torn"], stats
    tally(AREA, stats["kills"], stats["kills"], f"undo killed, /etc {etc}")


# --------------------------------------------------------------------------- in process
class _Crash(BaseException):
    """Stands for the process dying at that instant."""


def _crash() -> None:
    raise _Crash


def _cut(target: Path, new: bytes, monkeypatch, journal_dir: Path | None = None) -> bytes:
    """Rewrite *target* in place with *new*, dying before the truncation: the torn bytes."""
    monkeypatch.setattr(mw, "is_mount_point", lambda p: True)
    monkeypatch.setattr(mw, "_before_truncate", _crash)
    with pytest.raises(_Crash):
        mw.write_file(target, new, journal_dir=journal_dir)
    monkeypatch.setattr(mw, "_before_truncate", None)
    return target.read_bytes()


def _unwritable_folder(tmp_path: Path, monkeypatch) -> Path:
    """A folder the writer may not write (os.access says no): its journal goes elsewhere."""
    folder = tmp_path / "etc"
    folder.mkdir()
    real_access = os.access
    monkeypatch.setattr(mw.os, "access", lambda p, m, **kw: False if Path(p) == folder
                        else real_access(p, m, **kw))
    return folder


def _cut_journaled_in(sd: Path, tmp_path: Path, monkeypatch) -> tuple[Path, bytes, Path]:
    """A hosts file in an unwritable folder whose rewrite was cut, journaled in state dir *sd*
    (not the default one): (the file, the bytes it should end with, a settings file)."""
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "elsewhere"))
    target = _unwritable_folder(tmp_path, monkeypatch) / "hosts"
    old = b"127.0.0.1\tlocalhost\n" + b"10.9.9.9\tother\n" * 300
    target.write_bytes(old)
    new = b"127.0.0.1\tlocalhost\n# new\n"
    assert _cut(target, new, monkeypatch, journal_dir=sd / INPLACE_DIR) not in (old, new)
    cfg = tmp_path / "settings.toml"
    cfg.write_text(ROBOT_CONFIG)
    return target, new, cfg


def test_linux_hosts_completes_a_cut_write_beside_the_file(tmp_path, monkeypatch):
    target = tmp_path / "hosts"
    old = b"127.0.0.1\tlocalhost\n" + b"10.1.2.3\tturtlebot\n" * 50
    target.write_bytes(old)
    new = b"127.0.0.1\tlocalhost\n10.10.10.1\tturtlebot\n198.51.100.2\tsami\n"
    torn = _cut(target, new, monkeypatch)
    assert torn not in (old, new)
    cfg = tmp_path / "settings.toml"
    cfg.write_text(ROBOT_CONFIG)
    paths = Paths(hosts_path=target, state_dir=tmp_path / "sd")
    ctx = make_context(load_settings(cfg), RunOptions(paths=paths, upnp=False))
    out = asyncio.run(check_hosts(ctx))
    assert out.status.value == "pass", out.summary
    assert target.read_bytes() == new
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".inplace")]


def test_a_journal_in_the_default_state_dir_is_found_by_a_reader_not_told_it(tmp_path,
                                                                            monkeypatch):
    """The writer journaled in the state dir (the file's folder may not be written); a reader
    given no state dir (``hosts show``, ``check``) looks in the default one."""
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "xdg"))
    jdir = tmp_path / "xdg" / "rosnet-tui" / INPLACE_DIR
    target = _unwritable_folder(tmp_path, monkeypatch) / "hosts"
    old = b"# old\n" * 400
    target.write_bytes(old)
    torn = _cut(target, b"# new\n", monkeypatch, journal_dir=jdir)
    assert torn not in (old, b"# new\n") and list(jdir.iterdir())
    assert mw.read_text(target) == "# new\n"
    assert target.read_bytes() == b"# new\n" and not list(jdir.iterdir())


def test_the_checks_context_completes_a_cut_write_of_the_bashrc(tmp_path, monkeypatch):
    """The ROS checks (and the stdlib programs they start here) open ~/.bashrc themselves: the
    round's context completes a cut write first."""
    rc = tmp_path / ".bashrc"
    old = b"# mine\n" + b"export ROS_MASTER_URI=http://old:11311\n" * 40
    rc.write_bytes(old)
    new = b"# mine\nexport ROS_MASTER_URI=http://turtlebot:11311\n"
    assert _cut(rc, new, monkeypatch) not in (old, new)
    cfg = tmp_path / "settings.toml"
    cfg.write_text(ROBOT_CONFIG)
    make_context(load_settings(cfg), RunOptions(paths=Paths(bashrc_path=rc, state_dir=tmp_path / "sd")))
    assert rc.read_bytes() == new


def test_the_hosts_preview_and_apply_complete_a_cut_write_in_their_state_dir(tmp_path,
                                                                            monkeypatch):
    """``hosts apply --state-dir X`` previews from the completed file, not from the torn one."""
    from rosnet_tui.core.files.hosts import preview_hosts

    sd = tmp_path / "sd"
    target, new, cfg = _cut_journaled_in(sd, tmp_path, monkeypatch)
    preview = preview_hosts(load_settings(cfg), "remote", target, state_dir=sd)
    assert preview.old == new
    assert mw.read_bytes(target) == new


def test_hosts_show_finds_the_journal_in_the_state_dir_it_is_given(tmp_path, monkeypatch,
                                                                   capsys):
    """A writer with ``--state-dir X`` journaled in X (the file's folder may not be written):
    ``hosts show --state-dir X`` completes it, though X is not the default state dir."""
    from rosnet_tui.cli import main

    sd = tmp_path / "sd"
    target, new, cfg = _cut_journaled_in(sd, tmp_path, monkeypatch)
    assert main(["hosts", "show", "--config", str(cfg), "--file", str(target),
                 "--state-dir", str(sd)]) == 0
    assert "has no rosnet-tui block yet" in capsys.readouterr().out
    assert target.read_bytes() == new and not list((sd / INPLACE_DIR).iterdir())
