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
from rosnet_tui.core.config.settings_model import default_security
from rosnet_tui.core.wizard.session import WizardSession
from rosnet_tui.ui.fields import OrderedInput
from rosnet_tui.ui.messages import SettingsSaved
from rosnet_tui.ui.theme import cut
from rosnet_tui.ui.widgets import KeyBar, PlainHeader


class CoreValidator(Validator):
    """Wrap a core validator (value -> reason or None) for Textual's Input."""

    def __init__(self, func, **kwargs) -> None:
        super().__init__()
        self.func = func
        self.kwargs = kwargs

    def validate(self, value: str) -> ValidationResult:
        why = self.func(value.strip(), **self.kwargs)
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


CONNECTION_OPTIONS = [("Telecom (mobile hotspot)", "telecom"), ("Home", "home"),
                      ("Corporate / university", "corporate")]
ROLE_OPTIONS = [("ROS master (roscore / the Zenoh hub)", "master"), ("Member", "member")]
ROS_VERSION_OPTIONS = [("ROS 2 (rmw_zenoh: one forwarded port)", 2), ("ROS 1 (roscore)", 1)]
PROFILE_OPTIONS = [("Remote (peers by public IP)", "remote"), ("Office LAN", "office"),
                   ("Portable hotspot LAN", "portable")]
# On: ROS 2, mutual TLS (only fleet certificates); ROS 1, a firewall admitting only the peers.
SECURITY_OPTIONS = [("On: only the fleet gets in", "on"),
                    ("Off: open to anyone at the ports", "none")]
ROSBRIDGE_OPTIONS = [("Off (no web clients)", False),
                     ("On: check browsers' path (rosbridge)", True)]
SELECT_OPTIONS = {"this-role": ROLE_OPTIONS, "this-connection": CONNECTION_OPTIONS,
                  "this-profile": PROFILE_OPTIONS, "ros-version": ROS_VERSION_OPTIONS,
                  "rosbridge-enabled": ROSBRIDGE_OPTIONS, "ros-security": SECURITY_OPTIONS}


