"""What goes down the wire: only the cells that changed, in as few bytes as the terminal allows.

Textual repaints whole regions (a screen change several times, the footer on every binding change)
and writes a full colour sequence and a reset around every run of text. On a 64 kbit/s link that
is seconds per screen. :class:`FrugalScreen` sits between Textual and the terminal: it keeps a
model of what the terminal shows (character and attributes of every cell) and sends only the cells
that differ, moving the cursor over the rest, with the shortest attribute change (never a reset
followed by the same colours) and an erase (ECH) for runs of blanks.

It understands what Textual writes (cursor addressing, SGR attributes, text, CR/LF); any other
sequence that could change the screen makes it forget its model, so the next frame is sent whole.
:class:`FrugalDriver` plugs it into Textual's Linux driver, forgets the model whenever the terminal
may have changed behind its back (start, resume after suspend, resize, Ctrl+L), and reports
clicks only (no mouse-motion traffic).
"""

from __future__ import annotations

import re
import unicodedata

from rich.cells import cell_len

# An SGR state: (foreground, background, underline colour, attribute bits). Colours are the SGR
# parameters that set them ("31", "38;5;12", "38;2;1;2;3"), None for the default.
BOLD, DIM, ITALIC, UNDERLINE, BLINK, REVERSE, CONCEAL, STRIKE, OVERLINE = (1 << i for i in range(9))
_ON = {1: BOLD, 2: DIM, 3: ITALIC, 4: UNDERLINE, 5: BLINK, 6: BLINK, 7: REVERSE, 8: CONCEAL,
       9: STRIKE, 53: OVERLINE}
_OFF = {22: BOLD | DIM, 23: ITALIC, 24: UNDERLINE, 25: BLINK, 27: REVERSE, 28: CONCEAL,
        29: STRIKE, 55: OVERLINE}
_ON_CODE = {BOLD: "1", DIM: "2", ITALIC: "3", UNDERLINE: "4", BLINK: "5", REVERSE: "7",
            CONCEAL: "8", STRIKE: "9", OVERLINE: "53"}
_OFF_CODE = {ITALIC: "23", UNDERLINE: "24", BLINK: "25", REVERSE: "27", CONCEAL: "28",
             STRIKE: "29", OVERLINE: "55"}
# Attributes that make a blank cell look different from an erased one.
_VISIBLE_ON_BLANK = UNDERLINE | REVERSE | STRIKE | OVERLINE | CONCEAL

DEFAULT: tuple = (None, None, None, 0)
_WIDE_TAIL = ""  # the second cell of a double-width character

_TOKEN = re.compile(
    r"(?P<csi>\x1b\[(?P<params>[0-?]*)(?P<inter>[ -/]*)(?P<final>[@-~]))"
    r"|(?P<str>\x1b[\]P_^X][^\x07\x1b]*(?:\x07|\x1b\\))"
    r"|(?P<esc2>\x1b[ -/]*[0-~])"
    r"|(?P<ctl>[\x00-\x1a\x1c-\x1f\x7f])"
    r"|(?P<text>[^\x00-\x1f\x7f]+)", re.S)

# The Linux console's fonts are code page 437: its printable half, and the pictures of its control
# codes. Other glyphs become one of these (same width), or "?".
CP437 = frozenset(bytes(range(32, 256)).decode("cp437") + "☺☻♥♦♣♠•◘○◙♂♀♪♫☼►◄↕‼¶§▬↨↑↓→←∟↔▲▼⌂")
_CONSOLE_FALLBACK = str.maketrans({
    "…": ">", "—": "-", "–": "-", "‒": "-", "‘": "'", "’": "'", "“": '"', "”": '"',
    "╭": "┌", "╮": "┐", "╰": "└", "╯": "┘", "━": "═", "┃": "║", "┏": "╔", "┓": "╗",
    "┗": "╚", "┛": "╝", "▁": " ", "▂": " ", "▃": "▄", "▅": "▄", "▆": "█", "▇": "█",
    "▉": "█", "▊": "█", "▋": "▌", "▍": "▌", "▎": " ", "▏": " ", "▔": "▀", "▕": "▐",
    "✓": "√", "✔": "√", "✗": "x", "✘": "x", "⚠": "!", "❯": ">", "›": ">", "‹": "<",
    "▶": "►", "◀": "◄", "⏵": "►", "⏴": "◄", "🔒": "#",
})


