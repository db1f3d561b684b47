"""Reusable widgets: the step bar and the live check list of the Verification pane."""

from __future__ import annotations

from dataclasses import dataclass

from rich.text import Text
from textual import events
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Vertical
from textual.message import Message
from textual.reactive import reactive
from textual.widget import Widget
from textual.widgets import DataTable, Input, Static

from rosnet_tui.core.results import CheckResult
from rosnet_tui.core.session import NOT_RUN, RUNNING, aggregate  # noqa: F401 (re-exported)
from rosnet_tui.core.steps import STEPS

# The state words of a check (the four result statuses plus the session's "not run"/"running").
STATE_STYLE = {
    "pass": "$success",
    "warn": "$warning",
    "fail": "$error",
    "skip": "$text-muted",
    RUNNING: "$accent",
    NOT_RUN: "$text-muted",
}
STATE_LABEL = {"pass": "PASS", "warn": "WARN", "fail": "FAIL", "skip": "SKIP",
               RUNNING: " .. ", NOT_RUN: "  - "}


STEP_MARK = {"pass": "ok", "warn": "!", "fail": "x", "skip": "-", RUNNING: "..",
             NOT_RUN: "", "partial": "~"}


class StepBar(Widget):
    """One line: the four steps, where you are, and each step's state."""

    DEFAULT_CSS = """
    StepBar { height: 1; layout: horizontal; background: $panel; }
    StepBar > .step-item { width: auto; padding: 0 1 0 0; color: $text-muted; }
    StepBar > .step-item.-current { background: $primary; color: $text; text-style: bold; }
    StepBar > .step-item.-fail { color: $error; }
    StepBar > .step-item.-warn { color: $warning; }
    StepBar > .step-item.-pass { color: $success; }
    StepBar > .step-item.-current.-fail, StepBar > .step-item.-current.-warn,
    StepBar > .step-item.-current.-pass { color: $text; }
    """

    current: reactive[str] = reactive("isp")

    class Selected(Message):
        def __init__(self, step_id: str) -> None:
            self.step_id = step_id
            super().__init__()

    def __init__(self, current: str = "isp", **kwargs) -> None:
        super().__init__(**kwargs)
        self._states: dict[str, str] = {s.id: NOT_RUN for s in STEPS}
        self.set_reactive(StepBar.current, current)

    def compose(self) -> ComposeResult:
        for s in STEPS:
            yield Static(self._label(s.id), id=f"step-item-{s.id}", classes="step-item",
                         markup=False)

    def on_mount(self) -> None:
        self._refresh_items()

    def _label(self, step_id: str) -> str:
        step = next(s for s in STEPS if s.id == step_id)
        mark = STEP_MARK.get(self._states[step_id], "")
        here = ">" if step_id == self.current else " "  # readable without colour too
        return f"{here}{step.number} {step.title}" + (f" [{mark}]" if mark else "")

    def set_state(self, step_id: str, state: str) -> None:
        if self._states.get(step_id) != state:
            self._states[step_id] = state
            if self.is_mounted:
                self._refresh_items()

    def watch_current(self) -> None:
        if self.is_mounted:
            self._refresh_items()

    def _refresh_items(self) -> None:
        for s in STEPS:
            item = self.query_one(f"#step-item-{s.id}", Static)
            item.update(self._label(s.id))
            item.set_class(s.id == self.current, "-current")
            for st in ("fail", "warn", "pass"):
                item.set_class(self._states[s.id] == st, f"-{st}")

    def on_click(self, event: events.Click) -> None:
        widget = event.widget
        if widget is not None and widget.id and widget.id.startswith("step-item-"):
            self.post_message(self.Selected(widget.id.removeprefix("step-item-")))


class OrderedInput(Input):
    """An Input whose editing keys (backspace, arrows...) keep their place among typed characters.

    Textual runs an Input's bound keys as actions after the event has travelled, while typed
    characters are inserted at once, so in a burst of input (a mobile SSH link delivers keys in
    bursts) "abc<backspace>d" can come out as "abd" missing the wrong letter. Running the
    widget's own bindings in line keeps the order (Textual issue 6605).
    """

    async def _on_key(self, event: events.Key) -> None:
        if not event.is_printable:
            for binding in self._merged_bindings.key_to_bindings.get(event.key, []):
                if not binding.priority:
                    event.stop()
                    event.prevent_default()
                    await self.run_action(binding.action)
                    return
        await super()._on_key(event)


