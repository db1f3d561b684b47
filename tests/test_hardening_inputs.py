"""Issue 21, hardening leftovers: JSON nested too deeply, and files that are FIFOs.

Reproduced: ``state.read_json`` on a state file of a few thousand brackets raised RecursionError
(the sync status, the applied records and the address histories all read through it); a TSIG key
file that is a FIFO hung the DNS store in ``open()`` until someone wrote to it. Now every JSON
text from a file, a peer or the network is decoded with a bounded depth (``core.jsonsafe``), or,
in the stdlib-only programs that also run on peers, RecursionError is caught like a decode error;
and every file a user names or the state dir holds is read without blocking, regular files only,
bounded (``core.files.regular_file``).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from rosnet_tui.core.files import managed_file as mf
from rosnet_tui.core.files import managed_text as mt
from rosnet_tui.core.files import undo_journal as uj
from rosnet_tui.core.files.cut_writes import MAGIC, journal_target
from rosnet_tui.core.files.inplace_format import parse_journal
from tests.hardening_tally import tally

REPO = Path(__file__).resolve().parents[1]
AREA = "deep JSON and FIFOs"
DEEP = "[" * 50_000 + "]" * 50_000
DEEP_OBJ = '{"a":' * 20_000 + "1" + "}" * 20_000


# --------------------------------------------------------------------------- deep JSON
@pytest.mark.parametrize("text", [DEEP, DEEP_OBJ, '{"history": ' + DEEP + "}"])
def test_state_read_json_refuses_deep_nesting_as_damaged_state(tmp_path, text):
    from rosnet_tui.core.saved import state

    p = tmp_path / state.PUBLIC_IP_FILE
    p.write_text(text)
    assert state.read_json(p) is None                         # damaged state: as if missing
    assert state.public_ip_history(tmp_path) == []
    rec = state.record_public_ip(tmp_path, "203.0.113.9")     # and it is written afresh
    assert rec.history[-1]["ip"] == "203.0.113.9"
    tally(AREA, 1, 1, "state.read_json")


def test_sync_status_and_applied_records_survive_deep_nesting(tmp_path):
    from rosnet_tui.core.saved import sync_applied as applied
    from rosnet_tui.core.sync import status

    for p in (status.status_path(tmp_path), applied.applied_path(tmp_path)):
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(DEEP)
    assert applied.load_applied(tmp_path) == {}
    assert status.load_status(tmp_path) is None
    tally(AREA, 2, 2, "status.json, applied.json")


def test_ui_state_survives_deep_nesting(tmp_path):
    from rosnet_tui.core.saved.ui_state import UI_FILE, UiState

    (tmp_path / UI_FILE).write_text(DEEP_OBJ)
    assert UiState(tmp_path).data == {}
    tally(AREA, 1, 1, "ui.json")


def test_a_deeply_nested_undo_journal_entry_is_skipped_not_a_crash(tmp_path):
    target = tmp_path / "rc"
    target.write_text("# mine\n")
    sd = tmp_path / "state"
    mf.apply_preview(mf.preview_block(target, ["export A=1"]), state_dir=sd)
    (sd / "journal" / "000002.json").write_text(DEEP_OBJ)
    assert [e.id for e in uj.journal_entries(sd)] == ["000001"]
    mf.undo_last(sd)
    assert target.read_text() == "# mine\n"
    tally(AREA, 1, 1, "undo journal")


def test_an_in_place_journal_with_a_deep_header_is_not_trusted(tmp_path):
    head = MAGIC + DEEP.encode() + b"\n"
    assert parse_journal(head) is None
    journal = tmp_path / ".hosts.rosnet-tui.1-2.inplace"
    journal.write_bytes(head)
    assert journal_target(str(journal)) is None        # what start-up reads of it: no crash


def test_peer_and_network_json_parsers_refuse_deep_nesting():
    from rosnet_tui.core.checks.router import parse_probe_result
    from rosnet_tui.core.exposure.public_ip import parse_ip
    from rosnet_tui.core.peer import rosproto, zenohproto
    from rosnet_tui.core.ros import ros2

    assert parse_ip('{"ip": ' + DEEP + "}") is None
    assert zenohproto.parse_report(zenohproto.REPORT_MARK + DEEP_OBJ) is None
    assert rosproto.parse_report_line(DEEP_OBJ) is None
    with pytest.raises(ValueError):
        ros2.loads_json5(DEEP_OBJ)
    assert parse_probe_result("RESULT " + DEEP_OBJ) is None
    assert parse_probe_result("RESULT [1, 2]") is None         # not an object: no AttributeError
    assert parse_probe_result('RESULT {"7447": ["open", "ok"]}') == {7447: ("open", "ok")}
    tally(AREA, 6, 6, "peer and network JSON")


def test_every_json_decode_in_the_product_is_bounded():
    """Siblings: outside core.jsonsafe, json.loads appears only in the stdlib-only peer programs
    (they cannot import it), and there RecursionError is caught with the decode errors."""
    peer_programs = ("rosnet_tui/core/peer/rosproto.py", "rosnet_tui/core/peer/zenohproto.py",
                     "rosnet_tui/core/peer/agentproto.py", "rosnet_tui/core/peer/relayproto.py",
                     "rosnet_tui/core/peer/zenohlink.py")
    allowed = {"rosnet_tui/core/jsonsafe.py", *peer_programs}
    found = []
    for p in sorted((REPO / "rosnet_tui").rglob("*.py")):
        rel = p.relative_to(REPO).as_posix()
        text = p.read_text()
        for m in re.finditer(r"json\.loads?\(", text):
            if rel not in allowed:
                found.append(f"{rel}:{text.count(chr(10), 0, m.start()) + 1}")
        if rel in peer_programs:
            for block in re.finditer(r"json\.loads\(.*?\n(?:.*\n){0,2}?\s*except \(([^)]*)\)",
                                     text):
                assert "RecursionError" in block.group(1), (rel, block.group(0))
    assert not found, f"unbounded JSON decoding: {found}"


# --------------------------------------------------------------------------- FIFOs
def returns_within(fn, fifo: Path, seconds: float = 20.0):
    """Run *fn* in a thread; it must return (or raise). Returning at all is the proof: open() of
    a FIFO nobody writes to never returns by itself, so no wall-clock figure is asserted;
    *seconds* only bounds the wait for a call that is stuck (freed afterwards by opening the
    FIFO's other end, so the test never hangs)."""
    box: dict = {}

    def run():
        try:
            box["value"] = fn()
        except BaseException as exc:  # noqa: BLE001 - handed to the test
            box["error"] = exc

    t = threading.Thread(target=run, daemon=True)
    t.start()
    t.join(seconds)
    if t.is_alive():
        try:                                                  # free a reader: EOF
            fd = os.open(fifo, os.O_WRONLY | os.O_NONBLOCK)
        except OSError:                                       # no reader: it waits to write
            fd = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)
        time.sleep(0.2)
        os.close(fd)
        t.join(5)
        pytest.fail(f"still blocked after {seconds} s on the FIFO {fifo}")
    return box


