"""Reusable widgets: the step bar and the live check list of the Verification pane."""

from __future__ import annotations

from dataclasses import dataclass

from rich.text import Text
from textual import events
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Vertical, VerticalScroll
from textual.message import Message
from textual.reactive import reactive
from textual.widget import Widget
from textual.widgets import DataTable, Static

from rosnet_tui.core.results import CheckResult
from rosnet_tui.core.wizard.session import NOT_RUN, RUNNING
from rosnet_tui.core.wizard.steps import STEPS
from rosnet_tui.ui.theme import cut

# The state words of a check (the four result statuses plus the session's "not run"/"running"),
# in the terminal's own colours (the words read without colour too).
STATE_COLOUR = {"pass": "green", "warn": "yellow", "fail": "red", RUNNING: "cyan"}
STATE_LABEL = {"pass": "PASS", "warn": "WARN", "fail": "FAIL", "skip": "SKIP",
               RUNNING: " .. ", NOT_RUN: "  - "}


STEP_MARK = {"pass": "ok", "warn": "!", "fail": "x", "skip": "-", RUNNING: "..",
             NOT_RUN: "", "partial": "~"}


class Line(Widget):
    """One line of text, redrawn only when it changes and never relaid out (its size is fixed):
    a bar that updates on every focus change should cost nothing when it says the same."""

    DEFAULT_CSS = """
    Line { height: 1; width: 1fr; }
    """

    def __init__(self, **kwargs) -> None:
        super().__init__(**kwargs)
        self._line = Text()

    def show(self, text: Text) -> None:
        if text.plain != self._line.plain or text.spans != self._line.spans:
            self._line = text
            self.refresh()

    def render(self) -> Text:
        return self._line


class StepBar(Line):
    """One line: the four steps, where you are (reverse video and '>'), and each step's state
    in words ([ok], [x]...), so it reads without colour. One widget, redrawn as one line."""

    current: reactive[str] = reactive("isp")

    class Selected(Message):
        def __init__(self, step_id: str) -> None:
            self.step_id = step_id
            super().__init__()

    def __init__(self, current: str = "isp", **kwargs) -> None:
        super().__init__(**kwargs)
        self._states: dict[str, str] = {s.id: NOT_RUN for s in STEPS}
        self._spans: list[tuple[int, int, str]] = []
        self.set_reactive(StepBar.current, current)

    def on_mount(self) -> None:
        self._redraw()

    def _label(self, step_id: str) -> str:
        step = next(s for s in STEPS if s.id == step_id)
        mark = STEP_MARK.get(self._states[step_id], "")
        here = ">" if step_id == self.current else " "  # readable without colour too
        return f"{here}{step.number} {step.title}" + (f" [{mark}]" if mark else "")

    def set_state(self, step_id: str, state: str) -> None:
        if self._states.get(step_id) != state:
            self._states[step_id] = state
            if self.is_mounted:
                self._redraw()

    def watch_current(self) -> None:
        if self.is_mounted:
            self._redraw()

    def _redraw(self) -> None:
        text = Text(no_wrap=True, overflow="ellipsis")
        self._spans = []
        for s in STEPS:
            start = len(text)
            state = self._states[s.id]
            style = "bold reverse" if s.id == self.current else STATE_COLOUR.get(state, "")
            # The separating blank inside the span: some SVG viewers drop a span's leading blank.
            text.append(self._label(s.id) + " ", style=style)
            self._spans.append((start, len(text), s.id))
        self.show(text)

    def on_click(self, event: events.Click) -> None:
        for start, end, step_id in self._spans:
            if start <= event.x < end:
                self.post_message(self.Selected(step_id))
                return


class KeyBar(Line):
    """The keys of the screen on one line (Textual's Footer is a widget per key, rebuilt at
    every focus change: more work and more bytes for the same line)."""

    DEFAULT_CSS = """
    KeyBar { dock: bottom; }
    """

    def on_mount(self) -> None:
        self.screen.bindings_updated_signal.subscribe(self, self._bindings_changed)
        self._bindings_changed(self.screen)

    def on_unmount(self) -> None:
        self.screen.bindings_updated_signal.unsubscribe(self)

    def _bindings_changed(self, screen) -> None:
        if not self.is_attached or screen is not self.screen:
            return
        text = Text(no_wrap=True, overflow="ellipsis")
        seen: set[str] = set()
        for _node, binding, enabled, _tooltip in screen.active_bindings.values():
            if not binding.show or not enabled or binding.action in seen:
                continue
            seen.add(binding.action)
            text.append(self.app.get_key_display(binding) + " ", style="bold cyan")
            text.append(f"{binding.description} ")
        self.show(text)


class PlainHeader(Line):
    """The top line: the program and the screen's subject, drawn as one plain line (Textual's
    Header draws more than it says, and with glyphs the Linux console lacks)."""

    DEFAULT_CSS = """
    PlainHeader { text-style: bold; padding: 0 1; dock: top; }
    """

    def on_mount(self) -> None:
        self.watch(self.screen, "title", self._retitle)
        self.watch(self.screen, "sub_title", self._retitle)

    def _retitle(self, _value: str = "") -> None:
        parts = [p for p in (self.screen.title, self.screen.sub_title) if p]
        self.show(Text(" · ".join(parts)))


