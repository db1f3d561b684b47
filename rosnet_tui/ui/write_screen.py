"""Write configuration from the wizard: a diff preview first, then an atomic, undoable apply.

The core does the work (rosnet_tui.core.files.hosts / bashrc / managed_file / privilege); this screen
only shows the preview, asks, and reports. A file this user may not write (``/etc/hosts``) is
written by re-running our own writer under sudo, with the TUI suspended so sudo can ask for the
password in the terminal; the exact command is shown first.
"""

from __future__ import annotations

from rich.text import Text
from textual import on
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical, VerticalScroll
from textual.widgets import Button, Checkbox, Static

from rosnet_tui.core.config.paths import Paths
from rosnet_tui.core.exposure import firewall
from rosnet_tui.core.files import managed_file as mf
from rosnet_tui.core.files import managed_text as mt
from rosnet_tui.core.files import privilege
from rosnet_tui.core.ros import relay_apply
from rosnet_tui.core.upnp.journal import describe as describe_forward
from rosnet_tui.core.wizard.write_plans import Severity, WritePlan
from rosnet_tui.ui.dialog import SCROLL_BINDINGS, ConfirmDialog
from rosnet_tui.ui.widgets import KeyBar


def diff_text(diff: str) -> Text:
    """A unified diff in the terminal's colours, red kept for failures: added lines green,
    removed ones yellow, hunk headers in the accent colour; the marks (+ - @@) say it in words
    too."""
    out = Text()
    for line in diff.splitlines():
        style = ("bold" if line.startswith(("+++", "---")) else
                 "cyan" if line.startswith("@@") else
                 "green" if line.startswith("+") else
                 "yellow" if line.startswith("-") else "")
        out.append(line + "\n", style=style)
    return out


# How each severity the core hands is shown (Textual's notification severities).
SEVERITY = {Severity.INFO: "information", Severity.ERROR: "error"}

# What a write screen dismisses with: the write was made, the user went on to the next preview of
# the sequence without writing (nothing to write here), or None (backed out: the sequence ends).
WRITTEN, NEXT = "written", "next"