def test_a_tsig_key_file_that_is_a_fifo_is_refused_at_once(tmp_path):
    from rosnet_tui.core.sync.dnsstore import load_tsig_key
    from rosnet_tui.core.sync.store import StoreConfigError

    fifo = tmp_path / "robots.key"
    os.mkfifo(fifo)
    box = returns_within(lambda: load_tsig_key(fifo), fifo)
    assert isinstance(box.get("error"), StoreConfigError), box
    assert "not a regular file" in str(box["error"]) and str(fifo) in str(box["error"])
    tally(AREA, 1, 1, "TSIG key FIFO")


def test_a_tsig_key_file_that_is_huge_or_a_device_is_refused(tmp_path):
    from rosnet_tui.core.sync.dnsstore import load_tsig_key
    from rosnet_tui.core.sync.store import StoreConfigError

    link = tmp_path / "zero.key"
    link.symlink_to("/dev/zero")
    # In a child with 1 GB of address space and 20 s: reading /dev/zero must not be tried.
    code = ("import resource, sys; resource.setrlimit(resource.RLIMIT_AS, (1 << 30, 1 << 30))\n"
            "from rosnet_tui.core.sync.dnsstore import load_tsig_key\n"
            "from rosnet_tui.core.sync.store import StoreConfigError\n"
            "try:\n    load_tsig_key(sys.argv[1])\nexcept StoreConfigError as exc:\n"
            "    print(exc)\n")
    r = subprocess.run([sys.executable, "-c", code, str(link)], capture_output=True, text=True,
                       timeout=20, env=dict(os.environ, PYTHONPATH=str(REPO)))
    assert "not a regular file" in r.stdout, (r.stdout, r.stderr[-500:])
    big = tmp_path / "big.key"
    big.write_bytes(b"#" * (2 << 20))
    with pytest.raises(StoreConfigError, match="too big"):
        load_tsig_key(big)
    tally(AREA, 2, 2, "TSIG key device, huge")


