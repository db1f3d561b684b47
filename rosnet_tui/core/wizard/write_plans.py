"""What the wizard's ``w`` writes on a step: a preview, an option, the sudo path, the checks after.

A :class:`WritePlan` is plain data built from the settings and the session's
:class:`~rosnet_tui.core.config.paths.Paths`; the UI only shows its preview and asks. Only the Linux
step (the hosts set) and the ROS step (the ROS environment block of ~/.bashrc) write files.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from typing import Any

from rosnet_tui.core import affected
from rosnet_tui.core.config.paths import Paths, default_config_dir
from rosnet_tui.core.config.settings_model import Settings
from rosnet_tui.core.exposure import firewall as fw
from rosnet_tui.core.files import bashrc, hosts, privilege
from rosnet_tui.core.files import managed_file as mf
from rosnet_tui.core.files import managed_text as mt
from rosnet_tui.core.files.managed_write import read_text
from rosnet_tui.core.ros import fleet_tls, pairing, ros2
from rosnet_tui.core.ssh.client_config import jump_hosts_block, ssh_config_previews
from rosnet_tui.core.ssh.options import options_for


class Severity(str, Enum):
    """How a line said after a write is shown: news, or a failure the user must act on."""

    INFO = "info"
    ERROR = "error"


@dataclass(frozen=True)
class Said:
    """A line for the user after a write, with its severity (the UI shows it; it never reads
    the words to guess)."""

    text: str
    severity: Severity = Severity.INFO


@dataclass
class WritePlan:
    """What a write screen needs to preview and apply one write."""

    title: str
    explain: str
    # Build the preview; the flag is the user's answer to the option (e.g. comment ROS_IP lines).
    make_preview: Callable[[bool], mf.Preview]
    option_label: str = ""            # empty: no option
    option_count: Callable[[], int] = lambda: 0
    # The sudo command for a preview that needs privilege (None: privilege cannot help).
    sudo_command: Callable[[mf.Preview, bool], list[str]] | None = None
    after: tuple[str, ...] = ()       # checks to re-run after a write
    footnote: str = ""
    # More files written in the same apply (one undo restores all), for the option's answer.
    companions: Callable[[bool], list[mf.Preview]] = lambda _option: []
    # A write that is not a file (the firewall): applies the preview itself (as root) instead of
    # managed_file; raises ManagedFileError.
    apply: Callable[[Any], object] | None = None
    # The write offered next on the same step, once this one is closed (None: none).
    then: Callable[[], WritePlan | None] | None = None
    # Run after a successful write (ROS 2 mutual TLS: make the CA, or pair with the master);
    # returns a line for the user (None: nothing to say).
    after_write: Callable[[], Awaitable[Said | None]] | None = None


def _read(path: Path, state_dir: Path) -> str | None:
    """A file we write, as text (a write of ours cut short is completed first); None when it
    is missing or cannot be read (the preview then says why)."""
    try:
        return read_text(path, state_dir=state_dir, errors="replace")
    except mt.ManagedFileError:
        return None


def hosts_plan(settings: Settings, paths: Paths) -> WritePlan:
    """Write this component's active hosts set (the Linux step)."""
    profile = settings.this.profile

    def conflicts() -> int:
        return len(hosts.find_hosts_conflicts(_read(paths.hosts_path, paths.state_dir),
                                              settings, profile))

    return WritePlan(
        title=f"Write the '{profile}' hosts set to {paths.hosts_path}",
        explain="Our marked block only; every other line stays. Review the change:",
        make_preview=lambda fix: hosts.preview_hosts(settings, profile, paths.hosts_path,
                                                     fix_conflicts=fix,
                                                     state_dir=paths.state_dir),
        option_label="also comment out other lines that give our names other addresses",
        option_count=conflicts,
        sudo_command=lambda p, fix: privilege.hosts_apply_command(
            profile=profile, config=paths.config_path, digest=p.write_digest,
            hosts_file=paths.hosts_path, state_dir=paths.state_dir, fix_conflicts=fix),
        after=affected.HOSTS,
        then=lambda: firewall_plan(settings, paths))


def firewall_plan(settings: Settings, paths: Paths) -> WritePlan | None:
    """ROS 1 with [ros] security = "firewall": the peers-only nftables table (Linux step, after
    the hosts set). None when the settings do not ask for it."""
    if not fw.wanted(settings):
        return None
    profile = settings.this.profile

    def make(_option: bool) -> fw.FirewallPreview:
        try:
            return fw.preview(settings, profile)
        except fw.FirewallError as exc:
            raise mf.ManagedFileError(str(exc)) from None

    def apply(pv: fw.FirewallPreview) -> None:
        try:
            fw.apply(pv, state_dir=paths.state_dir)
        except fw.FirewallError as exc:
            raise mf.ManagedFileError(str(exc)) from None

    return WritePlan(
        title=f"Load the peers-only firewall (nft table {fw.TABLE})",
        explain="ROS 1: on the forwarded TCP ports (22, the ROS range, the master's port) only "
                "the peers, this machine's LAN, [firewall] allow and this SSH session get in "
                "(below). One nft transaction; no other table is touched. Review it:",
        make_preview=make,
        sudo_command=lambda p, _o: fw.apply_command(config=paths.config_path, profile=profile,
                                                    digest=p.digest, state_dir=paths.state_dir,
                                                    session=p.session),
        apply=apply,
        after=affected.FIREWALL,
        footnote="The sync service keeps the allowed addresses current; `rosnet-tui undo` "
                 "removes the table.")


