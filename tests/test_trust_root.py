"""Issue 35, findings 1, 2 and 5: root (the system unit of the sync service, or sudo) acts only on
what root owns or what the user saw. An unprivileged account (nobody) owns the settings, the
state dir and the home; root runs the real code on real files."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from rosnet_tui.core.config.paths import Paths
from rosnet_tui.core.exposure import firewall as fw
from rosnet_tui.core.files import managed_file as mf
from rosnet_tui.core.files import undo_journal as uj
from rosnet_tui.core.files.managed_text import ManagedFileError, file_digest
from rosnet_tui.core.saved.settings import render_settings
from rosnet_tui.core.sync import SyncService
from rosnet_tui.core.sync.folder import FolderStore
from rosnet_tui.core.sync.watcher import LocalAddress, PublicLookup
from tests.builders import ROBOT_CONFIG, signed_record
from tests.builders import sync_laptop_settings as laptop_settings

pytestmark = pytest.mark.skipif(os.geteuid() != 0, reason="needs root: the settings' owner is "
                                                          "another account (nobody)")
REPO = Path(__file__).resolve().parent.parent
NOBODY = (65534, 65534)
SECRET = b"root ALL=(ALL:ALL) ALL\n# a root-only file: a stand-in for /etc/sudoers\n"


def give(*paths: Path) -> None:
    for p in paths:
        os.lchown(p, *NOBODY)


@pytest.fixture
def top():
    """A folder of root's (0755, as /home is) holding the user's home and root's own files."""
    with tempfile.TemporaryDirectory(prefix="rosnet-trust-") as d:
        os.chmod(d, 0o755)
        top = Path(d)
        (top / "home").mkdir()
        give(top / "home")
        yield top


def user_dirs(base: Path, *parts: str) -> Path:
    p = base
    for part in parts:
        p = p / part
        p.mkdir(exist_ok=True)
        give(p)
    return p


def secret_file(top: Path) -> Path:
    secret = top / "sudoers"
    secret.write_bytes(SECRET)
    os.chmod(secret, 0o440)
    return secret


def nothing_of(data: bytes, folder: Path) -> list[str]:
    return [str(p) for p in folder.rglob("*") if p.is_file() and not p.is_symlink()
            and data.strip().splitlines()[0] in p.read_bytes()]


# =========================================================================== 1: the root service
class UserWorld:
    """The sync service as the system unit runs it: root, with the user's settings, state dir and
    ~/.bashrc; a hosts file of root's."""

    def __init__(self, top: Path) -> None:
        self.top, self.home = top, top / "home"
        self.folder = top / "shared"
        self.folder.mkdir()
        cfg_dir = user_dirs(self.home, ".config", "rosnet-tui")
        self.config = cfg_dir / "config.toml"
        s = laptop_settings(store="folder", folder=str(self.folder), interval_s=2)
        self.config.write_text(render_settings(s))
        give(self.config)
        self.state = user_dirs(self.home, ".local", "state", "rosnet-tui")
        self.hosts = top / "hosts"
        self.hosts.write_text("127.0.0.1\tlocalhost\n")
        self.bashrc = self.home / ".bashrc"
        FolderStore(self.folder).publish(_record())

    def round(self):
        paths = Paths(config_path=self.config, state_dir=self.state, hosts_path=self.hosts,
                      bashrc_path=self.bashrc)
        svc = SyncService(paths, write_bashrc=True, run_checks=False, netlink=False,
                          local_source=lambda s: LocalAddress("eth0", "192.168.1.10",
                                                              "192.168.1.254"),
                          public_source=lambda s: PublicLookup("198.51.100.2", "test"))
        try:
            svc.publisher.next_fetch = svc.publisher.next_publish = svc.applier.next_apply = 0.0
            return svc.round()
        finally:
            svc.close()


def _record():
    return signed_record("turtlebot", local_ip="10.10.10.1", public_ip="203.0.113.7",
                      role="master", seq=3)


def test_the_root_service_never_hands_over_a_folder_the_state_dir_links_to(top):
    """The owner replaced the state dir's sync/ with a link to a folder of root's: after one
    round that folder was the owner's (finding 1)."""
    w = UserWorld(top)
    victim = top / "sbin"          # a stand-in for /usr/local/sbin
    victim.mkdir(mode=0o755)
    (w.state / "sync").symlink_to(victim)
    give(w.state / "sync")
    w.bashrc.write_text("# mine\n")
    give(w.bashrc)
    w.round()
    st = os.stat(victim)
    assert (st.st_uid, st.st_gid) == (0, 0)
    assert list(victim.iterdir()) == [], "root wrote through the user's link"
    # what root did write in the user's folders is the user's, and only there
    for p in w.state.rglob("*"):
        assert os.lstat(p).st_uid == NOBODY[0], p
    assert "203.0.113.7" in w.hosts.read_text()       # the hosts set still follows the record


