"""The advisor, Table-1 style: condition | meaning | action, the rows that apply marked.

Two views of one table: the findings for the current results (with this network's names, addresses
and ports filled in), and every rule (the troubleshooting reference), the matching ones marked.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, cast

from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Vertical
from textual.screen import Screen
from textual.widgets import DataTable, Footer, Header, Static

from rosnet_tui.core.advisor import Finding, all_rules, step_title
from rosnet_tui.core.steps import STEP_BY_ID
from rosnet_tui.ui.widgets import RowTable

if TYPE_CHECKING:
    from rosnet_tui.ui.app import RosnetApp

SEVERITY_WORD = {"fail": "FAIL", "warn": "WARN", "security": "SEC", "info": "INFO"}


def _short_step(step_id: str | None) -> str:
    step = STEP_BY_ID.get(step_id or "")
    return f"{step.number} {step.title.split('/')[0]}" if step else ""


class AdvisorScreen(Screen[str | None]):
    BINDINGS = [
        Binding("escape", "close", "Back"),
        Binding("t", "toggle_view", "All rules / findings"),
        Binding("g", "go", "Go to its step"),
    ]

    def __init__(self, **kwargs) -> None:
        super().__init__(**kwargs)
        self.show_all = False
        self._rows: list[tuple[str, str, str, str, str | None, bool, str]] = []

    @property
    def rosnet(self) -> RosnetApp:
        return cast("RosnetApp", self.app)

    def compose(self) -> ComposeResult:
        yield Header(show_clock=False, icon="")
        with Vertical(id="advisor-body"):
            yield Static("", id="advisor-caption")
            yield RowTable(cursor_type="row", id="advisor-table")
            yield Static("", id="advisor-detail", markup=False)
        yield Footer()

    def on_mount(self) -> None:
        self.title = "rosnet-tui"
        self.sub_title = "advisor"
        table = self.query_one(DataTable)
        table.add_column("", key="mark", width=4)
        table.add_column("Condition", key="condition")
        table.add_column("Go to", key="step", width=9)
        self.refresh_rows()
        table.focus()

    def on_screen_resume(self) -> None:
        self.refresh_rows()

    def refresh_rows(self) -> None:
        findings: list[Finding] = self.rosnet.findings
        fired = {f.rule for f in findings}
        self._rows = []
        if self.show_all:
            for r in all_rules():
                self._rows.append((r.id, SEVERITY_WORD.get(r.severity, r.severity), r.condition,
                                   r.meaning, r.goto_step, r.id in fired, r.action))
            caption = (f"All {len(self._rows)} rules; '>>' marks the {len(fired)} that apply "
                       "now. t: back to the findings.")
        else:
            for f in findings:
                self._rows.append((f.rule, SEVERITY_WORD.get(f.severity, f.severity),
                                   f.condition or f.rule, f.meaning, f.goto_step, True,
                                   "\n".join(f"- {a}" for a in f.actions)))
            caption = ("No findings: run the checks of a step first (r)." if not findings else
                       f"{len(findings)} finding(s) for the latest results, most important "
                       "first. t: every rule.")
        self.query_one("#advisor-caption", Static).update(caption)
        table = self.query_one(DataTable)
        table.clear()
        for i, (rid, sev, cond, _meaning, goto, hit, _action) in enumerate(self._rows):
            mark = Text(">>" if (hit and self.show_all) else sev,
                        style="bold" if hit else "")
            step = _short_step(goto)
            table.add_row(mark, cond, step, key=f"{i}-{rid}")
        self._fit()
        self._show_detail()

    def _fit(self) -> None:
        table = self.query_one(DataTable)
        width = self.size.width or 80
        col = table.columns.get("condition")  # type: ignore[call-overload]
        if col is not None:
            col.auto_width = False
            col.width = max(20, width - 4 - 9 - 10)
        table.refresh()

    def on_resize(self) -> None:
        self._fit()

    def _current(self):
        table = self.query_one(DataTable)
        if not self._rows or table.cursor_row is None or not 0 <= table.cursor_row < len(self._rows):
            return None
        return self._rows[table.cursor_row]

    def _show_detail(self) -> None:
        row = self._current()
        text = ""
        if row is not None:
            rid, sev, cond, meaning, goto, _hit, action = row
            where = f"Go back to {step_title(goto)} (press g)." if goto else ""
            text = (f"{cond}  [{rid}]\nWhat it means: {meaning}\nWhat to do:\n{action}\n{where}")
        self.query_one("#advisor-detail", Static).update(text)

    def on_data_table_row_highlighted(self, event: DataTable.RowHighlighted) -> None:
        self._show_detail()

    def on_data_table_row_selected(self, event: DataTable.RowSelected) -> None:
        self.action_go()

    def action_toggle_view(self) -> None:
        self.show_all = not self.show_all
        self.refresh_rows()

    def action_go(self) -> None:
        row = self._current()
        if row is None or not row[4]:
            self.notify("This finding points to no particular step.", timeout=3)
            return
        self.dismiss(row[4])

    def action_close(self) -> None:
        self.dismiss(None)
