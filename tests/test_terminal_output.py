"""The frugal terminal writer (rosnet_tui/ui/terminal.py) shows exactly what Textual drew.

A real session of the wizard is recorded under a pty with the writer turned off (Textual's own
output), then replayed through :class:`FrugalScreen`; a terminal emulator (pyte) fed each stream
must show the same characters with the same attributes in every cell, while the rewritten
stream is a fraction of the size.
"""

from __future__ import annotations

import re
import sys

import pyte
import pytest

from bench.local_env import local_world, spawn_app
from rosnet_tui.ui.terminal import DEFAULT, FrugalScreen, apply_sgr, sgr_change

# Sequences the emulator does not know and would print (kitty keyboard, mode queries): both
# streams carry them; they are taken out of what the emulators see.
_UNKNOWN_TO_PYTE = re.compile(r"\x1b\[[<>=][0-9;]*[a-zA-Z]|\x1b\[\?[0-9;]*\$[a-zA-Z]")


def _pyte(text: str) -> str:
    return _UNKNOWN_TO_PYTE.sub("", text)


def screen_state(screen: pyte.Screen) -> list[list[tuple]]:
    return [[(c.data, c.fg, c.bg, c.bold, c.italics, c.underscore, c.strikethrough, c.reverse)
             for c in (screen.buffer[y][x] for x in range(screen.columns))]
            for y in range(screen.lines)]


def replay(chunks: list[str], cols: int, rows: int) -> tuple[int, int]:
    """Feed Textual's output and the rewritten output to two emulators; compare them at every
    point where the rewriter holds nothing back. Returns (bytes in, bytes out)."""
    raw, thin = pyte.Screen(cols, rows), pyte.Screen(cols, rows)
    raw_stream, thin_stream = pyte.Stream(raw), pyte.Stream(thin)
    frugal = FrugalScreen(cols, rows)
    n_in = n_out = 0
    compared = 0
    for chunk in chunks:
        text = chunk
        out = frugal.feed(text)
        n_in += len(chunk.encode())
        n_out += len(out.encode())
        raw_stream.feed(text)
        thin_stream.feed(_pyte(out))
        if not frugal._carry:
            assert screen_state(thin) == screen_state(raw)
            compared += 1
    assert compared > 3
    return n_in, n_out


@pytest.mark.parametrize("term,size", [("xterm-256color", (80, 24)), ("linux", (120, 40))])
def test_a_recorded_session_looks_the_same_through_the_writer(term, size):
    import os

    os.environ["ROSNET_TUI_FRUGAL"] = "0"  # inherited by the recorded program: Textual's output
    try:
        with local_world() as world:
            world.fresh_state()
            p = spawn_app(world, cols=size[0], rows=size[1], term=term)
            try:
                assert p.wait_text("Your provider allows", 30) is not None, p.text_since(0)[-500:]
                p.wait_quiet(0.5, 10)
                for key, shown in (("2", "Your modem forwards"), ("r", "checking"),
                                   ("1", "Your provider"), ("?", "Four steps"), ("\x1b", None),
                                   ("s", "This component"), ("x", None)):
                    mark = p.mark
                    p.send(key)
                    if shown:
                        p.wait_text(shown, 10, mark)
                    else:
                        p.wait_for(lambda t: True, 3, mark)
                    p.wait_quiet(0.6, 10)
            finally:
                p.close(b"\x11")
            chunks = [c.data for c in p.chunks]
    finally:
        del os.environ["ROSNET_TUI_FRUGAL"]
    # Cut at arbitrary places (escape sequences split too), to exercise the carry.
    data = _pyte(b"".join(chunks).decode("utf-8"))
    for cut in (4093, 997, 61):
        n_in, n_out = replay([data[i:i + cut] for i in range(0, len(data), cut)], *size)
        assert n_out < n_in / 3, (n_in, n_out)