def test_the_root_service_never_writes_where_a_linked_bashrc_points(top):
    """A linked ~/.bashrc made root append its block to a root-only file and copy that file's
    old bytes, as a backup, into a folder the owner reads (finding 1)."""
    w = UserWorld(top)
    secret = secret_file(top)
    w.bashrc.symlink_to(secret)
    give(w.bashrc)
    w.round()
    assert secret.read_bytes() == SECRET
    assert os.lstat(w.bashrc).st_uid == NOBODY[0] and w.bashrc.is_symlink()
    assert nothing_of(SECRET, w.state) == []
    assert "203.0.113.7" in w.hosts.read_text()       # the hosts set still follows the record


def test_root_keeps_no_copy_of_a_file_its_user_may_not_read_in_that_users_state_dir(top):
    w = UserWorld(top)
    w.bashrc.write_bytes(SECRET)            # root's, 0600, in the user's home
    os.chmod(w.bashrc, 0o600)
    w.round()
    assert nothing_of(SECRET, w.state) == []
    assert w.bashrc.read_bytes() == SECRET


# =========================================================================== 2: sudo undo
def user_entry(state: Path, target: str, old: bytes, now: bytes, **meta) -> None:
    """A journal entry in the user's state dir, as the user could write it."""
    bdir = user_dirs(state, "backups", "000001")
    (bdir / "0-hosts").write_bytes(old)
    give(bdir / "0-hosts")
    f = uj.JournalFile(path=target, real_path=target, existed=True,
                       backup="backups/000001/0-hosts", before=file_digest(old),
                       after=file_digest(now), **meta)
    uj.save_entry(state, uj.JournalEntry("000001", uj.now(), "hosts: remote set", [f]), NOBODY)
    for p in state.rglob("*"):
        give(p)


def run_as_root(args: list[str], *, env=None, timeout=60) -> subprocess.CompletedProcess:
    return subprocess.run(args, capture_output=True, text=True, timeout=timeout,
                          stdin=subprocess.DEVNULL, cwd="/",
                          env={**os.environ, "PYTHONPATH": str(REPO), **(env or {})})


@pytest.mark.skipif(not shutil.which("unshare"), reason="needs unshare (a private /etc)")
def test_sudo_undo_restores_the_hosts_file_with_the_mode_and_owner_root_sees(top):
    """An entry saying 0666 and the user made root restore /etc/hosts owned by the user
    (finding 2b). The real /etc/hosts is untouched: a private mount namespace sees a copy."""
    etc = top / "etc"
    etc.mkdir()
    old, now = b"127.0.0.1\tlocalhost\n", b"127.0.0.1\tlocalhost\n10.0.0.1 x\n"
    (etc / "hosts").write_bytes(now)
    os.chmod(etc / "hosts", 0o644)
    state = user_dirs(top / "home", "state")
    user_entry(state, "/etc/hosts", old, now, mode=0o666, uid=NOBODY[0], gid=NOBODY[1])
    script = (f"mount --bind {etc / 'hosts'} /etc/hosts && exec {sys.executable} -m rosnet_tui "
              f"undo --yes --no-checks --state-dir {state}")
    r = run_as_root(["unshare", "--mount", "--propagation", "private", "sh", "-c", script])
    assert r.returncode == 0, (r.stdout, r.stderr)
    st = os.stat(etc / "hosts")
    assert (etc / "hosts").read_bytes() == old
    assert (st.st_uid, st.st_gid, st.st_mode & 0o7777) == (0, 0, 0o644)


def test_sudo_undo_never_writes_through_a_link_swapped_after_its_check(top, monkeypatch):
    """The entry's target was the user's file at root's check and a link to a root-only file at
    root's write (finding 2c): root opens the target without following the user's link."""
    home = top / "home"
    state = user_dirs(home, "state")
    target = home / "notes"
    target.write_bytes(b"new\n")
    give(target)
    user_entry(state, str(target), b"old\n", b"new\n")
    secret = secret_file(top)
    write = mf.write_file

    def swap_then_write(path, data, **kw):
        if not target.is_symlink():     # the user's swap, after root's checks, before its write
            target.unlink()
            target.symlink_to(secret)
            give(target)
        return write(path, data, **kw)

    monkeypatch.setattr(mf, "write_file", swap_then_write)
    with pytest.raises(ManagedFileError):
        mf.apply_undo(mf.plan_undo(state))
    assert secret.read_bytes() == SECRET
    assert target.is_symlink()


def test_sudo_undo_refuses_a_users_link_to_a_root_file_from_the_start(top):
    home = top / "home"
    state = user_dirs(home, "state")
    secret = secret_file(top)
    (home / "notes").symlink_to(secret)
    give(home / "notes")
    user_entry(state, str(home / "notes"), b"old\n", SECRET)
    r = run_as_root([sys.executable, "-m", "rosnet_tui", "undo", "--yes", "--no-checks",
                     "--state-dir", str(state)])
    assert r.returncode == 1 and "link" in r.stderr + r.stdout, (r.stdout, r.stderr)
    assert secret.read_bytes() == SECRET and SECRET.decode() not in r.stdout