def validate_optional_name(value: str) -> str | None:
    """A name, or nothing (the default applies)."""
    return S.validate_name(value) if value else None


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
        yield OrderedInput(p.name, placeholder="name", id=f"peer-{i}-name", compact=True,
                           validators=[PeerNameValidator(self)], classes="peer-name")
        yield OrderedInput(p.local_ip, placeholder="local IP", id=f"peer-{i}-local", compact=True,
                    validators=[CoreValidator(S.validate_ip, required=False)])
        yield OrderedInput(p.public_ip, placeholder="public IP", id=f"peer-{i}-public", compact=True,
                    validators=[CoreValidator(S.validate_ip, required=False)])
        yield OrderedInput(p.ssh_user, placeholder="ssh user", id=f"peer-{i}-user", compact=True,
                    validators=[CoreValidator(S.validate_ssh_user)], classes="peer-user")
        yield Button(Text("[del]"), id=f"peer-{i}-remove", compact=True, classes="peer-remove",
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
        t = s.this
        # First run: the detected address, ready to keep. Saved settings keep their blank (the
        # address is then detected at each run), so saving them unchanged changes nothing.
        local_ip = t.local_ip or ("" if s.complete else self.detected.local_ip)
        yield PlainHeader()
        with VerticalScroll(id="setup-form"):
            yield Static("Describe this machine and the components it must reach. Tab moves "
                         "between fields; Ctrl+S saves; Esc or F10 goes back without saving.",
                         id="setup-intro")
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
                yield OrderedInput(local_ip, placeholder=self.detected.local_ip or "e.g. 10.10.10.1",
                                   id="this-local-ip", compact=True,
                                   validators=[CoreValidator(
                                       S.validate_ip, required=not self.detected.local_ip)])
            yield Label(self._local_ip_hint(), id="this-local-ip-error", classes="field-hint")
            with Horizontal(classes="field"):
                yield Label("Test port", classes="field-label")
                yield OrderedInput(str(s.probe.port), id="probe-port", compact=True, type="integer",
                            validators=[CoreValidator(S.validate_port)])
            yield Label("", id="probe-port-error", classes="field-error")
            with Horizontal(classes="field"):
                yield Label("ROS", classes="field-label")
                yield Select(ROS_VERSION_OPTIONS, value=s.ros.version if s.ros.version in (1, 2)
                             else 1, allow_blank=False, id="ros-version", compact=True)
            with Horizontal(classes="field", id="zenoh-field"):
                yield Label("Zenoh port", classes="field-label")
                yield OrderedInput(str(s.ros.zenoh_port), id="ros-zenoh-port", compact=True,
                                   type="integer", validators=[CoreValidator(S.validate_port)])
            yield Label("", id="ros-zenoh-port-error", classes="field-error")
            with Horizontal(classes="field", id="domain-field"):
                yield Label("Domain id", classes="field-label")
                yield OrderedInput(str(s.ros.domain_id), id="ros-domain-id", compact=True,
                                   type="integer", validators=[CoreValidator(S.validate_domain_id)])
            yield Label("", id="ros-domain-id-error", classes="field-error")
            with Horizontal(classes="field", id="master-field"):
                yield Label("ROS master", classes="field-label")
                yield OrderedInput(s.ros.master if t.role == "member" else "",
                            placeholder="name of the peer that runs roscore", id="ros-master",
                            compact=True, validators=[CoreValidator(S.validate_name)])
            yield Label("", id="ros-master-error", classes="field-error")
            with Horizontal(classes="field"):
                yield Label("rosbridge", classes="field-label")
                yield Select(ROSBRIDGE_OPTIONS, value=s.rosbridge.enabled is True,
                             allow_blank=False, id="rosbridge-enabled", compact=True)
            with Horizontal(classes="field", id="rosbridge-port-field"):
                yield Label("Bridge port", classes="field-label")
                yield OrderedInput(str(s.rosbridge.port), id="rosbridge-port", compact=True,
                                   type="integer",
                                   validators=[CoreValidator(S.validate_port, lo=1, hi=65535)])
            yield Label("", id="rosbridge-port-error", classes="field-error")
            with Horizontal(classes="field", id="rosbridge-host-field"):
                yield Label("Bridge host", classes="field-label")
                yield OrderedInput(s.rosbridge.host, placeholder="default: the ROS master",
                                   id="rosbridge-host", compact=True,
                                   validators=[CoreValidator(validate_optional_name)])
            yield Label("", id="rosbridge-host-error", classes="field-error")
            with Horizontal(classes="field"):
                yield Label("Security", classes="field-label")
                yield Select(SECURITY_OPTIONS, value="none" if s.ros.security == "none" else "on",
                             allow_blank=False, id="ros-security", compact=True)
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
        peers = [{"name": p.name, "local_ip": p.local_ip, "public_ip": p.public_ip,
                  "ssh_user": p.ssh_user} for p in (row.read() for row in self.query(PeerRow))]
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
        for wid, value in draft["fields"].items():
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
        peers = draft.get("peers")
        if isinstance(peers, list):
            rows = self.query_one("#peer-rows")
            await rows.remove_children()
            for p in peers:
                if isinstance(p, dict):
                    peer = S.Peer(name=str(p.get("name", "")), local_ip=str(p.get("local_ip", "")),
                                  public_ip=str(p.get("public_ip", "")),
                                  ssh_user=str(p.get("ssh_user", "")))
                    await rows.mount(self._peer_row(peer))
        from rosnet_tui.core.saved.ui_state import local_time

        when = local_time(str(draft.get("at", "")))
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

    def _update_role(self) -> None:
        is_member = self.query_one("#this-role", Select).value == "member"
        self.query_one("#master-field").display = is_member
        self.query_one("#ros-master-error").display = is_member
        ros2 = self.query_one("#ros-version", Select).value == 2  # only what the version needs
        for wid in ("#zenoh-field", "#ros-zenoh-port-error", "#domain-field",
                    "#ros-domain-id-error"):
            self.query_one(wid).display = ros2
        bridge = self.query_one("#rosbridge-enabled", Select).value is True
        for wid in ("#rosbridge-port-field", "#rosbridge-port-error", "#rosbridge-host-field",
                    "#rosbridge-host-error"):
            self.query_one(wid).display = bridge

    @on(Input.Changed)
    def _input_changed(self, event: Input.Changed) -> None:
        self._draft_soon()
        if event.input.id and event.validation_result is not None:
            label = self._error_label(event.input.id)
            if label is not None:
                ok = event.validation_result.is_valid
                msg = "" if ok else "; ".join(event.validation_result.failure_descriptions)
                if event.input.id == "this-local-ip" and ok:
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
        old = self.session.settings
        val = lambda wid: self.query_one(f"#{wid}", Input).value.strip()  # noqa: E731
        role = str(self.query_one("#this-role", Select).value)
        this = replace(old.this, name=val("this-name"), role=role,
                       connection=str(self.query_one("#this-connection", Select).value),
                       profile=str(self.query_one("#this-profile", Select).value),
                       local_ip=val("this-local-ip"),
                       interface=old.this.interface)
        peers = [row.read() for row in self.query(PeerRow)]
        master = this.name if role == "master" else val("ros-master")
        problems: list[tuple[str, str]] = []
        port_text = val("probe-port")
        why = S.validate_port(port_text)
        port = int(port_text) if why is None else old.probe.port
        if why:
            problems.append(("probe.port", why))
        version = int(self.query_one("#ros-version", Select).value or 1)
        ros = replace(old.ros, master=master, version=version)
        if self.query_one("#ros-security", Select).value == "none":
            ros.security = "none"
        elif ros.security == "none" or ros.security_chosen():
            ros.security = default_security(version)   # on: what this version does
        if version == 2:
            for key, wid, check in (("zenoh_port", "ros-zenoh-port", S.validate_port),
                                    ("domain_id", "ros-domain-id", S.validate_domain_id)):
                text = val(wid)
                why = check(text)
                if why:
                    problems.append((f"ros.{key}", why))
                else:
                    ros = replace(ros, **{key: int(text)})
        bridge = replace(old.rosbridge,
                         enabled=self.query_one("#rosbridge-enabled", Select).value is True)
        if bridge.enabled:
            text = val("rosbridge-port")
            why = S.validate_port(text, lo=1, hi=65535)
            if why:
                problems.append(("rosbridge.port", why))
            else:
                bridge = replace(bridge, port=int(text))
            bridge = replace(bridge, host=val("rosbridge-host"))
        settings = replace(old, this=this, peers=peers, ros=ros,
                           probe=replace(old.probe, port=port), rosbridge=bridge)
        problems += settings.problems()
        # Blank is fine when this machine's address can be detected at each run.
        why = S.validate_ip(this.local_ip, required=not self.detected.local_ip)
        if why:
            problems.insert(0, ("this.local_ip", why))
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
                      "probe.port": "#probe-port", "ros.master": "#ros-master",
                      "ros.zenoh_port": "#ros-zenoh-port",
                      "ros.domain_id": "#ros-domain-id",
                      "rosbridge.port": "#rosbridge-port",
                      "rosbridge.host": "#rosbridge-host"}.get(key)
            label_id = f"{target}-error" if target else None
        if label_id:
            label = self.query_one(label_id, Label)
            label.update(cut(why, max(20, self.size.width - 16)))
            label.set_class(True, "-shown")
        if target:
            self.query_one(target, Input).focus()
        self.notify(why, title="Not saved yet", severity="warning", timeout=6)