def console_glyphs(text: str) -> str:
    """*text* with every glyph the Linux console's font lacks replaced (width kept)."""
    text = text.translate(_CONSOLE_FALLBACK)
    if all(ch in CP437 for ch in text):
        return text
    return "".join(ch if ch in CP437 else ("??" if _width(ch) == 2 else "?") for ch in text)


_CONTENT_CHANGING = set("@JKLMPSTXbr")  # CSI finals that change cells we model (or scroll)
_SYNC_START, _SYNC_END = "\x1b[?2026h", "\x1b[?2026l"


def apply_sgr(state: tuple, params: str) -> tuple | None:
    """The SGR state after ``CSI params m`` from *state*; None when it is not understood."""
    fg, bg, ulc, bits = state
    codes = params.split(";") if params else ["0"]
    i = 0
    try:
        while i < len(codes):
            c = codes[i]
            if ":" in c:
                head, _, sub = c.partition(":")
                if head == "4" and sub in ("0", "1"):
                    bits = bits | UNDERLINE if sub == "1" else bits & ~UNDERLINE
                    i += 1
                    continue
                return None
            n = int(c) if c else 0
            if n == 0:
                fg = bg = ulc = None
                bits = 0
            elif n in _ON:
                bits |= _ON[n]
            elif n in _OFF:
                bits &= ~_OFF[n]
            elif 30 <= n <= 37 or 90 <= n <= 97:
                fg = str(n)
            elif 40 <= n <= 47 or 100 <= n <= 107:
                bg = str(n)
            elif n == 39:
                fg = None
            elif n == 49:
                bg = None
            elif n == 59:
                ulc = None
            elif n in (38, 48, 58):
                mode = codes[i + 1]
                if mode == "5":
                    value = f"{n};5;{int(codes[i + 2])}"
                    i += 2
                elif mode == "2":
                    r, g, b = (int(x) for x in codes[i + 2:i + 5])
                    value = f"{n};2;{r};{g};{b}"
                    i += 4
                else:
                    return None
                if n == 38:
                    fg = value
                elif n == 48:
                    bg = value
                else:
                    ulc = value
            else:
                return None
            i += 1
    except (ValueError, IndexError):
        return None
    return (fg, bg, ulc, bits)


def _codes(state: tuple) -> list[str]:
    fg, bg, ulc, bits = state
    out = [code for bit, code in _ON_CODE.items() if bits & bit]
    out += [c for c in (fg, bg, ulc) if c is not None]
    return out


def sgr_change(old: tuple | None, new: tuple) -> str:
    """The shortest SGR sequence that takes the terminal from *old* (None: unknown) to *new*."""
    if old == new:
        return ""
    full = "\x1b[" + ";".join(["0", *_codes(new)] if new != DEFAULT else []) + "m"
    if old is None:
        return full
    (ofg, obg, oulc, obits), (fg, bg, ulc, bits) = old, new
    codes: list[str] = []
    off = obits & ~bits
    if off & (BOLD | DIM):
        codes.append("22")
        obits &= ~(BOLD | DIM)
    codes += [code for bit, code in _OFF_CODE.items() if off & bit]
    codes += [code for bit, code in _ON_CODE.items() if bits & bit and not obits & bit]
    for o, n, default in ((ofg, fg, "39"), (obg, bg, "49"), (oulc, ulc, "59")):
        if o != n:
            codes.append(n if n is not None else default)
    inc = "\x1b[" + ";".join(codes) + "m"
    return inc if len(inc) < len(full) else full


