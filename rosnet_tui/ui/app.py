"""The wizard: a thin Textual layer over rosnet_tui.core."""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from textual.app import App
from textual.binding import Binding

from rosnet_tui.core.checks import CheckContext, CheckSpec, checks_for
from rosnet_tui.core.netinfo import LocalNet, detect_local_net, with_detected
from rosnet_tui.core.results import CheckResult
from rosnet_tui.core.settings import Settings, atomic_write_text, default_state_dir, save_settings
from rosnet_tui.core.steps import STEP_BY_ID, STEPS
from rosnet_tui.ui.setup_screen import SetupScreen
from rosnet_tui.ui.step_screen import StepScreen
from rosnet_tui.ui.widgets import NOT_RUN, StepBar, aggregate

if TYPE_CHECKING:
    from rosnet_tui.core.advisor import Finding


@dataclass
class AppDeps:
    """What the app needs from the outside world; tests hand in their own."""

    config_path: Path
    settings: Settings
    state_dir: Path = field(default_factory=default_state_dir)
    detect_net: Callable[[], LocalNet] = detect_local_net
    specs_for: Callable[[str], list[CheckSpec]] = lambda step: checks_for([step])
    make_context: Callable[[Settings], CheckContext] | None = None
    open_setup: bool = False
    hosts_path: Path = Path("/etc/hosts")
    bashrc_path: Path = field(default_factory=lambda: Path.home() / ".bashrc")


