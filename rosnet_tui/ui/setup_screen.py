"""The set-up screen: this component, its role and connection, and its peers."""

from __future__ import annotations

from dataclasses import replace

from textual import on
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical, VerticalScroll
from textual.screen import Screen
from textual.validation import ValidationResult, Validator
from textual.widgets import Button, Footer, Header, Input, Label, Select, Static

from rosnet_tui.core import settings as S
from rosnet_tui.core.session import WizardSession
from rosnet_tui.ui.messages import SettingsSaved
from rosnet_tui.ui.widgets import OrderedInput


class CoreValidator(Validator):
    """Wrap a core validator (value -> reason or None) for Textual's Input."""

    def __init__(self, func, **kwargs) -> None:
        super().__init__()
        self.func = func
        self.kwargs = kwargs

    def validate(self, value: str) -> ValidationResult:
        why = self.func(value.strip(), **self.kwargs)
        return self.failure(why) if why else self.success()


CONNECTION_OPTIONS = [("Telecom (mobile hotspot)", "telecom"), ("Home", "home"),
                      ("Corporate / university", "corporate")]
ROLE_OPTIONS = [("ROS master (runs roscore)", "master"), ("Member", "member")]
PROFILE_OPTIONS = [("Remote (peers by public IP)", "remote"), ("Office LAN", "office"),
                   ("Portable hotspot LAN", "portable")]


class PeerRow(Horizontal):
    """One peer: name, local IP, public IP, optional SSH user."""

    DEFAULT_CSS = """
    PeerRow { height: 1; }
    PeerRow > Input { width: 1fr; margin-right: 1; }
    PeerRow > .peer-user { width: 12; }
    PeerRow > Button { width: 5; min-width: 5; }
    """

    def __init__(self, index: int, peer: S.Peer, **kwargs) -> None:
        super().__init__(classes="peer-row", **kwargs)
        self.index = index
        self.peer = peer

    def compose(self) -> ComposeResult:
        i, p = self.index, self.peer
        yield OrderedInput(p.name, placeholder="name", id=f"peer-{i}-name", compact=True,
                    validators=[CoreValidator(S.validate_name)], classes="peer-name")
        yield OrderedInput(p.local_ip, placeholder="local IP", id=f"peer-{i}-local", compact=True,
                    validators=[CoreValidator(S.validate_ip, required=False)])
        yield OrderedInput(p.public_ip, placeholder="public IP", id=f"peer-{i}-public", compact=True,
                    validators=[CoreValidator(S.validate_ip, required=False)])
        yield OrderedInput(p.ssh_user, placeholder="ssh user", id=f"peer-{i}-user", compact=True,
                    validators=[CoreValidator(S.validate_ssh_user)], classes="peer-user")
        yield Button("del", id=f"peer-{i}-remove", compact=True, classes="peer-remove",
                     tooltip="Remove this peer")

    def read(self) -> S.Peer:
        """The peer as typed so far (its own values until its fields are mounted)."""
        i, p = self.index, self.peer
        typed = {w.id: w.value.strip() for w in self.query(Input)}
        val = lambda suffix, default: typed.get(f"peer-{i}-{suffix}", default)  # noqa: E731
        return replace(p, name=val("name", p.name), local_ip=val("local", p.local_ip),
                       public_ip=val("public", p.public_ip), ssh_user=val("user", p.ssh_user))


