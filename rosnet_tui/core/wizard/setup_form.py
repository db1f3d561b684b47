"""The set-up form's fields, each declared once: its label, its help (placeholder, choices), how
typed text is checked, when it shows, and which settings key it reads and writes.

The UI renders :data:`FIELDS` and :data:`PEER_FIELDS` and hands back what was typed;
:func:`settings_from_form` turns that into settings and the problems that keep them from being
saved, keyed as :meth:`Settings.problems` keys them, so the screen can put each reason beside its
field (:func:`field_for_key`). Defaults are the settings model's (a new form shows a new
:class:`~rosnet_tui.core.config.settings_model.Settings`), its validators are the model's too.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from typing import Any, Literal

from rosnet_tui.core.config import settings_model as S

Kind = Literal["text", "number", "choice"]
# When a field shows: always, on a member, under ROS 2, with rosbridge on.
Shows = Literal["", "member", "ros2", "rosbridge"]


def validate_optional_name(value: str) -> str | None:
    """A name, or nothing (the default applies)."""
    return S.validate_name(value) if value else None


def validate_bridge_port(value: str) -> str | None:
    """rosbridge's port: any TCP port (it is not forwarded, so not held to the test range)."""
    return S.validate_port(value, lo=1, hi=65535)


@dataclass(frozen=True)
class FormField:
    """One field of the set-up form."""

    id: str                  # the widget's id (and the draft's key)
    key: str                 # the settings key, as Settings.problems() names it ("probe.port")
    label: str
    kind: Kind
    placeholder: str = ""
    options: tuple[tuple[str, Any], ...] = ()   # choice: (what the user reads, the value)
    check: Callable[[str], str | None] | None = None   # why typed text is refused (None: fine)
    shows: Shows = ""
    box: str = ""            # the id of its row, when the row hides with `shows`
    # The value the form shows for *settings* (None: the settings key's own value).
    shown_value: Callable[[S.Settings], Any] | None = None
    # Blank means "detected at each run" (this machine's address): required only when nothing
    # could be detected, and the detected value is the placeholder.
    detected: bool = False
    hint: str = ""           # a line under the field: when it is needed

    def why(self, text: str, detected: str = "") -> str | None:
        """Why *text* cannot be this field's value (None when it can)."""
        if self.detected:
            return S.validate_ip(text, required=not detected)
        return self.check(text) if self.check is not None else None

    def value(self, settings: S.Settings, detected: str = "") -> Any:
        """What the form shows for *settings* (*detected*: this machine's address, if found)."""
        if self.detected:   # first run: the detected value, ready to keep
            return settings.this.local_ip or ("" if settings.complete else detected)
        if self.shown_value is not None:
            return self.shown_value(settings)
        table, attr = self.key.split(".")
        got = getattr(getattr(settings, table), attr)
        return str(got) if self.kind != "choice" else got


def _security_shown(s: S.Settings) -> str:
    return "none" if s.ros.security == "none" else "on"


FIELDS: tuple[FormField, ...] = (
    FormField("this-name", "this.name", "Name", "text", placeholder="e.g. turtlebot",
              check=S.validate_name),
    FormField("this-role", "this.role", "Role", "choice",
              options=(("ROS master (roscore / the Zenoh hub)", "master"), ("Member", "member"))),
    FormField("this-connection", "this.connection", "Connection", "choice",
              options=(("Telecom (mobile hotspot)", "telecom"), ("Home", "home"),
                       ("Corporate / university", "corporate"))),
    FormField("this-profile", "this.profile", "Network", "choice",
              options=(("Remote (peers by public IP)", "remote"), ("Office LAN", "office"),
                       ("Portable hotspot LAN", "portable"))),
    # Saved settings keep their blank (the address is then detected at each run), so saving
    # them unchanged changes nothing.
    FormField("this-local-ip", "this.local_ip", "Local IP", "text",
              placeholder="e.g. 10.10.10.1", detected=True),
    FormField("probe-port", "probe.port", "Test port", "number", check=S.validate_port),
    FormField("ros-version", "ros.version", "ROS", "choice",
              options=(("ROS 2 (rmw_zenoh: one forwarded port)", 2), ("ROS 1 (roscore)", 1)),
              shown_value=lambda s: s.ros.version if s.ros.version in S.ROS_VERSIONS else 1),
    FormField("ros-zenoh-port", "ros.zenoh_port", "Zenoh port", "number", check=S.validate_port,
              shows="ros2", box="zenoh-field"),
    FormField("ros-domain-id", "ros.domain_id", "Domain id", "number",
              check=S.validate_domain_id, shows="ros2", box="domain-field"),
    FormField("ros-master", "ros.master", "ROS master", "text",
              placeholder="name of the peer that runs roscore", check=S.validate_name,
              shows="member", box="master-field",
              shown_value=lambda s: s.ros.master if s.this.role == "member" else ""),
    # Blank: no relay (its other keys, docs/SETTINGS.md, keep their defaults when it is typed).
    FormField("relay-host", "relay.host", "Relay", "text",
              placeholder="none, or its name: relay.example.org", check=validate_optional_name,
              shows="ros2", box="relay-field",
              hint="Both sites behind carrier NAT or no forwarding possible: a relay"),
    FormField("rosbridge-enabled", "rosbridge.enabled", "rosbridge", "choice",
              options=(("Off (no web clients)", False),
                       ("On: check browsers' path (rosbridge)", True)),
              shown_value=lambda s: s.rosbridge.enabled is True),
    FormField("rosbridge-port", "rosbridge.port", "Bridge port", "number",
              check=validate_bridge_port, shows="rosbridge", box="rosbridge-port-field"),
    FormField("rosbridge-host", "rosbridge.host", "Bridge host", "text",
              placeholder="default: the ROS master", check=validate_optional_name,
              shows="rosbridge", box="rosbridge-host-field"),
    # On: ROS 2, mutual TLS (only fleet certificates); ROS 1, a firewall admitting only the peers.
    FormField("ros-security", "ros.security", "Security", "choice",
              options=(("On: only the fleet gets in", "on"),
                       ("Off: open to anyone at the ports", "none")),
              shown_value=_security_shown),
)
FIELD_BY_ID = {f.id: f for f in FIELDS}


