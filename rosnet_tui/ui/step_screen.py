"""One generic screen renders any of the four steps: Expected outcome, Configuration, Verification."""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator
from typing import TYPE_CHECKING

from textual import work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Container, VerticalScroll
from textual.screen import Screen
from textual.widgets import Static

from rosnet_tui.core import affected
from rosnet_tui.core.wizard.session import WizardSession
from rosnet_tui.core.wizard.steps import Step, step_for
from rosnet_tui.ui.messages import Navigate
from rosnet_tui.ui.textual_compat import installed_screens
from rosnet_tui.ui.widgets import CheckList, KeyBar, PlainHeader, StepBar

if TYPE_CHECKING:
    from rosnet_tui.core.checks import CheckSpec
    from rosnet_tui.core.results import CheckResult


def _markdown(text: str):
    """The configuration text as one renderable: drawn in a single frame, unlike a widget per
    block, which keeps a step's first visit quick over a slow link (bench row 5)."""
    from rosnet_tui.ui.mdlite import render

    return render(text)


class StepScreen(Screen):
    """A step of the procedure, with its checks run live in a worker."""

    AUTO_FOCUS = "#check-table"  # focused as the screen is shown: drawn once, already focused

    BINDINGS = [
        Binding("r", "run_checks", "Run"),
        Binding("R", "run_one", "Re-run one", show=False),
        Binding("c", "cancel_checks", "Cancel", show=False),
        Binding("e", "toggle_evidence", "Evidence"),
        Binding("w", "write", "Write"),
        Binding("u", "undo", "Undo write", show=False),
        Binding("m", "map_forward", "Modem"),  # the Router step only (check_action)
        Binding("k", "trust_key", "Review host key", show=False),
        Binding("g", "go_finding", "Go to cause", show=False),
        Binding("z", "zoom", "Zoom pane", show=False),
    ]

    def __init__(self, step: Step, session: WizardSession, **kwargs) -> None:
        super().__init__(**kwargs)
        self.step = step
        self.session = session
        self.config_source = ""  # the Markdown the Configuration pane shows

    def compose(self) -> ComposeResult:
        self.step = step_for(self.step.id, self.session.settings)  # settings may have changed
        yield PlainHeader()
        yield StepBar(self.step.id, id="step-bar")
        # The panes sit on the screen itself (no container around them: one widget less to
        # style and lay out before the first frame).
        with VerticalScroll(id="expected-pane", classes="pane") as expected:
            expected.border_title = f"{self.step.number} {self.step.title}: expected outcome"
            yield Static(self.step.expected, id="expected-text")
        with Container(id="lower"):
            with VerticalScroll(id="config-pane", classes="pane") as config:
                config.border_title = "Configuration"
                if self.step.id == "router":  # the card: plain text, fit to the pane
                    yield Static("", id="router-card", markup=False)
                else:
                    self.config_source = self.session.configuration_text(self.step.id)
                    yield Static(_markdown(self.config_source), id="config-text")
            # The check list is the Verification pane itself (one container less).
            verify = CheckList(self.session.check_rows(self.step.id),
                               advice=self.session.findings_for, id="verify-pane", classes="pane")
            verify.border_title = "Verification"
            yield verify
        yield KeyBar()

    def on_mount(self) -> None:
        if self.step.id == "router":
            self.call_after_refresh(self._render_card)
        self.title = "rosnet-tui"
        self.refresh_subtitle()
        self._sync_results()

    def on_screen_resume(self) -> None:
        self.query_one(StepBar).current = self.step.id
        self._sync_results()
        self.refresh_subtitle()

    def refresh_subtitle(self) -> None:
        t = self.session.settings.this
        self.sub_title = f"{t.name or '?'} · {t.role} · {t.connection} · {t.profile}"

    def refresh_config(self) -> None:
        """Settings changed: re-render the tailored configuration (and, when the ROS version
        changed, the step's list of checks)."""
        self.step = step_for(self.step.id, self.session.settings)
        self.query_one("#expected-text", Static).update(self.step.expected)
        rows = self.session.check_rows(self.step.id)
        if [cid for cid, _title in rows] != list(self.query_one(CheckList).rows):
            self.run_worker(self._replace_check_list(rows), exclusive=False)
        if self.step.id == "router":
            self._render_card()
        else:
            self.config_source = self.session.configuration_text(self.step.id)
            self.query_one("#config-text", Static).update(_markdown(self.config_source))
        self.refresh_subtitle()

    async def _replace_check_list(self, rows: list[tuple[str, str]]) -> None:
        """The ROS version changed: a new list of checks (the old one removed first: the new
        one takes its ids)."""
        old = self.query_one(CheckList)
        parent = old.parent
        had_focus = self.focused is not None and (self.focused is old
                                                  or old in self.focused.ancestors)
        await old.remove()
        if parent is not None:
            new = CheckList(rows, advice=self.session.findings_for, id="verify-pane",
                            classes="pane")
            new.border_title = old.border_title
            await parent.mount(new)
            if had_focus:
                self.query_one("#check-table").focus()
            self._sync_results()

    def _render_card(self) -> None:
        pane = self.query_one("#config-pane")
        width = pane.scrollable_content_region.width or 76
        text = self.session.router_card_text(width - 3)
        said = self.session.modem_said()  # the modem's own word, if asked
        self.query_one("#router-card", Static).update(("\n".join(said) + "\n\n" if said else "")
                                                      + text)

    def on_resize(self) -> None:
        if self.step.id == "router":
            self.call_after_refresh(self._render_card)

    def _sync_results(self) -> None:
        """Show the latest known state of every check and every step (shared through the app)."""
        session = self.session
        checks = self.query_one(CheckList)
        earlier = set()
        for cid in checks.rows:
            state, result = session.check_state(cid)
            at = session.restored_at(cid)
            if at:
                earlier.add(at)
            row = checks.rows[cid]
            if row.state != state or row.result is not result or row.at != at:
                checks.set_state(cid, state, result, at)
        verify = self.query_one("#verify-pane")
        title = "Verification" + (f" (results of {min(earlier)}: r runs again)" if earlier else "")
        if verify.border_title != title:
            verify.border_title = title
        bar = self.query_one(StepBar)
        for step_id, state in session.step_states().items():
            bar.set_state(step_id, state)

    @property
    def specs(self) -> list[CheckSpec]:
        """The step's checks, loaded when first run; the list gains their full titles then."""
        specs = self.session.specs(self.step.id)
        if self.is_mounted:
            self.query_one(CheckList).set_titles(self.session.check_rows(self.step.id))
        return specs

    # ------------------------------------------------------------------ actions
    def action_run_checks(self) -> None:
        self.run_specs(self.specs)

    def action_run_one(self) -> None:
        cid = self.query_one(CheckList).highlighted_id
        spec = next((s for s in self.specs if s.id == cid), None)
        if spec is not None:
            self.run_specs([spec])

    def action_cancel_checks(self) -> None:
        """Cancel the checks running on any step (they may have been started elsewhere)."""
        steps = []
        for screen in self.app.screen_stack + installed_screens(self.app):
            if isinstance(screen, StepScreen) and screen.is_mounted and screen not in steps:
                if screen.workers.cancel_group(screen, "checks"):
                    steps.append(screen)
        if steps:
            names = ", ".join(f"{s.step.number} {s.step.title}" for s in steps)
            self.notify(f"Cancelled the checks of {names}.", timeout=3)
        else:
            self.notify("No checks are running.", timeout=3)

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        if action == "write":
            return self.step.id in ("linux", "ros")
        if action == "trust_key":
            return self.step.id == "linux"
        if action == "map_forward":
            return self.step.id == "router"
        return True

    def action_map_forward(self) -> None:
        """Let the modem forward what this component needs (UPnP IGD, PCP, NAT-PMP)."""
        from rosnet_tui.ui.map_screen import MapScreen

        def done(mapped: bool | None) -> None:
            if mapped:
                self.run_specs([s for s in self.specs if s.id in affected.FORWARD])

        settings = self.session.runtime_settings()
        self.app.push_screen(MapScreen(settings, self.session.paths.state_dir,
                                       float(settings.checks.timeout_s)), done)

    def action_write(self) -> None:
        plan = self.session.write_plan(self.step.id)
        if plan is None:
            return
        plans = [plan]   # the writes offered one after the other (the hosts set, the firewall)
        while plans[-1].then is not None and len(plans) < 5:   # a short chain; bounded anyway
            following = plans[-1].then()
            if following is None:
                break
            plans.append(following)
        self._offer_write(plans, 0)

    def _offer_write(self, plans: list, index: int) -> None:
        """Preview and apply plans[index], then offer the next one; backing out of any preview
        ends the sequence (nothing more is offered, nothing more written)."""
        from rosnet_tui.ui.write_screen import NEXT, WRITTEN, WriteScreen

        plan = plans[index]
        last = index + 1 == len(plans)

        def done(outcome: str | None) -> None:
            if outcome == WRITTEN:
                self.run_specs([s for s in self.specs if s.id in plan.after])
            if outcome in (WRITTEN, NEXT) and not last:
                self._offer_write(plans, index + 1)

        self.app.push_screen(WriteScreen(plan, self.session.paths,
                                         place=(index + 1, len(plans)),
                                         next_title="" if last else plans[index + 1].title), done)

    def action_trust_key(self) -> None:
        from rosnet_tui.ui.trust_screen import TrustKeyScreen

        pending = self.session.unknown_host_keys()
        if not pending:
            self.notify("No unknown SSH host key to review (run the Linux checks first).",
                        timeout=4)
            return
        key = pending[0]
        name = key.peer
        peer = self.session.settings.peer(name)
        port = peer.ssh_port if peer else 22

        def done(trust: bool | None) -> None:
            if not trust:
                self.notify(f"Not trusted: SSH checks to {name} stay refused.", timeout=5)
                return
            try:
                path = self.session.trust_host_key(name, port, key.host_key)
            except (ValueError, OSError) as exc:
                self.notify(f"Not written: {exc}", severity="error", timeout=8)
                return
            self.notify(f"Trusted {name}'s key ({path}).", timeout=5)
            self.run_specs([s for s in self.specs if s.id.startswith("linux.")])

        self.app.push_screen(TrustKeyScreen(name, port, key.host_key, key.fingerprint,
                                            key.address, peer.ssh_user if peer else ""),
                             done)

    def action_undo(self) -> None:
        from rosnet_tui.ui.write_screen import UndoScreen

        def done(undone: bool | None) -> None:
            if undone:
                self.run_specs([s for s in self.specs if s.id in affected.UNDO])

        self.app.push_screen(UndoScreen(self.session.paths), done)

    def action_go_finding(self) -> None:
        """Go back to the step that the highlighted check's first finding points to."""
        cid = self.query_one(CheckList).highlighted_id
        for f in self.session.findings_for(cid) if cid else []:
            if f.goto_step and f.severity in ("fail", "warn"):
                if f.goto_step == self.step.id:
                    self.notify("The cause is on this step: see the configuration above.",
                                timeout=4)
                else:
                    self.post_message(Navigate(f.goto_step))
                return
        self.notify("No finding points elsewhere for this check.", timeout=3)

    def action_toggle_evidence(self) -> None:
        self.query_one(CheckList).toggle_evidence()

    def on_check_list_evidence_toggled(self, message: CheckList.EvidenceToggled) -> None:
        self.set_class(message.shown, "-evidence")
        if message.shown:  # the evidence names the check by its full title: load the checks
            self.specs  # noqa: B018
            self.query_one(CheckList).refresh_evidence()

    def action_zoom(self) -> None:
        """Zoom the focused pane (the evidence box, or the pane holding the focus); again to
        restore."""
        if self.maximized is not None:
            self.minimize()
            return
        node = self.focused
        while node is not None and not (node.has_class("pane") or node.has_class("zoomable")):
            node = node.parent  # type: ignore[assignment]
        if node is None:
            node = self.query_one("#verify-pane")
        self.maximized = node  # containers refuse Screen.maximize(); the property does it

    def run_specs(self, specs: list[CheckSpec]) -> None:
        if not specs:
            self.notify("This step has no checks registered yet.", severity="warning")
            return
        results = self.session.start_run(specs)
        self._sync_results()
        self._run_worker(results)

    @work(exclusive=True, exit_on_error=False, group="checks")
    async def _run_worker(self, results: AsyncIterator[CheckResult]) -> None:
        try:
            async with contextlib.aclosing(results):
                async for result in results:
                    self._sync_results()
                    if result.id == "router.upnp":
                        self._render_card()
        finally:
            self._sync_results()
        for key in self.session.unknown_host_keys():
            self.notify(f"{key.peer} has an SSH host key this machine does not know yet. Press k "
                        "to compare its fingerprint and decide.", severity="warning", timeout=12)
