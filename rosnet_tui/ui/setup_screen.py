"""The set-up screen: this component, its role and connection, and its peers."""

from __future__ import annotations

from dataclasses import replace

from rich.text import Text
from textual import on
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical, VerticalScroll
from textual.screen import Screen
from textual.validation import ValidationResult, Validator
from textual.widgets import Button, Input, Label, Select, Static

from rosnet_tui.core.config import settings_model as S
from rosnet_tui.core.wizard import setup_form as form
from rosnet_tui.core.wizard.session import WizardSession
from rosnet_tui.ui.fields import OrderedInput
from rosnet_tui.ui.messages import SettingsSaved
from rosnet_tui.ui.theme import cut
from rosnet_tui.ui.widgets import KeyBar, PlainHeader


class CoreValidator(Validator):
    """Wrap a core validator (value -> reason or None) for Textual's Input."""

    def __init__(self, func) -> None:
        super().__init__()
        self.func = func

    def validate(self, value: str) -> ValidationResult:
        why = self.func(value.strip())
        return self.failure(why) if why else self.success()


class FieldValidator(Validator):
    """A field of the core's table, checked as it is typed."""

    def __init__(self, field: form.FormField, detected: str) -> None:
        super().__init__()
        self.field = field
        self.detected = detected

    def validate(self, value: str) -> ValidationResult:
        why = self.field.why(value.strip(), self.detected)
        return self.failure(why) if why else self.success()


class PeerNameValidator(Validator):
    """A peer's name: a valid name, not this component's own, not another peer's (names are
    looked up without regard to case), refused as it is typed."""

    def __init__(self, row: PeerRow) -> None:
        super().__init__()
        self.row = row

    def validate(self, value: str) -> ValidationResult:
        value = value.strip()
        why = S.validate_name(value)
        if why is None:
            screen = self.row.screen if self.row.is_attached else None
            others = screen.names_in_use(self.row) if isinstance(screen, SetupScreen) else {}
            same = others.get(value.lower())
            if same == "this component":
                why = f"'{S.shown(value, S.FIELD_SHOWN_CHARS)}' is this component's own name"
            elif same:
                why = f"'{S.shown(value, S.FIELD_SHOWN_CHARS)}' is already a peer (names ignore case)"
        return self.failure(why) if why else self.success()


# The choices of each select, by its id (a draft keeps them as text).
SELECT_OPTIONS = {f.id: list(f.options) for f in form.FIELDS if f.kind == "choice"}


class PeerRow(Horizontal):
    """One peer: name, local IP, public IP, optional SSH user."""

    DEFAULT_CSS = """
    PeerRow { height: 1; }
    PeerRow > Input { width: 1fr; margin-right: 1; }
    PeerRow > .peer-user { width: 12; }
    PeerRow > Button { width: 7; min-width: 7; }
    """

    def __init__(self, index: int, peer: S.Peer, **kwargs) -> None:
        super().__init__(classes="peer-row", **kwargs)
        self.index = index
        self.peer = peer

    def compose(self) -> ComposeResult:
        i, p = self.index, self.peer
        for c in form.PEER_FIELDS:
            check = PeerNameValidator(self) if c.check is None else CoreValidator(c.check)
            yield OrderedInput(getattr(p, c.attr), placeholder=c.placeholder,
                               id=f"peer-{i}-{c.suffix}", compact=True, validators=[check],
                               classes=c.classes or None)
        yield Button(Text("[del]"), id=f"peer-{i}-remove", compact=True, classes="peer-remove",
                     tooltip="Remove this peer")

    def read(self) -> S.Peer:
        """The peer as typed so far (its own values until its fields are mounted)."""
        i, p = self.index, self.peer
        typed = {w.id: w.value.strip() for w in self.query(Input)}
        return replace(p, **{c.attr: typed.get(f"peer-{i}-{c.suffix}", getattr(p, c.attr))
                             for c in form.PEER_FIELDS})