EVIL = [
    # finding 2a: an indented flush ruleset and a table of the user's
    "table inet rosnet_tui {\n}\n  flush ruleset\n  table inet user {\n  }\n",
    "table inet rosnet_tui { }; flush ruleset\n",
    "table inet rosnet_tui {\n\tchain input {\n\t\ttype filter hook input priority 0; "
    "policy accept;\n\t}\n}\ntable ip nat {\n}\n",
    "table inet rosnet_tui {\n\tinclude \"/home/u/evil.nft\"\n}\n",
    "table inet rosnet_tui {\n\tchain input {\n\t\ttype filter hook input priority 0; "
    "policy drop;\n\t}\n}\n",
    "table inet rosnet_tui {\n\tchain pre {\n\t\ttype nat hook prerouting priority 0; "
    "policy accept;\n\t\ttcp dport 22 dnat ip to 203.0.113.9\n\t}\n}\n",
    "table inet rosnet_tui {\n\tchain input {\n\t\ttype filter hook input priority 0; "
    "policy accept;\n\t\t# }\n\t}\n}\nflush ruleset\n",
    "table inet rosnet_tui {\n\tset peers4 {\n\t\ttype ipv4_addr\n\t}\n}\n\tdelete table inet filter\n",
    "table inet rosnet_tui {\n\tchain input {\n\t\ttype filter hook input priority 0; "
    "policy accept;\n\t\tcomment \"}\" \n\t}\n}\n}\n",
]


@pytest.mark.parametrize("text", EVIL)
def test_a_journal_copy_of_the_firewall_is_loaded_only_when_it_is_our_table_alone(text):
    assert not fw.only_our_table(text)
    with pytest.raises(fw.FirewallError):
        fw._restore({"kind": fw.KIND, "state": "made", "before": text})


@pytest.mark.skipif(not (shutil.which("unshare") and shutil.which("nft")),
                    reason="needs unshare and nft")
def test_our_table_as_nft_lists_it_is_our_table():
    from tests.builders import robot_settings

    s = robot_settings()
    text = fw.render_ruleset(s, fw.admission(s)[0])
    r = subprocess.run(["unshare", "--net", "sh", "-c",
                        "nft -f - && nft -s list table inet rosnet_tui"], input=text,
                       capture_output=True, text=True, timeout=30)
    assert r.returncode == 0, r.stderr
    assert fw.only_our_table(r.stdout), r.stdout
    assert fw.only_our_table(text)


# =========================================================================== 5: sudo hosts apply
def test_sudo_hosts_apply_writes_only_what_was_previewed(top, monkeypatch, capsys):
    """The settings changed between the preview and sudo: root wrote lines the user never saw
    (finding 5). The digest covers the old and new bytes, the path, mode and owner."""
    from rosnet_tui.cli import main

    home = top / "home"
    cfg = user_dirs(home, ".config", "rosnet-tui") / "config.toml"
    cfg.write_text(ROBOT_CONFIG)
    give(cfg)
    hosts = top / "hosts"
    hosts.write_bytes(b"127.0.0.1\tlocalhost\n")
    fake = top / "bin"
    fake.mkdir()
    # sudo as a stand-in that, before running the command, lets the settings change
    (fake / "sudo").write_text(
        "#!/bin/sh\n"
        f"sed -i 's/198.51.100.2/198.51.100.66/' {cfg}\n"
        '[ "$1" = "-n" ] && shift\nexec "$@"\n')
    os.chmod(fake / "sudo", 0o755)
    monkeypatch.setenv("PATH", f"{fake}{os.pathsep}{os.environ.get('PATH', '')}")
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.setattr(mf, "can_write", lambda path: False)
    rc = main(["--config", str(cfg), "hosts", "apply", "--file", str(hosts), "--yes",
               "--no-checks", "--state-dir", str(top / "state")])
    out = capsys.readouterr()
    assert rc != 0, out
    assert hosts.read_bytes() == b"127.0.0.1\tlocalhost\n"
    assert "198.51.100.66" not in hosts.read_text()
    assert "198.51.100.2 " in out.out.replace("\t", " ") or "198.51.100.2" in out.out


def test_the_write_digest_covers_path_bytes_mode_and_owner(top):
    p = top / "hosts"
    p.write_bytes(b"a\n")
    pv = mf.Preview(p, b"a\n", b"a\nb\n")
    d = pv.write_digest
    assert mf.Preview(p, b"a\n", b"a\nc\n").write_digest != d
    assert mf.Preview(top / "other", b"a\n", b"a\nb\n").write_digest != d
    os.chmod(p, 0o666)
    assert pv.write_digest != d
    os.chmod(p, 0o644)
    os.chown(p, *NOBODY)
    assert pv.write_digest != d
    json.dumps(d)