def _width(ch: str) -> int:
    if " " <= ch <= "~":
        return 1
    if unicodedata.combining(ch):
        return 0
    # cell_len knows the common one-cell glyphs (box drawing, Latin-1...) without loading Rich's
    # table of every character's width, which takes 10-30 ms before the first frame.
    return cell_len(ch)


class FrugalScreen:
    """Rewrite a stream of terminal output so that only changed cells are sent."""

    def __init__(self, cols: int = 80, rows: int = 24, *, console: bool = False) -> None:
        self.cols, self.rows = cols, rows
        self.console = console  # the Linux console: only its font's glyphs are sent
        self._carry = ""
        self.sent = 0       # characters written out (after rewriting)
        self.received = 0   # characters Textual wrote
        self.invalidate()

    def invalidate(self, cols: int | None = None, rows: int | None = None) -> None:
        """Forget what the terminal shows: the next frame is sent whole."""
        if cols:
            self.cols = cols
        if rows:
            self.rows = rows
        self.grid: dict[tuple[int, int], tuple[str, tuple]] = {}
        self.vx = self.vy = 0               # where Textual's cursor is
        self.rx: int | None = None          # where the terminal's cursor is (None: unknown)
        self.ry: int | None = None
        self.pending: tuple | None = DEFAULT  # the attributes Textual has set
        self.real: tuple | None = None      # the terminal's attributes (None: unknown)
        self.cursor_shown = False
        self._sync_held = False

    def plain_attributes(self) -> str:
        """What takes the terminal back to plain attributes ("" when it has them already)."""
        out: list[str] = []
        self._sgr(out, DEFAULT)
        text = "".join(out)
        self.sent += len(text)
        return text

    # ------------------------------------------------------------------ feeding
    def feed(self, data: str) -> str:
        """Textual's output in, what the terminal needs out."""
        self.received += len(data)
        data = self._carry + data
        self._carry = ""
        pos = data.rfind("\x1b")
        if pos >= 0:  # a write may end inside an escape sequence: its tail waits for the next
            m = _TOKEN.match(data, pos)
            if m is None or (m.lastgroup == "esc2" and data[pos + 1:pos + 2] in "[]P_^X"):
                self._carry = data[pos:]
                data = data[:pos]
        out: list[str] = []
        for m in _TOKEN.finditer(data):
            kind = m.lastgroup
            if kind == "text":
                text = m.group("text")
                self._text(console_glyphs(text) if self.console and not text.isascii() else text,
                           out)
            elif kind == "csi":
                self._csi(m, out)
            elif kind == "ctl":
                self._control(m.group(), out)
            else:  # strings (OSC, DCS...) and two-byte escapes: passed through
                self._emit(out, m.group())
        if self.cursor_shown:
            self._move(out)
        text = "".join(out)
        self.sent += len(text)
        return text

    def _emit(self, out: list[str], s: str) -> None:
        if self._sync_held:
            out.append(_SYNC_START)
            self._sync_held = False
        out.append(s)

    # ------------------------------------------------------------------ sequences
    def _csi(self, m: re.Match, out: list[str]) -> None:
        params, inter, final = m.group("params"), m.group("inter"), m.group("final")
        seq = m.group()
        if final == "m" and not inter and not params.startswith((">", "?", "<", "=")):
            new = apply_sgr(self.pending or DEFAULT, params) if self.pending is not None else None
            if new is None:  # not understood: pass it on, forget the attributes
                self._emit(out, seq)
                self.pending = self.real = None
            else:
                self.pending = new
            return
        if final in "Hf" and not inter and not params.startswith("?"):
            parts = (params.split(";") + ["", ""])[:2]
            try:
                self.vy = max(0, int(parts[0] or 1) - 1)
                self.vx = max(0, int(parts[1] or 1) - 1)
                return
            except ValueError:
                pass
        if seq == _SYNC_START:
            self._sync_held = True  # sent with the first change; dropped if nothing changes
            return
        if seq == _SYNC_END:
            if self._sync_held:
                self._sync_held = False
            else:
                out.append(seq)
            return
        if seq in ("\x1b[?25h", "\x1b[?25l"):
            self.cursor_shown = seq.endswith("h")
            if self.cursor_shown:
                self._move(out)
        if seq in ("\x1b[?1049l", "\x1b[?1049h"):
            self._sgr(out, DEFAULT)  # never leave colours behind on the other screen
        if final in _CONTENT_CHANGING or seq.startswith(("\x1b[?1049", "\x1b[?47", "\x1b[?1047")):
            self._move(out)
            self._sgr(out, self.pending)
            self._emit(out, seq)
            keep = (self.vx, self.vy, self.pending, self.real, self.cursor_shown)
            self.invalidate()
            self.vx, self.vy, self.pending, self.real, self.cursor_shown = keep
            return
        self._emit(out, seq)

    def _control(self, ch: str, out: list[str]) -> None:
        if ch == "\r":
            self.vx = 0
        elif ch == "\n":  # Textual's line feeds between lines: the tty adds the CR
            self.vx, self.vy = 0, self.vy + 1
        else:
            self._emit(out, ch)
            self.rx = self.ry = None

    # ------------------------------------------------------------------ cells
    def _sgr(self, out: list[str], state: tuple | None) -> None:
        if state is None:
            return
        change = sgr_change(self.real, state)
        if change:
            self._emit(out, change)
            self.real = state

    def _move(self, out: list[str]) -> None:
        """Put the terminal's cursor where Textual's is, in the fewest bytes."""
        vx, vy, rx, ry = self.vx, self.vy, self.rx, self.ry
        if rx == vx and ry == vy:
            return
        seq = None
        if ry == vy and rx is not None:
            d = vx - rx
            if 0 < d <= 3:
                cells = [self.grid.get((x, vy)) for x in range(rx, vx)]
                if all(c is not None and c[1] == self.real and c[0] != _WIDE_TAIL
                       and _width(c[0][:1] or " ") == 1 for c in cells):
                    seq = "".join(c[0] for c in cells)  # type: ignore[index]
            if seq is None:
                if d > 0:
                    seq = "\x1b[C" if d == 1 else f"\x1b[{d}C"
                elif vx == 0:
                    seq = "\r"
                else:
                    seq = "\x1b[D" if d == -1 else f"\x1b[{-d}D"
        elif vx == 0 and ry is not None and vy == ry + 1:
            seq = "\r\n"
        elif vx == 0:
            seq = f"\x1b[{vy + 1}H" if vy else "\x1b[H"
        else:
            seq = f"\x1b[{vy + 1};{vx + 1}H"
        self._emit(out, seq)
        self.rx, self.ry = vx, vy

    def _text(self, text: str, out: list[str]) -> None:
        grid, state = self.grid, self.pending
        i, n = 0, len(text)
        while i < n:
            ch = text[i]
            w = _width(ch)
            x, y = self.vx, self.vy
            if w == 0:  # a combining mark joins the cell before
                prev = grid.get((x - 1, y))
                if prev is not None:
                    grid[(x - 1, y)] = (prev[0] + ch, prev[1])
                self._move(out)
                self._emit(out, ch)
                i += 1
                continue
            if state is None:  # attributes unknown: write through, remember nothing
                self._move(out)
                self._emit(out, ch)
                grid.pop((x, y), None)
                self._advance(w)
                i += 1
                continue
            cell = (ch, state)
            if grid.get((x, y)) == cell and (w == 1 or grid.get((x + 1, y)) == (_WIDE_TAIL, state)):
                self.vx += w
                i += 1
                continue
            if ch == " " and not state[3] & _VISIBLE_ON_BLANK and state[1] is None:
                run = len(text) - i - len(text[i:].lstrip(" "))
                if run >= 6:
                    self._erase(out, run, state)
                    i += run
                    continue
            self._move(out)
            self._sgr(out, state)
            self._emit(out, ch)
            self._forget_halves(x, y, w)
            grid[(x, y)] = cell
            if w == 2:
                grid[(x + 1, y)] = (_WIDE_TAIL, state)
            self._advance(w)
            i += 1

    def _erase(self, out: list[str], run: int, state: tuple) -> None:
        """A run of blanks: erase the cells that differ (one ECH) instead of writing spaces."""
        x0, y = self.vx, self.vy
        end = min(x0 + run, self.cols)
        blank = (" ", state)
        todo = [x for x in range(x0, end) if self.grid.get((x, y)) != blank]
        if todo:
            first, last = todo[0], todo[-1]
            self.vx = first
            self._move(out)
            self._sgr(out, state)
            count = last - first + 1
            if last == self.cols - 1:
                self._emit(out, "\x1b[K")
            else:
                self._emit(out, "\x1b[X" if count == 1 else f"\x1b[{count}X")
            for x in range(first, last + 1):
                self._forget_halves(x, y, 1)
                self.grid[(x, y)] = blank
        self.vx = x0 + run

    def _forget_halves(self, x: int, y: int, w: int) -> None:
        """Overwriting half of a double-width character breaks the other half."""
        grid = self.grid
        if grid.get((x, y), ("",))[0] == _WIDE_TAIL and (x, y) in grid:
            grid.pop((x - 1, y), None)
        nxt = grid.get((x + w, y))
        if nxt is not None and nxt[0] == _WIDE_TAIL:
            grid.pop((x + w, y), None)

    def _advance(self, w: int) -> None:
        self.vx += w
        if self.vx >= self.cols:  # at the margin the terminal's cursor position is ambiguous
            self.rx = self.ry = None
        else:
            self.rx, self.ry = self.vx, self.vy