class SetupScreen(Screen[bool]):
    """Who this component is, and who its peers are. Dismisses True when settings were saved."""

    BINDINGS = [
        Binding("escape,f10", "cancel", "Back", key_display="Esc/F10"),
        Binding("ctrl+s", "save", "Save"),
        Binding("ctrl+n", "add_peer", "Add peer"),
    ]
    DRAFT_DELAY_S = 0.3  # typing is kept this soon after the last key

    def __init__(self, session: WizardSession, **kwargs) -> None:
        super().__init__(**kwargs)
        self.session = session
        self.detected = session.detected
        self._next_peer = 0
        self._draft_timer = None
        self._restored_draft = False
        self._as_opened: tuple | None = None   # the form before any key: typing nothing is no draft

    def compose(self) -> ComposeResult:
        s = self.session.settings
        yield PlainHeader()
        with VerticalScroll(id="setup-form"):
            yield Static("Describe this machine and the components it must reach. Tab moves "
                         "between fields; Ctrl+S saves; Esc or F10 goes back without saving.",
                         id="setup-intro")
            yield Static("This component", classes="section")
            for f in form.FIELDS:
                yield from self._field(f, s)
            yield Static("Peers  (name · local IP · public IP · SSH user, optional)",
                         classes="section")
            with Vertical(id="peer-rows"):
                for p in s.peers:
                    yield self._peer_row(p)
            yield Label("", id="peer-error", classes="field-error")
            with Horizontal(id="setup-buttons"):
                yield Button(Text("[Add peer]"), id="add-peer", compact=True)
                yield Button(Text("[Save]"), id="save", variant="primary", compact=True)
                yield Button(Text("[Cancel]"), id="cancel", compact=True)
        yield KeyBar()

    def _field(self, f: form.FormField, s: S.Settings) -> ComposeResult:
        """One field of the core's table: its row, and the line under it for its reason."""
        detected = self.detected.local_ip
        with Horizontal(classes="field", id=f.box or None):
            yield Label(f.label, classes="field-label")
            value = f.value(s, detected)
            if f.kind == "choice":
                yield Select(list(f.options), value=value, allow_blank=False, id=f.id,
                             compact=True)
            else:
                placeholder = (detected or f.placeholder) if f.detected else f.placeholder
                yield OrderedInput(value, placeholder=placeholder, id=f.id, compact=True,
                                   type="integer" if f.kind == "number" else "text",
                                   validators=[FieldValidator(f, detected)])
        if f.hint:
            yield Label(f.hint, id=f"{f.id}-hint", classes="field-hint")
        if f.detected:
            yield Label(self._local_ip_hint(), id=f"{f.id}-error", classes="field-hint")
        elif f.kind != "choice":
            yield Label("", id=f"{f.id}-error", classes="field-error")

    def _local_ip_hint(self) -> str:
        d = self.detected
        if not d.local_ip:
            return "no network interface detected: type the address the modem forwards to"
        return f"detected: {d.local_ip} on {d.interface}" + (
            f", gateway {d.gateway}" if d.gateway else "")

    def _peer_row(self, peer: S.Peer) -> PeerRow:
        row = PeerRow(self._next_peer, peer, id=f"peer-row-{self._next_peer}")
        self._next_peer += 1
        return row

    async def on_mount(self) -> None:
        self.title = "rosnet-tui"
        self.sub_title = "set-up"
        self._as_opened = self.form_fields()
        await self._restore_draft()
        self._update_role()
        self.query_one("#this-name", Input).focus()

    # ------------------------------------------------------------------ the draft
    def form_fields(self) -> tuple[dict[str, str], list[dict[str, str]]]:
        """Every field as typed: this component's by widget id, and the peers' rows."""
        fields: dict[str, str] = {}
        for w in self.query(Input):
            if w.id and not w.id.startswith("peer-"):
                fields[w.id] = w.value
        for sel in self.query(Select):
            if sel.id and sel.value is not Select.BLANK:
                fields[sel.id] = str(sel.value)
        peers = [form.peer_row(row.read()) for row in self.query(PeerRow)]
        return fields, peers

    def keep_draft(self) -> None:
        """Save the form as typed, unless nothing was typed or it says what the saved settings
        say."""
        if self._draft_timer is not None:
            self._draft_timer.stop()
            self._draft_timer = None
        if not self.is_mounted:
            return
        fields, peers = self.form_fields()
        settings, _problems = self.read_form()
        if (fields, peers) == self._as_opened or (
                settings == self.session.settings and self.session.paths.config_path.exists()):
            self.session.clear_draft()
        else:
            self.session.save_draft(fields, peers)

    def _draft_soon(self) -> None:
        if self._draft_timer is not None:
            self._draft_timer.stop()
        self._draft_timer = self.set_timer(self.DRAFT_DELAY_S, self.keep_draft)

    async def _restore_draft(self) -> None:
        draft = self.session.draft()
        if not draft:
            return
        for wid, value in draft.fields.items():
            try:
                widget = self.query_one(f"#{wid}")
            except Exception:
                continue  # a field this version does not have
            try:
                if isinstance(widget, Input):
                    widget.value = str(value)
                elif isinstance(widget, Select):  # kept as text: back to the option's value
                    options = SELECT_OPTIONS.get(wid, [])
                    widget.value = next((v for _label, v in options if str(v) == str(value)),
                                        value)
            except Exception:
                continue  # a value the field refuses: it keeps the saved one
        if draft.peers is not None:
            rows = self.query_one("#peer-rows")
            await rows.remove_children()
            for peer in draft.peers:
                await rows.mount(self._peer_row(peer))
        from rosnet_tui.core.saved.ui_state import local_time

        when = local_time(draft.at)
        self._restored_draft = True
        self.notify(f"Back where you were: the set-up typed {when or 'earlier'} and not saved "
                    "yet. Ctrl+S saves it, Esc discards it.", timeout=8)

    def names_in_use(self, row: PeerRow) -> dict[str, str]:
        """Lower-cased names taken by this component and the peers other than *row*."""
        names: dict[str, str] = {}
        try:
            names[self.query_one("#this-name", Input).value.strip().lower()] = "this component"
        except Exception:
            pass
        for other in self.query(PeerRow):
            if other is not row:
                name = other.read().name.lower()
                if name:
                    names.setdefault(name, other.read().name)
        return names

    # ------------------------------------------------------------------ events
    @on(Select.Changed, "#this-role")
    @on(Select.Changed, "#ros-version")
    @on(Select.Changed, "#rosbridge-enabled")
    def _role_changed(self) -> None:
        self._update_role()

    @on(Select.Changed)
    def _select_changed(self) -> None:
        self._draft_soon()

    def _choices(self) -> dict[str, object]:
        return {sel.id: sel.value for sel in self.query(Select) if sel.id}

    def _update_role(self) -> None:
        """Show only the fields the choices call for (the master's name on a member, what the
        ROS version needs, rosbridge's when it is on)."""
        choices = self._choices()
        for f in form.FIELDS:
            if f.box:
                shown = form.shown(f, choices)
                self.query_one(f"#{f.box}").display = shown
                for line in self.query(f"#{f.id}-error, #{f.id}-hint"):
                    if shown:     # the style sheet's say: an error line shows only with one
                        line.styles.clear_rule("display")
                    else:
                        line.display = False

    @on(Input.Changed)
    def _input_changed(self, event: Input.Changed) -> None:
        self._draft_soon()
        if event.input.id and event.validation_result is not None:
            label = self._error_label(event.input.id)
            if label is not None:
                ok = event.validation_result.is_valid
                msg = "" if ok else "; ".join(event.validation_result.failure_descriptions)
                field = form.FIELD_BY_ID.get(event.input.id)
                if ok and field is not None and field.detected:
                    msg = self._local_ip_hint()
                label.update(cut(msg, max(20, self.size.width - 16)))
                label.set_class(not ok, "-shown")

    def _error_label(self, input_id: str) -> Label | None:
        if input_id.startswith("peer-"):
            return self.query_one("#peer-error", Label)
        try:
            return self.query_one(f"#{input_id}-error", Label)
        except Exception:
            return None

    @on(Button.Pressed, "#add-peer")
    async def action_add_peer(self) -> None:
        row = self._peer_row(S.Peer(name=""))
        await self.query_one("#peer-rows").mount(row)  # mounted before the next key is read
        row.query_one(Input).focus()

    @on(Button.Pressed, ".peer-remove")
    async def _remove_peer(self, event: Button.Pressed) -> None:
        row = event.button.parent
        if isinstance(row, PeerRow):
            await row.remove()
            self._draft_soon()

    @on(Button.Pressed, "#save")
    def action_save(self) -> None:
        settings, problems = self.read_form()
        if problems:
            key, why = problems[0]
            self._show_problem(key, why)
            return
        try:
            self.session.save_settings(settings)
        except S.SettingsError as exc:
            self.notify(str(exc), title="Not saved", severity="error", timeout=10)
            return
        if self._draft_timer is not None:
            self._draft_timer.stop()
        self.session.clear_draft()
        self.app.post_message(SettingsSaved())
        self.dismiss(True)

    @on(Button.Pressed, "#cancel")
    def action_cancel(self) -> None:
        if not self.session.settings.complete:
            self.notify("Fill in this component and save first (Ctrl+Q quits; what you typed "
                        "is kept for next time).", severity="warning")
            return
        if self._draft_timer is not None:
            self._draft_timer.stop()
        self.session.clear_draft()  # going back without saving: the draft is dropped
        self.dismiss(False)

    # ------------------------------------------------------------------ form -> settings
    def read_form(self) -> tuple[S.Settings, list[tuple[str, str]]]:
        values: dict[str, object] = self._choices()
        values.update({w.id: w.value.strip() for w in self.query(Input)
                       if w.id and not w.id.startswith("peer-")})
        return form.settings_from_form(self.session.settings, values,
                                       [row.read() for row in self.query(PeerRow)],
                                       self.detected.local_ip)

    def _show_problem(self, key: str, why: str) -> None:
        """Put the reason beside the field at fault, and the cursor in it."""
        target, label_id = None, None
        in_row = form.peer_field_for_key(key)
        if in_row is not None:
            idx, column = in_row
            rows = list(self.query(PeerRow))
            if 0 <= idx < len(rows):
                target = f"#peer-{rows[idx].index}-{column.suffix}"
            label_id = "#peer-error"
            why = f"peer {idx + 1}: {why}"
        else:
            field = form.field_for_key(key)
            target = f"#{field.id}" if field is not None else None
            label_id = f"{target}-error" if target else None
        if label_id:
            label = self.query_one(label_id, Label)
            label.update(cut(why, max(20, self.size.width - 16)))
            label.set_class(True, "-shown")
        if target:
            self.query_one(target, Input).focus()
        self.notify(why, title="Not saved yet", severity="warning", timeout=6)