def test_sgr_parsing_and_shortest_change():
    s = apply_sgr(DEFAULT, "1;38;5;12;48;2;1;2;3")
    assert s == ("38;5;12", "48;2;1;2;3", None, 1)
    assert apply_sgr(s, "0") == DEFAULT
    assert apply_sgr(DEFAULT, "") == DEFAULT
    assert apply_sgr(DEFAULT, "4:3") is None  # curly underline: not modelled, passed on
    assert sgr_change(DEFAULT, DEFAULT) == ""
    assert sgr_change(None, DEFAULT) == "\x1b[m"
    assert sgr_change(apply_sgr(DEFAULT, "1;31"), apply_sgr(DEFAULT, "1;32")) == "\x1b[32m"
    bold_dim = apply_sgr(DEFAULT, "1;2")
    assert apply_sgr(bold_dim, sgr_change(bold_dim, apply_sgr(DEFAULT, "2"))[2:-1]) == \
        apply_sgr(DEFAULT, "2")


def test_unchanged_cells_are_not_sent_again():
    f = FrugalScreen(20, 3)
    frame = "\x1b[1;1H\x1b[31mhello\x1b[0m\x1b[2;1H\x1b[1mworld\x1b[0m"
    assert "hello" in f.feed(frame)
    assert f.feed(frame) == ""
    out = f.feed(frame.replace("world", "wordy"))
    assert "dy" in out and "hello" not in out and len(out) < 15


def test_wide_characters_and_blanks():
    f = FrugalScreen(20, 2)
    a = f.feed("\x1b[1;1H日本" + " " * 16)
    assert "日本" in a
    assert f.feed("\x1b[1;1H日本" + " " * 16) == ""
    b = f.feed("\x1b[1;1Hab本" + " " * 16)  # half of a wide character overwritten
    screen = pyte.Screen(20, 2)
    pyte.Stream(screen).feed(a + b)
    assert screen.display[0].startswith("ab本")


def test_incomplete_sequence_waits_for_the_rest():
    f = FrugalScreen(20, 2)
    out = f.feed("\x1b[1;1H\x1b[3") + f.feed("1mred\x1b[0m")
    screen = pyte.Screen(20, 2)
    pyte.Stream(screen).feed(out)
    assert screen.display[0].startswith("red") and screen.buffer[0][0].fg == "red"


if __name__ == "__main__":  # pragma: no cover
    sys.exit(pytest.main([__file__, "-q"]))


def _walk(term: str, no_color: bool = False) -> str:
    """The wizard's output through every screen (steps, results, evidence, advisor, help,
    set-up), on loopback."""
    with local_world() as world:
        world.fresh_state()
        p = spawn_app(world, term=term, no_color=no_color)
        try:
            assert p.wait_text("Your provider allows", 30) is not None
            p.wait_quiet(0.4, 10)
            for key, shown in (("2", "Your modem forwards"), ("r", "checking"), ("e", None),
                               ("3", None), ("4", None), ("a", None), ("\x1b", None),
                               ("?", "closes this help"), ("\x1b", None),
                               ("s", "This component"), ("\x1b", None)):
                mark = p.mark
                p.send(key)
                if shown:
                    p.wait_text(shown, 10, mark)
                else:
                    p.wait_for(lambda t: True, 3, mark)
                p.wait_quiet(0.5, 10)
        finally:
            p.close(b"\x11")
        return p.raw_since(0).decode("utf-8", "replace")


def test_the_linux_console_gets_only_glyphs_its_font_has():
    from rosnet_tui.ui.terminal import CP437

    text = re.sub(r"\x1b\[[0-?]*[ -/]*[@-~]|\x1b\][^\x07\x1b]*(?:\x07|\x1b\\)", "",
                  _walk("linux"))
    missing = sorted({ch for ch in text if ord(ch) > 126 and ch not in CP437})
    assert not missing, missing


def test_no_color_draws_no_colour_and_shows_focus_in_reverse():
    raw = _walk("xterm-256color", no_color=True)
    params = [p for seq in re.findall(r"\x1b\[([0-9;]*)m", raw) for p in seq.split(";") if p]
    colours = [p for p in params if p in {"38", "48"} or 30 <= int(p) <= 49 and p not in
               {"39", "49"} or 90 <= int(p) <= 107]
    assert not colours, sorted(set(colours))
    assert "7" in params  # the cursor row and the current step: reverse video