@pytest.mark.parametrize("which", ["public_ip", "ui", "journal", "backup", "router_config"])
def test_state_files_and_named_files_that_are_fifos_do_not_hang(tmp_path, which, monkeypatch):
    from rosnet_tui.core.saved import state

    if which == "public_ip":
        fifo = tmp_path / state.PUBLIC_IP_FILE
        os.mkfifo(fifo)
        box = returns_within(lambda: state.read_json(fifo), fifo)
        assert box == {"value": None}
    elif which == "ui":
        from rosnet_tui.core.saved.ui_state import UI_FILE, UiState

        fifo = tmp_path / UI_FILE
        os.mkfifo(fifo)
        box = returns_within(lambda: UiState(tmp_path).data, fifo)
        assert box == {"value": {}}
    elif which == "journal":
        sd = tmp_path / "state"
        (sd / "journal").mkdir(parents=True)
        fifo = sd / "journal" / "000001.json"
        os.mkfifo(fifo)
        box = returns_within(lambda: uj.journal_entries(sd), fifo)
        assert box == {"value": []}
    elif which == "backup":
        target = tmp_path / "rc"
        target.write_text("# mine\n")
        sd = tmp_path / "state"
        res = mf.apply_preview(mf.preview_block(target, ["export A=1"]), state_dir=sd)
        (backup,) = res.backups
        backup.unlink()
        os.mkfifo(backup)
        fifo = backup
        box = returns_within(lambda: mf.plan_undo(sd), fifo)
        assert isinstance(box.get("error"), mt.ManagedFileError), box
    else:
        from rosnet_tui.core.checks.ros2 import _read_router_config

        fifo = tmp_path / "router.json5"
        os.mkfifo(fifo)
        box = returns_within(lambda: _read_router_config(f"file://{fifo}"), fifo)
        data, why = box["value"]
        assert data is None and "not a regular file" in why
    tally(AREA, 1, 1, f"FIFO {which}")


@pytest.mark.parametrize("which", ["ros1_bashrc", "ros2_bashrc", "ros2_distro", "known_hosts"])
def test_more_files_that_are_fifos_do_not_hang(tmp_path, which):
    """Siblings: ~/.bashrc as the ROS checks (and their peer programs) read it, and the
    known_hosts file the wizard appends a trusted key to."""
    fifo = tmp_path / ("known_hosts" if which == "known_hosts" else ".bashrc")
    os.mkfifo(fifo)
    if which == "ros1_bashrc":
        from rosnet_tui.core.peer.rosproto import read_shell_exports

        box = returns_within(lambda: read_shell_exports(str(fifo), ("ROS_MASTER_URI",)), fifo)
        assert box == {"value": {}}
    elif which == "ros2_bashrc":
        from rosnet_tui.core.peer.zenohproto import read_exports

        box = returns_within(lambda: read_exports(str(fifo)), fifo)
        assert box == {"value": {}}
    elif which == "ros2_distro":
        from rosnet_tui.core.peer.zenohproto import ros_env

        box = returns_within(lambda: ros_env({}, str(fifo)), fifo)
        assert box == {"value": {}}
    else:
        from rosnet_tui.core.ssh.known_hosts import trust_host_key
        from rosnet_tui.core.ssh.options import SshOptions

        key = "ssh-ed25519 AAAAC3NzaC1lZDI1NTE5AAAAIEdz0LdBvGAIK3wAmPBkH3TkjCFRCe7Ddm6yZ8pHsH4j"
        opts = SshOptions(ssh_dir=str(tmp_path), known_hosts_files=[str(fifo)])
        box = returns_within(lambda: trust_host_key(opts, "turtlebot", 22, key), fifo)
        assert isinstance(box.get("error"), ValueError) and "not a regular file" in \
            str(box["error"]), box
    tally(AREA, 1, 1, f"FIFO {which}")


def test_sync_install_over_a_fifo_unit_file_is_refused_at_once(tmp_path):
    from rosnet_tui.cli.sync import UNIT_NAME

    cfg = tmp_path / "settings.toml"
    cfg.write_text('[this]\nname = "turtlebot"\n')
    os.mkfifo(tmp_path / UNIT_NAME)
    started = time.monotonic()
    r = subprocess.run([sys.executable, "-m", "rosnet_tui", "sync", "install-service", "--config",
                        str(cfg), "--unit-dir", str(tmp_path), "--yes"], capture_output=True,
                       text=True, timeout=30, env=dict(os.environ, PYTHONPATH=str(REPO)),
                       stdin=subprocess.DEVNULL)
    assert r.returncode == 1 and "not a regular file" in r.stderr, (r.returncode, r.stderr)
    assert "Traceback" not in r.stderr and time.monotonic() - started < 15
    tally(AREA, 1, 1, "FIFO sync unit")