class RosnetApp(App[int]):
    CSS_PATH = "app.tcss"
    TITLE = "rosnet-tui"
    ENABLE_COMMAND_PALETTE = False

    BINDINGS = [
        Binding("1", "goto('isp')", "ISP", show=False),
        Binding("2", "goto('router')", "Router", show=False),
        Binding("3", "goto('linux')", "Linux", show=False),
        Binding("4", "goto('ros')", "ROS", show=False),
        Binding("b", "back", "Back"),
        Binding("n", "next", "Next"),
        Binding("a", "advisor", "Advisor"),
        Binding("s", "setup", "Set-up"),
        Binding("question_mark", "help", "Help", key_display="?"),
        Binding("q", "leave", "Quit"),
    ]

    def __init__(self, deps: AppDeps) -> None:
        super().__init__()
        self.deps = deps
        self.settings = deps.settings
        self.detected = LocalNet()
        self._states: dict[str, tuple[str, CheckResult | None]] = {}
        self._specs: dict[str, list[CheckSpec]] = {}
        self.findings: list[Finding] = []
        self.current_step = self._load_ui_state().get("last_step", "isp")
        if self.current_step not in {s.id for s in STEPS}:
            self.current_step = "isp"

    # ------------------------------------------------------------------ start-up
    def on_mount(self) -> None:
        self.detected = self.deps.detect_net()
        self.set_class(self.size.width >= self.WIDE_AT, "wide")
        for step in STEPS:
            specs = self.deps.specs_for(step.id)
            self._specs[step.id] = specs
            self.install_screen(StepScreen(step, specs), name=f"step-{step.id}")
        self.push_screen(f"step-{self.current_step}")
        if self.deps.open_setup or not self.settings.complete:
            self.action_setup()

    WIDE_AT = 110  # columns from which configuration and verification sit side by side

    def on_resize(self, event) -> None:
        self.set_class(event.size.width >= self.WIDE_AT, "wide")

    # ------------------------------------------------------------------ shared check state
    def check_state(self, check_id: str) -> tuple[str, CheckResult | None]:
        return self._states.get(check_id, (NOT_RUN, None))

    def set_check_state(self, check_id: str, state: str, result: CheckResult | None) -> None:
        self._states[check_id] = (state, result)
        if result is not None or state == NOT_RUN:
            from rosnet_tui.core.advisor import advise  # loaded with the first result

            self.findings = advise(self.latest_results(), self.runtime_settings())

    def latest_results(self) -> dict[str, CheckResult]:
        return {cid: r for cid, (_state, r) in self._states.items() if r is not None}

    def findings_for(self, check_id: str) -> list[Finding]:
        return [f for f in self.findings if check_id in f.check_ids]

    def step_states(self) -> dict[str, str]:
        return {s.id: aggregate([self.check_state(c.id)[0] for c in self._specs.get(s.id, [])])
                for s in STEPS}

    def make_context(self) -> CheckContext:
        settings = self.runtime_settings()
        if self.deps.make_context is not None:
            return self.deps.make_context(settings)
        return CheckContext(settings=settings, timeout_s=settings.checks.timeout_s,
                            env=dict(os.environ), state_dir=self.deps.state_dir,
                            hosts_path=self.deps.hosts_path, bashrc_path=self.deps.bashrc_path)

    def runtime_settings(self) -> Settings:
        """The saved settings, with what they leave blank filled in from this machine."""
        return with_detected(self.settings, self.detected)

    # ------------------------------------------------------------------ settings
    def save_settings(self, settings: Settings) -> None:
        save_settings(settings, self.deps.config_path)
        self.settings = settings
        for step in STEPS:
            screen = self.get_screen(f"step-{step.id}")
            if isinstance(screen, StepScreen) and screen.is_mounted:
                screen.refresh_config()

    # ------------------------------------------------------------------ ui state
    def _ui_state_path(self) -> Path:
        return self.deps.state_dir / "ui.json"

    def _load_ui_state(self) -> dict:
        try:
            data = json.loads(self._ui_state_path().read_text(encoding="utf-8"))
            return data if isinstance(data, dict) else {}
        except (OSError, ValueError):
            return {}

    def record_step_progress(self) -> None:
        try:
            atomic_write_text(self._ui_state_path(),
                              json.dumps({"last_step": self.current_step}) + "\n")
        except OSError:
            pass  # remembering the step is a convenience, never a reason to fail

    # ------------------------------------------------------------------ navigation
    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        # Single letters act on the step screens only (elsewhere they are typed); Ctrl+Q always quits.
        if action in ("goto", "back", "next", "setup", "leave", "advisor"):
            return isinstance(self.screen, StepScreen)
        return True

    def action_goto(self, step_id: str) -> None:
        if step_id == self.current_step and isinstance(self.screen, StepScreen):
            return
        self.current_step = step_id
        self.switch_screen(f"step-{step_id}")
        self.record_step_progress()

    def _step_index(self) -> int:
        return next(i for i, s in enumerate(STEPS) if s.id == self.current_step)

    def action_next(self) -> None:
        i = self._step_index()
        if i + 1 < len(STEPS):
            self.action_goto(STEPS[i + 1].id)
        else:
            self.notify("This is the last step.", timeout=3)

    def action_back(self) -> None:
        i = self._step_index()
        if i > 0:
            self.action_goto(STEPS[i - 1].id)
        else:
            self.notify("This is the first step.", timeout=3)

    def on_step_bar_selected(self, message: StepBar.Selected) -> None:
        self.action_goto(message.step_id)

    def action_setup(self) -> None:
        def done(saved: bool | None) -> None:
            if saved:
                self.notify(f"Settings saved to {self.deps.config_path}", timeout=4)

        self.push_screen(SetupScreen(self.detected), done)

    async def action_leave(self) -> None:
        await self.action_quit()

    def action_advisor(self) -> None:
        from rosnet_tui.ui.advisor_screen import AdvisorScreen

        def done(step_id: str | None) -> None:
            if step_id:
                self.action_goto(step_id)

        self.push_screen(AdvisorScreen(), done)

    # ------------------------------------------------------------------ writing configuration
    def configuration_text(self, step_id: str) -> str:
        """The Configuration pane's Markdown for *step_id*."""
        text = STEP_BY_ID[step_id].configure(self.runtime_settings())
        if step_id == "ros":
            text += "\n\n" + self.sync_text()
        return text

    def sync_text(self) -> str:
        """The address-sync section of the ROS step: each component's last known addresses."""
        from rosnet_tui.core.sync.status import load_status, render_status

        status = load_status(self.deps.state_dir)
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
        from rosnet_tui.core.router_card import build_router_card, render_router_card

        settings, net = self.runtime_settings(), self.detected
        # This machine's interface facts (MAC, gateway) only when they are of the configured one.
        same = net.local_ip and net.local_ip == settings.this.local_ip
        card = build_router_card(settings, net if same else None)
        return render_router_card(card, markdown=False, width=max(40, width))

    def write_plan(self, step_id: str):
        """What `w` writes on *step_id*: the hosts set (Linux) or the ROS block (ROS)."""
        from rosnet_tui.core import bashrc, hosts, privilege
        from rosnet_tui.ui.write_screen import WritePlan

        settings = self.runtime_settings()
        deps = self.deps
        if step_id == "linux":
            profile = settings.this.profile

            def conflicts() -> int:
                text = deps.hosts_path.read_text(errors="replace") if deps.hosts_path.exists() else None
                return len(hosts.find_hosts_conflicts(text, settings, profile))

            return WritePlan(
                title=f"Write the '{profile}' hosts set to {deps.hosts_path}",
                explain="Our marked block only; every other line stays. Review the change:",
                make_preview=lambda fix: hosts.preview_hosts(settings, profile, deps.hosts_path,
                                                             fix_conflicts=fix),
                option_label="also comment out other lines that give our names other addresses",
                option_count=conflicts,
                sudo_command=lambda p, fix: privilege.hosts_apply_command(
                    profile=profile, config=deps.config_path, digest=p.digest,
                    hosts_file=deps.hosts_path, state_dir=deps.state_dir, fix_conflicts=fix),
                after=("linux.hosts", "linux.resolve"))
        if step_id == "ros":
            def ros_ip_lines() -> int:
                path = deps.bashrc_path
                return len(bashrc.find_ros_ip_lines(
                    path.read_text(errors="replace") if path.exists() else None))

            return WritePlan(
                title=f"Write ROS_MASTER_URI to {deps.bashrc_path}",
                explain="A marked block at the end of the file; every other line stays:",
                make_preview=lambda fix: bashrc.preview_bashrc(settings, deps.bashrc_path,
                                                               comment_ros_ip=fix),
                option_label="comment out ROS_IP / ROS_HOSTNAME lines (they break remote "
                             "networks: a node then publishes but cannot subscribe, or the "
                             "reverse)",
                option_count=ros_ip_lines,
                after=("ros.env",),
                footnote=f"For the shell you are in now: {bashrc.export_line(settings)}")
        return None

    def action_help(self) -> None:
        from rosnet_tui.ui.help_screen import HelpScreen

        if not isinstance(self.screen, HelpScreen):
            self.push_screen(HelpScreen())
