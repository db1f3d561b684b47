"""One wizard session: what every screen needs, handed to it (no screen reaches into the app).

The session holds the settings, the latest state of every check, the advisor's findings for
them, the one door to run checks, and the write plans. It imports no Textual: the UI is a thin
layer that shows it, and tests can build one without an app.
"""

from __future__ import annotations

from collections.abc import AsyncIterator, Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from rosnet_tui.core.config.paths import Paths
from rosnet_tui.core.config.settings_model import Settings, SettingsError
from rosnet_tui.core.procedure import STEP_IDS
from rosnet_tui.core.results import CheckResult
from rosnet_tui.core.saved.settings import load_settings, save_settings
from rosnet_tui.core.saved.ui_state import UiState, local_time
from rosnet_tui.core.wizard.setup_form import Draft, draft_from
from rosnet_tui.core.wizard.steps import STEP_BY_ID, step_for

if TYPE_CHECKING:
    from rosnet_tui.core.advisor import Finding
    from rosnet_tui.core.checks import CheckContext, CheckSpec
    from rosnet_tui.core.net.netinfo import LocalNet
    from rosnet_tui.core.wizard.write_plans import WritePlan

# A check's state in the wizard: the four result statuses plus two of the wizard's own.
NOT_RUN, RUNNING = "not run", "running"


@dataclass(frozen=True)
class UnknownHostKey:
    """A peer's SSH host key that linux.ssh met and nobody has trusted yet (its declared data,
    read for the screen that asks)."""

    peer: str
    host_key: str      # "<type> <base64>"
    fingerprint: str   # SHA256:... ("?" when linux.ssh did not see it)
    address: str       # where the peer's name resolved here ("" when unknown)


def aggregate(states: list[str]) -> str:
    """One state for a step from its checks' states: the worst one wins."""
    if not states:
        return NOT_RUN
    if RUNNING in states:
        return RUNNING
    for s in ("fail", "warn"):
        if s in states:
            return s
    if all(s == NOT_RUN for s in states):
        return NOT_RUN
    if any(s == NOT_RUN for s in states):
        return "partial"
    return "skip" if all(s == "skip" for s in states) else "pass"


def registry_specs(step: str) -> list[CheckSpec]:
    """The registered checks of *step* (the everyday source; tests hand in their own)."""
    from rosnet_tui.core.checks.runner import select

    return select([step])


