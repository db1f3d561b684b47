"""The advisor, Table-1 style: condition | meaning | action, the rows that apply marked.

Two views of one table: the findings for the current results (with this network's names, addresses
and ports filled in), and every rule (the troubleshooting reference), the matching ones marked.
"""

from __future__ import annotations

from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Vertical, VerticalScroll
from textual.screen import Screen
from textual.widgets import DataTable, Static

from rosnet_tui.core.advisor import Finding, all_rules
from rosnet_tui.core.procedure import SEVERITY_WORDS as SEVERITY_WORD
from rosnet_tui.core.procedure import step_title
from rosnet_tui.core.wizard.session import WizardSession
from rosnet_tui.core.wizard.steps import STEP_BY_ID
from rosnet_tui.ui.theme import cut
from rosnet_tui.ui.widgets import KeyBar, PlainHeader, RowTable


def _short_step(step_id: str | None) -> str:
    step = STEP_BY_ID.get(step_id or "")
    return f"{step.number} {step.title.split('/')[0]}" if step else ""


class AdvisorScreen(Screen[str | None]):
    BINDINGS = [
        Binding("escape,q,f10", "close", "Back", key_display="Esc/q"),
        Binding("t", "toggle_view", "All rules / findings"),
        Binding("g", "go", "Go to its step"),
        Binding("z", "zoom", "Zoom", show=False),
    ]

    def __init__(self, session: WizardSession, **kwargs) -> None:
        super().__init__(**kwargs)
        self.session = session
        self.show_all = False
        self._rows: list[tuple[str, str, str, str, str | None, bool, str]] = []

    def compose(self) -> ComposeResult:
        yield PlainHeader()
        with Vertical(id="advisor-body"):
            yield Static("", id="advisor-caption")
            yield RowTable(cursor_type="row", id="advisor-table")
            with VerticalScroll(id="advisor-detail-box", classes="zoomable") as box:
                box.can_focus = True  # Tab reaches it; the arrows scroll the whole advice
                yield Static("", id="advisor-detail", markup=False)
        yield KeyBar()

    def on_mount(self) -> None:
        self.title = "rosnet-tui"
        self.sub_title = "advisor"
        self.refresh_rows()
        self.query_one(DataTable).focus()

    def on_screen_resume(self) -> None:
        self.refresh_rows()

    def refresh_rows(self) -> None:
        findings: list[Finding] = self.session.findings
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
        table.clear(columns=True)
        wide = self._wide()
        # Table 1's columns: condition | meaning | action, when the terminal has the room.
        text_cols = ("condition", "meaning", "action") if wide else ("condition",)
        table.add_column(Text(""), key="mark", width=4)
        free = max(20, (self.size.width or 80) - 4 - 9 - 12)
        widths = {"condition": free // 3, "meaning": free // 3, "action": free - 2 * (free // 3)} \
            if wide else {"condition": free}
        for col in text_cols:
            table.add_column(Text(col.capitalize()), key=col, width=widths[col])
        table.add_column(Text("Go to"), key="step", width=9)
        for i, (rid, sev, cond, meaning, goto, hit, action) in enumerate(self._rows):
            mark = Text(">>" if (hit and self.show_all) else sev,
                        style="bold" if hit else "")
            cells = {"condition": cond, "meaning": meaning, "action": " ".join(action.split())}
            # Cut with an ellipsis to the column (the detail below has it all); Text, never
            # read as markup.
            table.add_row(mark, *(Text(cut(cells[c], widths[c])) for c in text_cols),
                          Text(_short_step(goto)), key=f"{i}-{rid}")
        self._show_detail()

    def _wide(self) -> bool:
        return (self.size.width or 80) >= 110

    def on_resize(self) -> None:
        if self.is_mounted and self._rows is not None:
            self.refresh_rows()

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

    def action_zoom(self) -> None:
        """The focused part (the table or the advice) fills the screen; again to restore."""
        if self.maximized is not None:
            self.minimize()
        else:
            self.maximized = self.focused or self.query_one(DataTable)