def frugal_driver_class():
    """Textual's Linux driver, writing through a :class:`FrugalScreen` (imported on demand)."""
    import os

    from textual import events
    from textual.drivers.linux_driver import LinuxDriver

    from rosnet_tui.ui import textual_compat as tc
    from rosnet_tui.ui.keys import escape_first_parser

    # The driver builds its parser when its input thread starts.
    tc.use_input_parser(escape_first_parser())

    class FrugalDriver(tc.DriverHooks, LinuxDriver):
        def __init__(self, *args, **kwargs) -> None:
            super().__init__(*args, **kwargs)
            term = os.environ.get("TERM", "")
            self.frugal = FrugalScreen(console=term == "linux" or term.startswith("linux-"))

        def _tty_size(self) -> tuple[int, int]:
            try:
                size = os.get_terminal_size(tc.driver_fileno(self))
                return size.columns, size.lines
            except OSError:
                return self.frugal.cols, self.frugal.rows

        def forget_screen(self) -> None:
            self._forget = True

        def plain_attributes(self) -> None:
            """Leave the terminal on plain attributes (after the first frame, whose last cells
            may be a coloured scrollbar: the next screen then starts from plain text)."""
            data = self.frugal.plain_attributes()
            if data:
                super().write(data)
                self.flush()

        def write(self, data: str) -> None:
            if getattr(self, "_forget", False):
                self._forget = False
                self.frugal.invalidate(*self._tty_size())
            data = self.frugal.feed(data)
            if data:
                super().write(data)

        def start_application_mode(self) -> None:
            self.frugal.invalidate(*self._tty_size())
            super().start_application_mode()

        def size_asked(self) -> None:
            self._forget = True  # asked on every SIGWINCH: the terminal may have redrawn

        def process_message(self, message) -> None:
            if isinstance(message, events.Resize):  # in-band resize reports
                self._forget = True
            super().process_message(message)

        def enable_mouse(self, wanted: bool) -> None:
            if wanted:  # clicks (SGR coordinates), no motion reports
                self.write("\x1b[?1000h\x1b[?1006h")
                self.flush()

    return FrugalDriver