@dataclass
class WizardSession:
    """The wizard's state and services; the app builds one, the screens are handed it."""

    settings: Settings
    # Where the settings file, the state dir, the hosts file and the rc file are: the same value
    # goes to the runner (make_context) and the write plans.
    paths: Paths = field(default_factory=Paths)
    specs_for: Callable[[str], list[CheckSpec]] = registry_specs
    # Tests hand in their own context factory; None: the runner's everyday context.
    context_factory: Callable[[Settings], CheckContext] | None = None
    # How this machine's network is found out (interfaces, default route): asked once, when
    # something needs it, since saved settings usually say it already.
    detect_net: Callable[[], LocalNet] | None = None
    _detected: LocalNet | None = field(default=None, init=False, repr=False)
    findings: list[Finding] = field(default_factory=list)
    _states: dict[str, tuple[str, CheckResult | None]] = field(default_factory=dict, init=False,
                                                               repr=False)
    _specs: dict[str, list[CheckSpec]] = field(default_factory=dict, init=False, repr=False)
    # What survives the session (ui.json): results as they land, findings, the set-up draft.
    ui_state: UiState = field(init=False, repr=False)
    _restored: dict[str, str] = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        self.ui_state = UiState(self.paths.state_dir)
        for cid, (result, at) in self.ui_state.results().items():
            self._states[cid] = (result.status.value, result)
            self._restored[cid] = at
        if self._restored:
            self.findings = list(self.ui_state.findings())  # type: ignore[arg-type]

    # ------------------------------------------------------------------ settings
    @property
    def detected(self) -> LocalNet:
        """This machine's interface, address and gateway (found out on first use)."""
        if self._detected is None:
            from rosnet_tui.core.net.netinfo import LocalNet, detect_local_net

            self._detected = (self.detect_net or detect_local_net)() or LocalNet()
        return self._detected

    @detected.setter
    def detected(self, net: LocalNet) -> None:
        self._detected = net

    def runtime_settings(self) -> Settings:
        """The saved settings, with what they leave blank filled in from this machine."""
        t = self.settings.this
        if t.local_ip and t.interface:  # nothing to fill in: no need to ask the system
            return self.settings
        from rosnet_tui.core.net.netinfo import with_detected

        return with_detected(self.settings, self.detected)

    def save_settings(self, settings: Settings) -> None:
        """Save *settings*; a file that already says the same is left untouched (not a byte,
        not its time)."""
        try:
            path = self.paths.config_path
            saved = load_settings(path) if path.exists() else None
        except SettingsError:
            saved = None
        if saved is not None and saved == settings:
            settings.saved_at = saved.saved_at     # the file's time: it already said this
        else:
            save_settings(settings, self.paths.config_path)
        self.settings = settings

    # ------------------------------------------------------------------ checks
    def specs(self, step: str) -> list[CheckSpec]:
        """The checks of *step* for the settings' ROS version (ros.* or ros2.*); the registry's
        are imported on first use (the first screen needs only their names)."""
        if step not in self._specs:
            self._specs[step] = self.specs_for(step)
        return [c for c in self._specs[step] if c.applies(self.settings)]

    def specs_loaded(self, step: str) -> bool:
        return step in self._specs or self.specs_for is not registry_specs

    def check_rows(self, step: str) -> list[tuple[str, str]]:
        """(id, title) of every check of *step*, without importing the checks if they are not
        loaded yet (the title is then the id; the screens show short labels anyway)."""
        declared = list(step_for(step, self.settings).check_ids)
        if not self.specs_loaded(step):
            return [(cid, cid) for cid in declared]
        specs = self.specs(step)
        known = {s.id for s in specs}
        return [(s.id, s.title) for s in specs] + [(c, c) for c in declared if c not in known]

    def make_context(self) -> CheckContext:
        """The context of one round of checks (the one door: core.checks.runner)."""
        settings = self.runtime_settings()
        if self.context_factory is not None:
            return self.context_factory(settings)
        from rosnet_tui.core.checks.runner import RunOptions, make_context

        return make_context(settings, RunOptions(paths=self.paths))

    def start_run(self, specs: Iterable[CheckSpec]) -> AsyncIterator[CheckResult]:
        """Start a run of *specs*: they show as running at once; iterating the answer runs them
        through the one door (:func:`rosnet_tui.core.checks.runner.stream`) and keeps each
        verdict as it lands (its state, the findings, the saved UI state) before yielding it.
        Checks stopped before their verdict (the run cancelled) go back to "not run"."""
        specs = list(specs)
        for spec in specs:
            self.set_check_state(spec.id, RUNNING, None)
        return self._run(specs)

    async def _run(self, specs: list[CheckSpec]) -> AsyncIterator[CheckResult]:
        from rosnet_tui.core.checks.runner import stream

        ctx = self.make_context()
        ids = {s.id for s in specs}
        try:
            async for result in stream(specs, ctx):
                ids.discard(result.id)
                self.set_check_state(result.id, result.status.value, result)
                yield result
        finally:
            for cid in ids:  # cancelled before a verdict: back to "not run"
                self.set_check_state(cid, NOT_RUN, None)

    def check_state(self, check_id: str) -> tuple[str, CheckResult | None]:
        return self._states.get(check_id, (NOT_RUN, None))

    def set_check_state(self, check_id: str, state: str, result: CheckResult | None) -> None:
        self._states[check_id] = (state, result)
        self._restored.pop(check_id, None)
        if result is not None or state == NOT_RUN:
            from rosnet_tui.core.advisor import advise  # loaded with the first result

            self.findings = advise(self.latest_results(), self.runtime_settings())
        if result is not None:  # kept at once: a dropped session loses nothing
            self.ui_state.set_result(result, self.findings)

    def restored_at(self, check_id: str) -> str:
        """When the shown result of *check_id* came, if it is from an earlier session ('' if
        it is from this one, or there is none)."""
        at = self._restored.get(check_id)
        return local_time(at) if at else ""

    def latest_results(self) -> dict[str, CheckResult]:
        return {cid: r for cid, (_state, r) in self._states.items() if r is not None}

    def findings_for(self, check_id: str) -> list[Finding]:
        return [f for f in self.findings if check_id in f.check_ids]

    def unknown_host_keys(self) -> list[UnknownHostKey]:
        """Peers whose SSH host key linux.ssh met but nobody has trusted yet, read through the
        check's declared data (rosnet_tui.core.checks.data)."""
        _state, result = self.check_state("linux.ssh")
        if result is None:
            return []
        from rosnet_tui.core.checks.data import view

        peers = view("linux.ssh", result.data).get("peers") or {}
        return [UnknownHostKey(name, d["host_key"], d.get("fingerprint") or "?",
                               d.get("address") or "")
                for name, d in peers.items()
                if isinstance(d, Mapping) and d.get("failure") == "host_key_unknown"
                and d.get("host_key")]

    def modem_said(self) -> list[str]:
        """The Router step's lines for what the modem itself said (router.upnp's declared data;
        nothing before that check ran)."""
        _state, upnp = self.check_state("router.upnp")
        if upnp is None:
            return []
        from rosnet_tui.core.checks.data import view
        from rosnet_tui.core.upnp.forwards import card_lines

        return card_lines(view("router.upnp", upnp.data))

    def step_states(self) -> dict[str, str]:
        out = {}
        for s in STEP_IDS:
            ids = ([c.id for c in self.specs(s)] if self.specs_loaded(s)
                   else list(step_for(s, self.settings).check_ids))
            out[s] = aggregate([self.check_state(cid)[0] for cid in ids])
        return out

    # ------------------------------------------------------------------ configuration text
    def configuration_text(self, step_id: str) -> str:
        """The Configuration pane's Markdown for *step_id*."""
        text = STEP_BY_ID[step_id].configure(self.runtime_settings())
        if step_id == "ros":
            text += "\n\n" + self.sync_text()
        return text

    def sync_text(self) -> str:
        """The address-sync section of the ROS step: each component's last known addresses."""
        from rosnet_tui.core.sync.status import load_status, render_status

        status = load_status(self.paths.state_dir)
        head = "**Address sync.** "
        if status is None:
            return (head + "Not running on this machine. Public addresses change when a modem "
                    "restarts; the sync service then rewrites the hosts entries and "
                    "`ROS_MASTER_URI` on every component by itself. Set it up on each component "
                    "(a `[sync]` table in the settings: a shared folder or a DNS zone), then:"
                    "\n\n```\nrosnet-tui sync install-service\n```")
        lines = "\n".join(render_status(status))
        return head + "What the sync service knows (`rosnet-tui sync status`):\n\n" \
            f"```\n{lines}\n```"

    def router_card_text(self, width: int) -> str:
        """The router card as plain text *width* columns wide: values to type into the modem."""
        from rosnet_tui.core.exposure.router_card import build_router_card, render_router_card

        settings, net = self.runtime_settings(), self.detected
        # This machine's interface facts (MAC, gateway) only when they are of the configured one.
        same = net.local_ip and net.local_ip == settings.this.local_ip
        card = build_router_card(settings, net if same else None)
        return render_router_card(card, markdown=False, width=max(40, width))

    # ------------------------------------------------------------------ writing configuration
    def write_plan(self, step_id: str) -> WritePlan | None:
        """What `w` writes on *step_id* (None: the step writes nothing)."""
        from rosnet_tui.core.wizard.write_plans import write_plan

        return write_plan(step_id, self.runtime_settings(), self.paths)

    def trust_host_key(self, name: str, port: int, host_key: str) -> Path:
        from rosnet_tui.core.ssh.known_hosts import trust_host_key

        return trust_host_key(self.make_context().ssh, name, port, host_key)

    # ------------------------------------------------------------------ where the user was
    def last_step(self) -> str:
        step = self.ui_state.last_step
        return step if step in STEP_IDS else STEP_IDS[0]

    def record_step(self, step: str) -> None:
        self.ui_state.set_last_step(step)  # a convenience: never a reason to fail

    # ------------------------------------------------------------------ the set-up draft
    def draft(self) -> Draft | None:
        """The set-up form of this settings file being filled in and not saved yet, from this or
        an earlier session (never one typed for another file)."""
        return draft_from(self.ui_state.draft(self.paths.config_path))

    def save_draft(self, fields: dict[str, str], peers: list[dict[str, str]]) -> None:
        """Keep the form as typed: *fields* by field id, *peers* as setup_form.peer_row gives."""
        self.ui_state.set_draft(self.paths.config_path, fields, peers)

    def clear_draft(self) -> None:
        self.ui_state.clear_draft(self.paths.config_path)