@dataclass(frozen=True)
class PeerField:
    """One column of a peer's row: its widget id is ``peer-<n>-<suffix>``."""

    suffix: str
    attr: str                # the Peer attribute (the key peer[n].<attr>)
    placeholder: str
    check: Callable[[str], str | None] | None = None   # None: the screen's own (the name)
    classes: str = ""


PEER_FIELDS: tuple[PeerField, ...] = (
    PeerField("name", "name", "name", classes="peer-name"),
    PeerField("local", "local_ip", "local IP", lambda v: S.validate_ip(v, required=False)),
    PeerField("public", "public_ip", "public IP", lambda v: S.validate_ip(v, required=False)),
    PeerField("user", "ssh_user", "ssh user", S.validate_ssh_user, classes="peer-user"),
)


@dataclass(frozen=True)
class Draft:
    """A set-up form typed and not saved yet (kept in the state dir between sessions)."""

    fields: dict[str, str]   # by field id, as typed (choices as text)
    peers: list[S.Peer] | None   # the peers' rows (None: the draft kept none)
    at: str                  # when it was kept (ISO 8601, UTC; "" when unknown)


def peer_row(peer: S.Peer) -> dict[str, str]:
    """A peer's row as a draft keeps it (its columns by settings attribute)."""
    return {c.attr: getattr(peer, c.attr) for c in PEER_FIELDS}


def draft_from(saved: Mapping[str, Any] | None) -> Draft | None:
    """The draft kept as *saved* (what the state file holds), or None; rows or values of
    another shape are left out."""
    if not saved or not isinstance(saved.get("fields"), dict):
        return None
    rows = saved.get("peers")
    peers = [S.Peer(**{c.attr: str(row.get(c.attr, "")) for c in PEER_FIELDS})
             for row in rows if isinstance(row, dict)] if isinstance(rows, list) else None
    return Draft(dict(saved["fields"]), peers, str(saved.get("at", "")))


def shown(field: FormField, values: Mapping[str, Any]) -> bool:
    """Whether *field* shows, given the form's choices (*values* by field id)."""
    if field.shows == "member":
        return values.get("this-role") == "member"
    if field.shows == "ros2":
        return values.get("ros-version") == 2
    if field.shows == "rosbridge":
        return values.get("rosbridge-enabled") is True
    return True


def field_for_key(key: str) -> FormField | None:
    """The typed-in field that a problem's settings *key* is about (None: no such field)."""
    return next((f for f in FIELDS if f.key == key and f.kind != "choice"), None)


def peer_field_for_key(key: str) -> tuple[int, PeerField] | None:
    """``peer[n].attr`` -> (n - 1, its column); the name's column for a key of no column."""
    if not key.startswith("peer["):
        return None
    index = int(key[5:key.index("]")]) - 1
    attr = key.rsplit(".", 1)[-1]
    column = next((c for c in PEER_FIELDS if c.attr == attr), PEER_FIELDS[0])
    return index, column


def settings_from_form(old: S.Settings, values: Mapping[str, Any], peers: list[S.Peer],
                       detected: str = "") -> tuple[S.Settings, list[tuple[str, str]]]:
    """The settings the form says (*values*: by field id, text stripped; choices as their
    values), and the problems keeping them from being saved ((key, why), the field's first)."""
    tables = {"this": replace(old.this), "ros": replace(old.ros), "probe": replace(old.probe),
              "rosbridge": replace(old.rosbridge), "relay": replace(old.relay)}
    problems: list[tuple[str, str]] = []
    for f in FIELDS:
        if f.key == "ros.security" or not shown(f, values):
            continue
        value = values.get(f.id, "")
        if f.kind == "number":
            why = f.check(value) if f.check is not None else None
            if why:
                problems.append((f.key, why))
                continue
            value = int(value)
        elif f.kind == "choice":   # as the options' type (a blank select: the first option)
            like = f.options[0][1]
            value = (value is True if isinstance(like, bool) else
                     int(value or like) if isinstance(like, int) else str(value))
        table, attr = f.key.split(".")
        setattr(tables[table], attr, value)
    this, ros = tables["this"], tables["ros"]
    if this.role == "master":
        ros.master = this.name
    if values.get("ros-security") == "none":
        ros.security = "none"
    elif ros.security == "none" or ros.security_chosen():
        ros.security = S.default_security(ros.version)   # on: what this version does
    relay = tables["relay"]
    if ros.version != 2 or not relay.host:   # no relay in the form: none of its keys either
        relay = S.RelaySettings()
    settings = replace(old, this=this, peers=peers, ros=ros, probe=tables["probe"],
                       rosbridge=tables["rosbridge"], relay=relay)
    problems += settings.problems()
    # Blank is fine when this machine's address can be detected at each run.
    why = FIELD_BY_ID["this-local-ip"].why(this.local_ip, detected)
    if why:
        problems.insert(0, ("this.local_ip", why))
    return settings, problems