class RowTable(DataTable):
    """A row-cursor table where Home and End go to the first and last row, as expected."""

    BINDINGS = [Binding("home", "scroll_top", "First", show=False),
                Binding("end", "scroll_bottom", "Last", show=False)]


@dataclass
class CheckRow:
    id: str
    title: str
    state: str = NOT_RUN
    result: CheckResult | None = None


class CheckList(Vertical):
    """The Verification pane's body: one row per check, and the evidence of the highlighted one."""

    DEFAULT_CSS = """
    CheckList { height: 1fr; }
    CheckList > DataTable { height: 1fr; min-height: 3; }
    CheckList > #evidence { height: auto; max-height: 8; padding: 0 1;
                            border-top: solid $primary-darken-2; display: none; }
    CheckList.-evidence > #evidence { display: block; }
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

    def compose(self) -> ComposeResult:
        table: DataTable = RowTable(cursor_type="row", zebra_stripes=False, id="check-table")
        yield table
        yield Static("", id="evidence", markup=False)

    def on_mount(self) -> None:
        table = self.query_one(DataTable)
        table.add_column("", key="state", width=4)
        table.add_column("Check", key="title")
        table.add_column("Result", key="summary")
        for row in self.rows.values():
            table.add_row(*self._cells(row), key=row.id)
        self._fit_columns()

    def on_resize(self) -> None:
        self._fit_columns()

    def _fit_columns(self) -> None:
        """Status and title keep their width; the result column takes the rest of the pane."""
        table = self.query_one(DataTable)
        if not table.columns or self.size.width <= 0:
            return
        title_w = max([len("Check")] + [len(r.title) for r in self.rows.values()])
        title_w = min(title_w, max(12, self.size.width // 3))
        pad = 2 * table.cell_padding * 3 + 1
        rest = max(10, self.size.width - 4 - title_w - pad)
        for key, width in (("state", 4), ("title", title_w), ("summary", rest)):
            col = table.columns[key]  # type: ignore[index]
            col.auto_width = False
            col.width = width
        table.refresh()

    def _state_text(self, state: str) -> Text:
        colour = self.app.get_css_variables().get(STATE_STYLE[state].lstrip("$"), "")
        style = f"bold {colour}".strip() if state in ("pass", "warn", "fail") else colour
        return Text(STATE_LABEL[state], style=style)

    def _cells(self, row: CheckRow) -> tuple[Text, str, str]:
        if row.state == RUNNING:
            summary = "checking..."
        elif row.result is not None:
            summary = row.result.summary
        else:
            summary = "not run yet: press r"
        return self._state_text(row.state), row.title, summary

    def set_state(self, check_id: str, state: str, result: CheckResult | None = None) -> None:
        row = self.rows.get(check_id)
        if row is None:
            return
        row.state = state
        if result is not None or state in (NOT_RUN, RUNNING):
            row.result = result
        table = self.query_one(DataTable)
        for key, value in zip(("state", "title", "summary"), self._cells(row), strict=True):
            table.update_cell(check_id, key, value)
        if self.highlighted_id == check_id:
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

    def _show_evidence(self) -> None:
        cid = self.highlighted_id
        row = self.rows.get(cid) if cid else None
        text = ""
        if row is not None:
            if row.result is None:
                text = f"{row.title} ({row.id}): {row.state}"
            else:
                r = row.result
                lines = [f"{r.status.label}  {row.id}  ({r.duration_s:.2f} s of {r.timeout_s:g} s)",
                         r.summary]
                lines += [f"  {e}" for e in r.evidence]
                if r.status.value in ("fail", "warn"):
                    for n, f in enumerate(self.advice(row.id)[:3], 1):
                        lines.append(f"Advice {n}: {f.meaning}")
                        lines += [f"  - {a}" for a in f.actions]
                        if f.goto_step:
                            lines.append(f"  (go back to the {f.goto_step} step: press g)")
                text = "\n".join(lines)
        self.query_one("#evidence", Static).update(text)

    def on_data_table_row_highlighted(self, event: DataTable.RowHighlighted) -> None:
        event.stop()
        self._show_evidence()

    def on_data_table_row_selected(self, event: DataTable.RowSelected) -> None:
        event.stop()
        self.toggle_evidence()