class RowTable(DataTable):
    """A row-cursor table where Home and End go to the first and last row, as expected."""

    BINDINGS = [Binding("home", "scroll_top", "First", show=False),
                Binding("end", "scroll_bottom", "Last", show=False)]


# Labels that fit the check table at 80 columns; the full title is in the evidence.
SHORT_TITLES = {
    "isp.internet": "Internet (DNS, HTTP)",
    "isp.public_ip": "Public IP",
    "isp.cgnat": "No CGNAT / double NAT",
    "router.local_ip": "Local IP forwarded to",
    "router.port_free": "Test port free",
    "router.listener": "Our listener up",
    "router.port_open": "Ports open from outside",
    "router.upnp": "Modem forwards (UPnP)",
    "linux.hosts": "Hosts file entries",
    "linux.resolve": "Names resolve",
    "linux.ping": "Ping by name",
    "linux.ssh": "SSH by name",
    "linux.chat_out": "Chat out (we connect)",
    "linux.chat_in": "Chat in (peer connects)",
    "linux.firewall": "Only peers get in",
    "ros.env": "ROS environment",
    "ros.master": "ROS master answers",
    "ros.node_uris": "Node addresses reachable",
    "ros.pubsub_out": "Publish here, peer hears",
    "ros.pubsub_in": "Peer publishes, we hear",
    "ros2.env": "ROS 2 environment",
    "ros2.router": "Master's Zenoh router",
    "ros2.graph": "Every node seen",
    "ros2.pubsub_out": "Publish here, peer hears",
    "ros2.pubsub_in": "Peer publishes, we hear",
    "ros2.link": "The link measured",
    "ros.link": "The link measured",
    "ros.rosbridge": "Browser path (rosbridge)",
    "security.ssh_auth": "SSH offers no password",
    "relay.router": "The relay's Zenoh router",
    "relay.tunnel": "Our tunnel on the relay",
    "security.outsider": "Outsider refused",
}
TITLE_MAX = 24


def short_title(check_id: str, title: str) -> str:
    return SHORT_TITLES.get(check_id) or cut(title, TITLE_MAX)


@dataclass
class CheckRow:
    id: str
    title: str
    state: str = NOT_RUN
    result: CheckResult | None = None
    at: str = ""          # when the result came, if from an earlier session (shown as such)

    @property
    def label(self) -> str:
        return short_title(self.id, self.title)


