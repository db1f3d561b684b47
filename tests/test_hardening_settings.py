"""Issue 15, settings: every problem is exit 2 with one clear line naming file, line and key, no
traceback, the file untouched; reads are bounded in size and time.

Reproduced: ~400 nested brackets crashed the loader (RecursionError); a bad 100 KB value was
echoed in full; peers equal but for case were accepted; a U+2028 in a comment shifted the reported
line; ``--config`` on a FIFO hung and a link to /dev/zero read until memory ran out; ``timeout_s =
true`` was taken as 1 s; ``[peer]`` beside ``[[peer]]`` gave the raw parser message.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rosnet_tui.core.config.settings_model import MAX_SETTINGS_BYTES, SettingsError
from rosnet_tui.core.saved.settings import load_settings, parse_settings
from tests.hardening_tally import tally
from tests.test_hardening_inputs import returns_within

REPO = Path(__file__).resolve().parents[1]
AREA = "settings"
GOOD = ('[this]\nname = "sami"\nrole = "member"\n[[peer]]\nname = "turtlebot"\n'
        'public_ip = "203.0.113.2"\n[ros]\nmaster = "turtlebot"\n')


def refused(text: str, tmp_path: Path) -> SettingsError:
    path = tmp_path / "config.toml"
    path.write_text(text, encoding="utf-8")
    before = path.read_bytes()
    with pytest.raises(SettingsError) as info:
        load_settings(path)
    err = info.value
    msg = str(err)
    assert str(path) in msg
    assert "\n" not in msg and len(msg) < 400 + len(str(path)), msg[:500]
    assert path.read_bytes() == before
    return err


# --------------------------------------------------------------------------- nesting
@pytest.mark.parametrize("text, line", [
    ("[this]\nname = " + "[" * 400 + "]" * 400 + "\n", 2),
    ("[this]\nname = " + "[" * 3000 + "]" * 3000 + "\n", 2),
    ('[this]\nname = "a"\n[probe]\npublic_ip_urls = ' + "{a=" * 500 + "1" + "}" * 500 + "\n", 4),
    ("# a [ comment [[[[\n[this]\nname = " + "[" * 1000 + "\n", 3),
    ('[this]\nname = "[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[["\nrole = '
     + "[" * 800 + "]" * 800 + "\n", 3),
], ids=["400", "3000", "inline-tables", "unclosed", "brackets-in-a-string"])
def test_deep_nesting_is_a_settings_error_with_line_and_key(tmp_path, text, line):
    err = refused(text, tmp_path)
    assert "nested" in str(err)
    assert err.line == line
    tally(AREA, 1, 1, "nesting")


# --------------------------------------------------------------------------- long values
@pytest.mark.parametrize("text, key", [
    ('[this]\nname = "a"\nlocal_ip = "' + "1" * 100_000 + '"\n', "this.local_ip"),
    ('[this]\nname = "' + "x" * 100_000 + '"\n', "this.name"),
    ('[this]\nname = "a"\nrole = "' + "m" * 100_000 + '"\n', "this.role"),
    ('[probe]\nport_check_url = "' + "u" * 100_000 + '"\n', "probe.port_check_url"),
    ('[this]\n"' + "k" * 100_000 + '" = 1\n', None),
    ('[checks]\ntimeout_s = 1' + "0" * 400 + "\n", "checks.timeout_s"),      # no float holds it
    ('[checks]\ntimeout_s = 1' + "0" * 5000 + "\n", None),                   # nor an int parse
    ('[ros]\nport = 1' + "0" * 5000 + "\n", None),
    ('[this]\nname = "a"\nlocal_ip = "1\\n2\\n3\\u0007"\n', "this.local_ip"),  # control chars
], ids=["ip", "name", "role", "url", "key", "int400", "int5000", "port5000", "ctrl"])
def test_a_huge_or_odd_value_is_refused_in_a_short_line(tmp_path, text, key):
    err = refused(text, tmp_path)
    if key is not None:
        assert err.key == key and err.line is not None
    tally(AREA, 1, 1, "long values")


# --------------------------------------------------------------------------- names
@pytest.mark.parametrize("text, line", [
    ('[this]\nname = "sami"\n[[peer]]\nname = "Robot"\npublic_ip = "203.0.113.2"\n'
     '[[peer]]\nname = "robot"\npublic_ip = "203.0.113.3"\n', 7),
    ('[this]\nname = "sami"\n[[peer]]\nname = "SAMI"\npublic_ip = "203.0.113.2"\n', 4),
])
def test_names_equal_but_for_case_are_the_same_name(tmp_path, text, line):
    err = refused(text, tmp_path)
    assert "used twice" in str(err) and err.line == line and err.key == "peer.name"
    tally(AREA, 1, 1, "case")


# --------------------------------------------------------------------------- line numbers
@pytest.mark.parametrize("sep", ["\u2028", "\u2029", "\x85"])
def test_unicode_line_separators_in_comments_do_not_shift_the_line(tmp_path, sep):
    """TOML allows these in a comment and ends a line only at LF: a later problem keeps its line."""
    text = f'# a comment{sep}with a separator\n[this]\n# {sep}{sep}\nname = "bad name"\n'
    err = refused(text, tmp_path)
    assert err.line == 4 and err.key == "this.name"
    tally(AREA, 1, 1, "line separators")


@pytest.mark.parametrize("sep", ["\x0b", "\x0c", "\x1c", "\x1d", "\x1e"])
def test_control_characters_that_python_counts_as_line_ends_are_refused_on_their_own_line(
        tmp_path, sep):
    """TOML refuses these anywhere (no comment or string can hold them), so no later problem can
    follow them: the refusal itself names the line that holds one, counted by LF only (Python's
    splitlines would count one more line per character)."""
    err = refused(f'[this]\nname = "sami"\n# x{sep}y{sep}\n# {sep}\n', tmp_path)
    assert err.line == 3 and "not valid TOML" in str(err)
    err = refused(f'# {sep}{sep}{sep}\n[this]\nname = "sami"\n', tmp_path)
    assert err.line == 1
    tally(AREA, 1, 1, "line separators")
    tally(AREA, 1, 1, "line separators")


# --------------------------------------------------------------------------- types
@pytest.mark.parametrize("text, key", [
    ("[checks]\ntimeout_s = true\n", "checks.timeout_s"),
    ("[checks]\ntimeout_s = false\n", "checks.timeout_s"),
    ("[sync]\ninterval_s = true\n", "sync.interval_s"),
    ("[checks]\ntimeout_s = nan\n", "checks.timeout_s"),
    ("[checks]\ntimeout_s = inf\n", "checks.timeout_s"),
    ("[sync]\ninterval_s = -inf\n", "sync.interval_s"),
    ("[sync]\ninterval_s = 1e9\n", "sync.interval_s"),
])
def test_a_boolean_or_non_finite_number_is_not_a_number_of_seconds(tmp_path, text, key):
    err = refused(text, tmp_path)
    assert err.key == key and err.line == 2
    tally(AREA, 1, 1, "types")


@pytest.mark.parametrize("text, line", [
    (GOOD + '[peer]\nname = "rover"\n', 9),
    ('[this]\nname = "sami"\n[peer]\nname = "rover"\n[[peer]]\nname = "x"\n', 3),
    ('[this]\nname = "sami"\n[peer]\nname = "rover"\n', 3),
])
def test_peer_with_one_bracket_says_how_to_write_it(tmp_path, text, line):
    err = refused(text, tmp_path)
    assert "[[peer]]" in str(err) and err.key == "peer" and err.line == line
    assert "Cannot" not in str(err)      # not the raw parser message
    tally(AREA, 1, 1, "[peer]")


def test_a_table_declared_twice_is_said_in_words(tmp_path):
    err = refused('[this]\nname = "a"\n[this]\nname = "b"\n', tmp_path)
    assert "[this]" in str(err) and "twice" in str(err) and err.line == 3
    tally(AREA, 1, 1, "twice")


def test_a_byte_order_mark_is_named(tmp_path):
    err = refused("\ufeff" + GOOD, tmp_path)
    assert "byte-order mark" in str(err) and err.line == 1
    tally(AREA, 1, 1, "bom")


# --------------------------------------------------------------------------- what is read
def test_not_a_regular_file_is_refused_without_reading_it(tmp_path):
    fifo = tmp_path / "fifo.toml"
    os.mkfifo(fifo)
    zero = tmp_path / "zero.toml"
    zero.symlink_to("/dev/zero")
    for path in (fifo, zero, tmp_path):     # returning at all: the FIFO was not opened to read
        box = returns_within(lambda p=path: load_settings(p), fifo)
        assert isinstance(box.get("error"), SettingsError), box
        assert "not a regular file" in str(box["error"])
    tally(AREA, 3, 3, "not a file")


def test_a_huge_file_is_refused_by_its_size(tmp_path):
    path = tmp_path / "big.toml"
    with open(path, "wb") as f:
        f.write(GOOD.encode())
        f.truncate(MAX_SETTINGS_BYTES + 1)
    with pytest.raises(SettingsError, match="too big"):
        load_settings(path)
    tally(AREA, 1, 1, "size")


def cli(*args: str, timeout: float = 20) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "rosnet_tui", *args], capture_output=True,
                          text=True, timeout=timeout, env=dict(os.environ, PYTHONPATH=str(REPO)),
                          cwd=REPO, stdin=subprocess.DEVNULL)


CASES = {
    "nested": "[this]\nname = " + "[" * 1000 + "]" * 1000 + "\n",
    "long": '[this]\nname = "a"\nlocal_ip = "' + "1" * 100_000 + '"\n',
    "case": '[this]\nname = "sami"\n[[peer]]\nname = "SAMI"\npublic_ip = "203.0.113.2"\n',
    "bool": GOOD + "[checks]\ntimeout_s = true\n",
    "peer": GOOD + '[peer]\nname = "rover"\n',
    "int": GOOD + "[checks]\ntimeout_s = 1" + "0" * 5000 + "\n",
}


@pytest.mark.parametrize("command", [["check"], ["hosts", "show"], ["report"],
                                     ["sync", "--once"], []],
                         ids=["check", "hosts", "report", "sync", "wizard"])
def test_every_command_exits_2_in_one_line_and_leaves_the_file(tmp_path, command):
    special = {"fifo": tmp_path / "fifo.toml", "zero": tmp_path / "zero.toml"}
    os.mkfifo(special["fifo"])
    special["zero"].symlink_to("/dev/zero")
    paths = dict(special)
    for name, text in CASES.items():
        p = tmp_path / f"{name}.toml"
        p.write_text(text)
        paths[name] = p
    n = 0
    for name, path in paths.items():
        before = None if name in special else path.read_bytes()
        extra = ["--state-dir", str(tmp_path / "state")] if command[:1] == ["sync"] else []
        r = cli(*command, "--config", str(path), *extra)
        assert r.returncode == 2, (name, r.returncode, r.stderr[-500:])
        assert "Traceback" not in r.stderr, (name, r.stderr[-2000:])
        lines = [x for x in r.stderr.splitlines() if x.strip()]
        where = [x for x in lines if str(path) in x]
        # one line says what and where; the wizard adds one line of advice
        assert len(where) == 1 and len(lines) <= (3 if not command else 1), (name, r.stderr[:600])
        assert all(len(x) < 600 for x in lines), (name, r.stderr[:300])
        if before is not None:
            assert path.read_bytes() == before
        n += 1
    tally(AREA, n, n, "cli")


# --------------------------------------------------------------------------- property
_pieces = st.sampled_from([
    "[this]\n", "[[peer]]\n", "[peer]\n", "[ros]\n", "[checks]\n", "[sync]\n", "[probe]\n",
    'name = "sami"\n', 'name = "SAMI"\n', "timeout_s = true\n", "timeout_s = nan\n",
    "interval_s = 1e308\n", "port = 1" + "0" * 30 + "\n", 'public_ip = "203.0.113.2"\n',
    "x = " + "[" * 1500 + "]" * 1500 + "\n", "# \u2028 comment\n", 'local_ip = "' + "9" * 500 + '"\n',
    "ssh_port = -1\n", "public_ip_urls = [1, 2]\n", "role = 3\n", "\x00\n", "= 3\n",
    '"\\ud800" = 1\n', "a.b.c = 1\n", "[this.name]\n",
])


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(_pieces, max_size=12), st.text(max_size=30))
def test_property_any_settings_text_loads_or_is_a_settings_error(pieces, noise):
    text = "".join(pieces) + noise
    try:
        parse_settings(text, Path("/c.toml"))
    except SettingsError as exc:
        msg = str(exc)
        assert "\n" not in msg and len(msg) < 500
    tally(AREA, 1, 1, "property")