class WriteScreen(ConfirmDialog[str | None]):
    """Preview -> confirm -> apply. One of a sequence of previews (the hosts set, then the
    firewall) says where it is ("1 of 2"); Esc ends the whole sequence."""

    BINDINGS = [Binding("escape,q,f10", "cancel", "Cancel", key_display="Esc/q"),
                Binding("y", "apply", "Apply"), Binding("y", "next", "Next"), *SCROLL_BINDINGS]
    CONFIRM_ACTIONS = ("apply", "next")

    def __init__(self, plan: WritePlan, paths: Paths, *, place: tuple[int, int] = (1, 1),
                 next_title: str = "", **kwargs) -> None:
        """*place*: this preview's number and how many the sequence has; *next_title*: the
        title of the one after it ("" for none)."""
        super().__init__(**kwargs)
        self.plan = plan
        self.state_dir = paths.state_dir
        self.undo = privilege.session_command(["undo"], paths)   # the exact command
        self.place = place
        self.next_title = next_title
        self.preview: mf.Preview | None = None
        self.option = False
        self.skipping = False   # nothing to write here: the confirm button goes on to the next

    def compose(self) -> ComposeResult:
        number, count = self.place
        with Vertical(id="write-box"):
            yield Static(self.plan.title + (f" ({number} of {count})" if count > 1 else ""),
                         id="write-title", markup=False)
            yield Static(self.plan.explain, id="write-explain")
            if self.plan.option_label and self.plan.option_count():
                yield Checkbox(self.plan.option_label, id="write-option", compact=True)
            with VerticalScroll(id="write-diff-box"):
                yield Static("", id="write-diff")
            yield Static("", id="write-status", markup=False)
            with Horizontal(id="write-buttons"):
                yield Button(Text("[Apply]"), id="write-apply", variant="primary", compact=True)
                yield Button(Text("[Cancel]"), id="write-cancel", compact=True)
        yield KeyBar()

    def on_mount(self) -> None:
        self.refresh_preview()

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        if action in self.CONFIRM_ACTIONS:   # `y` is Apply or Next, as the button says
            return self.confirm_enabled() and (action == "next") == self.skipping
        return super().check_action(action, parameters)

    def _can_write(self, can: bool) -> None:
        """Apply when there is something to write; else Next when a preview follows."""
        self.skipping = not can and bool(self.next_title)
        self.set_confirm(can or self.skipping, "[Next]" if self.skipping else "[Apply]")

    @on(Checkbox.Changed, "#write-option")
    def _option(self, event: Checkbox.Changed) -> None:
        self.option = event.value
        self.refresh_preview()

    def refresh_preview(self) -> None:
        status = self.query_one("#write-status", Static)
        try:
            self.preview = self.plan.make_preview(self.option)
        except (mt.ManagedFileError, ValueError, OSError) as exc:
            self.preview = None
            self.query_one("#write-diff", Static).update("")
            status.update(f"Cannot write: {exc}" + self._then())
            self._can_write(False)
            return
        p = self.preview
        self.companions = self.plan.companions(self.option)  # more files in the same apply
        diff = "".join([p.diff(), *(c.diff() for c in self.companions)])
        self.query_one("#write-diff", Static).update(
            diff_text(diff) if diff else
            f"{p.path} already holds this configuration: nothing to write.")
        notes = list(p.notes)
        if p.changed and p.needs_privilege and self.plan.sudo_command is not None:
            cmd = privilege.format_command(self.plan.sudo_command(p, self.option))
            notes.append(f"{p.path} needs root: Apply runs, in this terminal, {cmd}")
        elif p.changed:
            notes.append(f"Apply writes {p.path} (backup kept; `{self.undo}` reverts).")
        if self.plan.footnote:
            notes.append(self.plan.footnote)
        notes += [f"Apply writes {c.path} too." for c in self.companions if c.changed]
        status.update("\n".join(notes) + self._then())
        self._can_write(p.changed or any(c.changed for c in self.companions))

    def _then(self) -> str:
        if not self.next_title:
            return ""
        number, count = self.place
        return f"\nThen {number + 1} of {count}: {self.next_title}. Esc stops here."

    @on(Button.Pressed, "#write-cancel")
    def action_cancel(self) -> None:
        self.dismiss(None)

    def action_next(self) -> None:
        self.dismiss(NEXT)

    @on(Button.Pressed, "#write-apply")
    async def _pressed(self) -> None:
        if self.skipping:
            self.action_next()
        else:
            await self.action_apply()

    async def action_apply(self) -> None:
        p = self.preview
        extra = [c for c in getattr(self, "companions", []) if c.changed]
        if p is None or not (p.changed or extra):
            return
        state_dir = self.state_dir
        try:
            if p.needs_privilege:
                if self.plan.sudo_command is None:
                    raise mt.PermissionNeededError(f"this user may not write {p.path}", [p.path])
                argv = self.plan.sudo_command(p, self.option)
                with self.app.suspend():
                    print(f"\nrosnet-tui: running {privilege.format_command(argv)}\n", flush=True)
                    code = privilege.run_privileged(argv, interactive=True)
                if code != 0:
                    self.notify(f"The privileged write did not complete (exit {code}); nothing "
                                "else was changed.", severity="error", timeout=8)
                    self.refresh_preview()
                    return
            elif self.plan.apply is not None:   # not a file (the firewall)
                self.plan.apply(p)
            elif extra:
                mf.apply_previews([p, *extra], state_dir=state_dir, label=self.plan.title)
            else:
                mf.apply_preview(p, state_dir=state_dir)
        except mt.StalePreviewError:
            self.notify("The file changed since this preview: here is the new preview.",
                        severity="warning", timeout=6)
            self.refresh_preview()
            return
        except (mt.ManagedFileError, OSError) as exc:
            self.notify(f"Not written: {exc}", severity="error", timeout=10)
            return
        self.notify(f"Wrote {p.path}. `{self.undo}` reverts it.", timeout=5)
        if self.plan.after_write is not None:   # ROS 2 mutual TLS: CA or pairing (<= 5 s)
            said = await self.plan.after_write()
            if said is not None:
                self.notify(said.text, severity=SEVERITY[said.severity], timeout=10)
        self.dismiss(WRITTEN)