class CheckList(Vertical):
    """The Verification pane's body: one row per check, and the evidence of the highlighted one."""

    DEFAULT_CSS = """
    CheckList { height: 1fr; }
    CheckList > DataTable { height: 1fr; min-height: 3; overflow-x: hidden;
                            scrollbar-size-vertical: 1; }
    CheckList.-evidence > DataTable { height: auto; max-height: 50%; }
    CheckList > #evidence-box { height: 1fr; padding: 0 1; display: none;
                                border-top: solid $primary; scrollbar-size-vertical: 1; }
    CheckList > #evidence-box:focus { border-top: double $accent; }
    CheckList.-evidence > #evidence-box { display: block; }
    """

    class EvidenceToggled(Message):
        def __init__(self, shown: bool) -> None:
            self.shown = shown
            super().__init__()

    def __init__(self, rows: list[tuple[str, str]], advice=None, **kwargs) -> None:
        super().__init__(**kwargs)
        self.rows: dict[str, CheckRow] = {cid: CheckRow(cid, title) for cid, title in rows}
        # check id -> list of advisor findings (objects with meaning, actions, goto_step)
        self.advice = advice or (lambda check_id: [])
        self._widths = (4, TITLE_MAX, 40)
        self._evidence: Static | None = None

    def compose(self) -> ComposeResult:
        # The evidence box is hidden until asked for: it is mounted then (_evidence_text), which
        # keeps two widgets and their scrollbars out of the first frame.
        yield RowTable(cursor_type="row", zebra_stripes=False, id="check-table")

    def _evidence_text(self) -> Static:
        """The evidence's text, in its scrolling box (mounted on first use)."""
        if self._evidence is None:
            box = VerticalScroll(id="evidence-box", classes="zoomable")
            box.can_focus = True
            self.mount(box)
            self._evidence = Static("", id="evidence", markup=False)
            box.mount(self._evidence)
        return self._evidence

    def on_mount(self) -> None:
        table = self.query_one(DataTable)
        self._fit_widths()
        for key, label, width in zip(("state", "title", "summary"), ("", "Check", "Result"),
                                     self._widths, strict=True):
            table.add_column(Text(label), key=key, width=width)  # Text: never read as markup
        for row in self.rows.values():
            table.add_row(*self._cells(row), key=row.id)

    def on_resize(self) -> None:
        if self._fit_widths():
            table = self.query_one(DataTable)
            for key, width in zip(("state", "title", "summary"), self._widths, strict=True):
                col = table.columns[key]  # type: ignore[index]
                col.auto_width = False
                col.width = width
            for row in self.rows.values():
                self._update_row(row)
            table.refresh()

    def _expected_width(self) -> int:
        """The pane's width before the first layout (so the first frame is the right one): the
        screen less the pane's padding, or half of it less a frame when side by side."""
        width = self.app.size.width or 80
        return width // 2 - 4 if self.app.has_class("wide") else width - 2

    def set_titles(self, rows: list[tuple[str, str]]) -> None:
        """The checks got loaded: their full titles, and rows for checks not listed yet."""
        table = self.query_one(DataTable)
        for cid, title in rows:
            row = self.rows.get(cid)
            if row is None:
                row = self.rows[cid] = CheckRow(cid, title)
                table.add_row(*self._cells(row), key=cid)
            elif row.title != title:
                row.title = title

    def _fit_widths(self) -> bool:
        """Status and title keep their width; the result column takes the rest, so the table is
        never wider than the pane (no horizontal scrollbar). True when the widths changed."""
        width = self.size.width or self._expected_width()
        title_w = max([len("Check")] + [len(r.label) for r in self.rows.values()])
        title_w = min(title_w, max(12, (width - 9) // 2))
        # Each column has a cell of padding on both sides; one column is kept for a scrollbar.
        rest = max(8, width - 1 - (4 + 2) - (title_w + 2) - 2)
        widths = (4, title_w, rest)
        changed = widths != self._widths
        self._widths = widths
        return changed

    def _state_text(self, state: str) -> Text:
        colour = STATE_COLOUR.get(state, "")
        style = f"bold {colour}".strip() if state in ("pass", "warn", "fail") else colour
        return Text(STATE_LABEL[state], style=style)

    def _cells(self, row: CheckRow) -> tuple[Text, Text, Text]:
        if row.state == RUNNING:
            summary = "checking..."
        elif row.result is not None:
            summary = row.result.summary
        else:
            summary = "not run yet: press r"
        _s, title_w, rest = self._widths
        # Text, not str: a result such as "[x] refused" is shown as it is, not read as markup.
        return self._state_text(row.state), Text(cut(row.label, title_w)), Text(cut(summary, rest))

    def _update_row(self, row: CheckRow) -> None:
        table = self.query_one(DataTable)
        for key, value in zip(("state", "title", "summary"), self._cells(row), strict=True):
            table.update_cell(row.id, key, value)

    def set_state(self, check_id: str, state: str, result: CheckResult | None = None,
                  at: str = "") -> None:
        row = self.rows.get(check_id)
        if row is None:
            return
        row.state = state
        row.at = at
        if result is not None or state in (NOT_RUN, RUNNING):
            row.result = result
        self._update_row(row)
        if self.highlighted_id == check_id and self.has_class("-evidence"):
            self._show_evidence()

    @property
    def highlighted_id(self) -> str | None:
        table = self.query_one(DataTable)
        if not self.rows or table.cursor_row is None or table.cursor_row < 0:
            return None
        try:
            return list(self.rows)[table.cursor_row]
        except IndexError:
            return None

    def toggle_evidence(self) -> None:
        self.toggle_class("-evidence")
        self._show_evidence()
        self.post_message(self.EvidenceToggled(self.has_class("-evidence")))

    def evidence_text(self, check_id: str | None) -> str:
        row = self.rows.get(check_id) if check_id else None
        if row is None:
            return ""
        lines = [f"{row.title} ({row.id})"]
        if row.result is None:
            lines.append("running now" if row.state == RUNNING else "not run yet: press r")
            return "\n".join(lines)
        r = row.result
        lines.append(f"{r.status.label} in {r.duration_s:.2f} s of {r.timeout_s:g} s"
                     + (f", {row.at} (an earlier session; r runs it again)" if row.at else ""))
        lines.append(r.summary)
        lines += [f"  {e}" for e in r.evidence]
        if r.status.value in ("fail", "warn"):
            for n, f in enumerate(self.advice(row.id)[:3], 1):
                lines.append(f"Advice {n}: {f.meaning}")
                lines += [f"  - {a}" for a in f.actions]
                if f.goto_step:
                    lines.append(f"  (go back to the {f.goto_step} step: press g)")
        return "\n".join(lines)

    def refresh_evidence(self) -> None:
        if self.has_class("-evidence"):
            self._show_evidence()

    def _show_evidence(self) -> None:
        self._evidence_text().update(self.evidence_text(self.highlighted_id))

    def on_data_table_row_highlighted(self, event: DataTable.RowHighlighted) -> None:
        event.stop()
        if self.has_class("-evidence"):
            self._show_evidence()

    def on_data_table_row_selected(self, event: DataTable.RowSelected) -> None:
        event.stop()
        self.toggle_evidence()