def ros2_plan(settings: Settings, paths: Paths) -> WritePlan:
    """ROS 2: the ~/.bashrc block and the Zenoh router's config file, in one apply; under
    mutual TLS then the fleet CA (master) or pairing with the master over SSH (member)."""
    def make(client: bool) -> list[mf.Preview]:
        return (ros2.previews(settings, paths.bashrc_path, client=client,
                              state_dir=paths.state_dir)
                + ssh_config_previews(settings, state_dir=paths.state_dir)[0])

    member = not settings.is_master
    return WritePlan(
        title=f"Write the ROS 2 environment to {paths.bashrc_path}",
        explain="A marked block at the end of the file, and the router's own config file "
                f"({ros2.default_router_config_path()})"
                + ("; with the relay, a block at the top of ~/.ssh/config so that `ssh NAME` "
                   "jumps through it" if jump_hosts_block(settings) else "")
                + "; one undo restores them all:",
        make_preview=lambda client: make(client)[0],
        companions=lambda client: make(client)[1:],
        option_label=("no router on this machine: its nodes connect to the master's router in "
                      "client mode") if member else "",
        after=affected.ros2_write(ros2.mtls(settings)),
        after_write=lambda: after_ros2_write(settings),
        footnote="Then start the router: ros2 run rmw_zenoh_cpp rmw_zenohd (the master's first). "
                 "For the shell you are in now: " + "; ".join(ros2.shell_lines(settings)))


async def after_ros2_write(settings: Settings, opts: Any = None) -> Said | None:
    """What the wizard's ``w`` on the ROS step does after writing under mutual TLS (as
    ``ros apply``): the CA and certificate on the master; on a member, pairing over SSH when
    needed. None when nothing was needed."""
    if not ros2.mtls(settings):
        return None
    paths = fleet_tls.tls_paths(default_config_dir())
    try:
        if settings.is_master:
            made = pairing.prepare_master(settings, paths)
            return Said("Made " + "; ".join(made) + ".") if made else None
        if pairing.needs_pairing(settings, paths) is None:
            return None
        res = await pairing.pair_over_ssh(settings, paths, opts or options_for(settings.relay))
    except (fleet_tls.TlsError, OSError) as exc:
        return Said(f"Mutual TLS: {exc}", Severity.ERROR)
    if res.ok:
        return Said(f"{res.detail[:1].upper()}{res.detail[1:]} ({res.seconds:.1f} s).")
    return Said(f"Pairing failed: {res.detail}. Without SSH to the master: `rosnet-tui ros pair "
                "--print-request` here, `--sign` there, `--install` here.", Severity.ERROR)


def ros_plan(settings: Settings, paths: Paths) -> WritePlan:
    """Write the ROS environment block of ~/.bashrc (the ROS step)."""
    if settings.ros2:
        return ros2_plan(settings, paths)

    def ros_ip_lines() -> int:
        return len(bashrc.find_ros_ip_lines(_read(paths.bashrc_path, paths.state_dir)))

    return WritePlan(
        title=f"Write ROS_MASTER_URI to {paths.bashrc_path}",
        explain="A marked block at the end of the file; every other line stays:",
        make_preview=lambda fix: bashrc.preview_bashrc(settings, paths.bashrc_path,
                                                       comment_ros_ip=fix,
                                                       state_dir=paths.state_dir),
        option_label="comment out ROS_IP / ROS_HOSTNAME lines (they break remote networks: a "
                     "node then publishes but cannot subscribe, or the reverse)",
        option_count=ros_ip_lines,
        # ROS 1 refuses [relay]: only a block a ROS 2 apply left in ~/.ssh/config, taken out
        companions=lambda _fix: ssh_config_previews(settings, state_dir=paths.state_dir)[0],
        after=affected.ROS_ENV,
        footnote=f"For the shell you are in now: {bashrc.export_line(settings)}")


PLANS: dict[str, Callable[[Settings, Paths], WritePlan]] = {
    "linux": hosts_plan,
    "ros": ros_plan,
}

def write_plan(step_id: str, settings: Settings, paths: Paths) -> WritePlan | None:
    """The plan of *step_id*, or None when the step writes nothing."""
    build = PLANS.get(step_id)
    return build(settings, paths) if build is not None else None