class UndoScreen(ConfirmDialog[bool]):
    """Show what undoing the last apply does, and do it on confirmation."""

    BINDINGS = [Binding("escape,q,f10", "cancel", "Cancel", key_display="Esc/q"),
                Binding("y", "undo", "Undo"), *SCROLL_BINDINGS]
    CONFIRM_ACTIONS = ("undo",)

    def __init__(self, paths: Paths, **kwargs) -> None:
        super().__init__(**kwargs)
        self.state_dir = paths.state_dir
        self.force = privilege.session_command(["undo", "--force"], paths)
        self.plan: mf.UndoPlan | None = None

    def compose(self) -> ComposeResult:
        with Vertical(id="write-box"):
            yield Static("Undo the last write", id="write-title")
            with VerticalScroll(id="write-diff-box"):
                yield Static("", id="write-diff")
            yield Static("", id="write-status", markup=False)
            with Horizontal(id="write-buttons"):
                yield Button(Text("[Undo]"), id="write-apply", variant="primary", compact=True)
                yield Button(Text("[Cancel]"), id="write-cancel", compact=True)
        yield KeyBar()

    def on_mount(self) -> None:
        status = self.query_one("#write-status", Static)
        try:
            self.plan = mf.plan_undo(self.state_dir)
        except mt.ManagedFileError as exc:
            status.update(str(exc))
            self.set_confirm(False)
            return
        diff = self.plan.diff()
        forwards = [(firewall.describe(m) if kind == firewall.KIND else
                     relay_apply.describe(m) if kind == relay_apply.KIND else
                     f"Remove the forward {describe_forward(m)}")
                    for kind, m in self.plan.entry.made()]
        self.query_one("#write-diff", Static).update(diff_text(diff) if diff else
                                                     Text("\n".join(forwards)))
        notes = [f"Changed since by someone else: {c}" for c in self.plan.conflicts]
        if self.plan.conflicts:
            notes.append(f"Undo would lose those changes: run `{self.force}` if you are "
                         "sure.")
            self.set_confirm(False)
        elif self.plan.needs_privilege:
            cmd = privilege.format_command(self._sudo_argv())
            notes.append(f"Needs root: Undo runs, in this terminal, {cmd}")
        status.update("\n".join(notes))

    def _sudo_argv(self) -> list[str]:
        assert self.plan is not None
        return privilege.undo_command(entry_id=self.plan.entry.id,
                                      state_dir=self.state_dir)

    @on(Button.Pressed, "#write-cancel")
    def action_cancel(self) -> None:
        self.dismiss(False)

    @on(Button.Pressed, "#write-apply")
    def action_undo(self) -> None:
        if self.plan is None:
            return
        try:
            if self.plan.needs_privilege:
                argv = self._sudo_argv()
                with self.app.suspend():
                    print(f"\nrosnet-tui: running {privilege.format_command(argv)}\n", flush=True)
                    code = privilege.run_privileged(argv, interactive=True)
                if code != 0:
                    self.notify(f"The privileged undo did not complete (exit {code}).",
                                severity="error", timeout=8)
                    return
            else:
                mf.apply_undo(self.plan)
        except mt.ManagedFileError as exc:
            self.notify(f"Not undone: {exc}", severity="error", timeout=10)
            return
        self.notify("Put the firewall back as it was before the last change."
                    if firewall.KIND in self.plan.entry.kinds() else
                    "Put the relay's router config and unit back."
                    if relay_apply.KIND in self.plan.entry.kinds() else
                    "Removed the forwards of the last change from the modem."
                    if self.plan.entry.kinds() else "Restored the files of the last write.",
                    timeout=5)
        self.dismiss(True)