class SetupScreen(Screen[bool]):
    """Who this component is, and who its peers are. Dismisses True when settings were saved."""

    BINDINGS = [
        Binding("escape", "cancel", "Back"),
        Binding("ctrl+s", "save", "Save"),
        Binding("ctrl+n", "add_peer", "Add peer"),
    ]

    def __init__(self, session: WizardSession, **kwargs) -> None:
        super().__init__(**kwargs)
        self.session = session
        self.detected = session.detected
        self._next_peer = 0

    def compose(self) -> ComposeResult:
        s = self.session.settings
        t = s.this
        local_ip = t.local_ip or self.detected.local_ip
        yield Header(show_clock=False, icon="")
        with VerticalScroll(id="setup-form"):
            yield Static("Describe this machine and the components it must reach. Tab moves "
                         "between fields; Ctrl+S saves.", id="setup-intro")
            yield Static("This component", classes="section")
            with Horizontal(classes="field"):
                yield Label("Name", classes="field-label")
                yield OrderedInput(t.name, placeholder="e.g. turtlebot", id="this-name", compact=True,
                            validators=[CoreValidator(S.validate_name)])
            yield Label("", id="this-name-error", classes="field-error")
            with Horizontal(classes="field"):
                yield Label("Role", classes="field-label")
                yield Select(ROLE_OPTIONS, value=t.role, allow_blank=False, id="this-role",
                             compact=True)
            with Horizontal(classes="field"):
                yield Label("Connection", classes="field-label")
                yield Select(CONNECTION_OPTIONS, value=t.connection, allow_blank=False,
                             id="this-connection", compact=True)
            with Horizontal(classes="field"):
                yield Label("Network", classes="field-label")
                yield Select(PROFILE_OPTIONS, value=t.profile, allow_blank=False,
                             id="this-profile", compact=True)
            with Horizontal(classes="field"):
                yield Label("Local IP", classes="field-label")
                yield OrderedInput(local_ip, placeholder="e.g. 10.10.10.1", id="this-local-ip",
                            compact=True, validators=[CoreValidator(S.validate_ip)])
            yield Label(self._local_ip_hint(), id="this-local-ip-error", classes="field-hint")
            with Horizontal(classes="field"):
                yield Label("Test port", classes="field-label")
                yield OrderedInput(str(s.probe.port), id="probe-port", compact=True, type="integer",
                            validators=[CoreValidator(S.validate_port)])
            yield Label("", id="probe-port-error", classes="field-error")
            with Horizontal(classes="field", id="master-field"):
                yield Label("ROS master", classes="field-label")
                yield OrderedInput(s.ros.master if t.role == "member" else "",
                            placeholder="name of the peer that runs roscore", id="ros-master",
                            compact=True, validators=[CoreValidator(S.validate_name)])
            yield Label("", id="ros-master-error", classes="field-error")
            yield Static("Peers  (name · local IP · public IP · SSH user, optional)",
                         classes="section")
            with Vertical(id="peer-rows"):
                for p in s.peers:
                    yield self._peer_row(p)
            yield Label("", id="peer-error", classes="field-error")
            with Horizontal(id="setup-buttons"):
                yield Button("Add peer", id="add-peer", compact=True)
                yield Button("Save", id="save", variant="primary", compact=True)
                yield Button("Cancel", id="cancel", compact=True)
        yield Footer()

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

    def on_mount(self) -> None:
        self.title = "rosnet-tui"
        self.sub_title = "set-up"
        self._update_role()
        self.query_one("#this-name", Input).focus()

    # ------------------------------------------------------------------ events
    @on(Select.Changed, "#this-role")
    def _role_changed(self) -> None:
        self._update_role()

    def _update_role(self) -> None:
        is_member = self.query_one("#this-role", Select).value == "member"
        self.query_one("#master-field").display = is_member
        self.query_one("#ros-master-error").display = is_member

    @on(Input.Changed)
    def _input_changed(self, event: Input.Changed) -> None:
        if event.input.id and event.validation_result is not None:
            label = self._error_label(event.input.id)
            if label is not None:
                ok = event.validation_result.is_valid
                msg = "" if ok else "; ".join(event.validation_result.failure_descriptions)
                if event.input.id == "this-local-ip" and ok:
                    msg = self._local_ip_hint()
                label.update(msg)
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
    def _remove_peer(self, event: Button.Pressed) -> None:
        row = event.button.parent
        if isinstance(row, PeerRow):
            row.remove()

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
        self.app.post_message(SettingsSaved())
        self.dismiss(True)

    @on(Button.Pressed, "#cancel")
    def action_cancel(self) -> None:
        if not self.session.settings.complete:
            self.notify("Fill in this component and save first (Ctrl+Q quits).",
                        severity="warning")
            return
        self.dismiss(False)

    # ------------------------------------------------------------------ form -> settings
    def read_form(self) -> tuple[S.Settings, list[tuple[str, str]]]:
        old = self.session.settings
        val = lambda wid: self.query_one(f"#{wid}", Input).value.strip()  # noqa: E731
        role = str(self.query_one("#this-role", Select).value)
        this = replace(old.this, name=val("this-name"), role=role,
                       connection=str(self.query_one("#this-connection", Select).value),
                       profile=str(self.query_one("#this-profile", Select).value),
                       local_ip=val("this-local-ip"),
                       interface=old.this.interface or self.detected.interface)
        peers = [row.read() for row in self.query(PeerRow)]
        master = this.name if role == "master" else val("ros-master")
        problems: list[tuple[str, str]] = []
        port_text = val("probe-port")
        why = S.validate_port(port_text)
        port = int(port_text) if why is None else old.probe.port
        if why:
            problems.append(("probe.port", why))
        settings = replace(old, this=this, peers=peers, ros=replace(old.ros, master=master),
                           probe=replace(old.probe, port=port))
        problems += settings.problems()
        if S.validate_ip(this.local_ip):
            problems.insert(0, ("this.local_ip", S.validate_ip(this.local_ip) or ""))
        return settings, problems

    def _show_problem(self, key: str, why: str) -> None:
        """Put the reason beside the field at fault, and the cursor in it."""
        target, label_id = None, None
        if key.startswith("peer["):
            idx = int(key[5:key.index("]")]) - 1
            rows = list(self.query(PeerRow))
            field = key.rsplit(".", 1)[-1]
            suffix = {"name": "name", "local_ip": "local", "public_ip": "public",
                      "ssh_user": "user"}.get(field, "name")
            if 0 <= idx < len(rows):
                target = f"#peer-{rows[idx].index}-{suffix}"
            label_id = "#peer-error"
            why = f"peer {idx + 1}: {why}"
        else:
            target = {"this.name": "#this-name", "this.local_ip": "#this-local-ip",
                      "probe.port": "#probe-port", "ros.master": "#ros-master"}.get(key)
            label_id = f"{target}-error" if target else None
        if label_id:
            label = self.query_one(label_id, Label)
            label.update(why)
            label.set_class(True, "-shown")
        if target:
            self.query_one(target, Input).focus()
        self.notify(why, title="Not saved yet", severity="warning", timeout=6)
