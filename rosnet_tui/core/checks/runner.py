"""The one door to run checks: the wizard, every command and the sync service come through here.

A caller says which checks (:func:`select`) and how (:class:`RunOptions`); the door builds the
round's :class:`~rosnet_tui.core.checks.CheckContext` (settings, paths, environment, SSH options,
the shared test-port listeners) and runs the checks concurrently, each under its timeout.
"""

from __future__ import annotations

import asyncio
import os
from collections.abc import AsyncIterator, Callable, Iterable, Mapping
from dataclasses import dataclass, field, replace

from rosnet_tui.core.checks import (
    REGISTRY,
    CheckContext,
    CheckSpec,
    checks_for,
    load_builtin_checks,
    run_checks,
)
from rosnet_tui.core.config.paths import Paths
from rosnet_tui.core.config.settings_model import Settings
from rosnet_tui.core.files.managed_write import settle
from rosnet_tui.core.net.http import load_requests
from rosnet_tui.core.results import CheckResult
from rosnet_tui.core.ros import fleet_tls
from rosnet_tui.core.ssh.connection import load_paramiko
from rosnet_tui.core.ssh.options import SshOptions, relay_route
from rosnet_tui.core.ssh.pool import SshPool


@dataclass(frozen=True)
class RunOptions:
    """How to run a round of checks; every field has the everyday default."""

    timeout_s: float | None = None          # None: [checks] timeout_s of the settings
    paths: Paths = field(default_factory=Paths)  # the hosts file, ~/.bashrc, the state dir
    env: Mapping[str, str] | None = None    # None: this process's environment
    upnp: bool = True                       # isp.cgnat may ask the modem over UPnP
    ssh: SshOptions = field(default_factory=SshOptions)
    ssh_pool: SshPool | None = None         # None: a new pool for the round (see prestart_ssh)


def select(steps: Iterable[str] | None = None, ids: Iterable[str] | None = None,
           settings: Settings | None = None) -> list[CheckSpec]:
    """The checks of *steps* (every step when both are None), or exactly *ids* (unknown ids are
    left out), in registry order.

    With *settings*, a step's list follows its ROS version (ros.* for 1, ros2.* for 2); ids asked
    for by name are kept, and a check of the other version then skips, saying why.
    """
    if ids is None:
        return checks_for(steps, settings)
    load_builtin_checks()
    wanted = set(ids)
    return [s for s in checks_for(None) if s.id in wanted]


def preload() -> None:
    """Import what a round imports as it goes (the checks, paramiko, requests, cryptography's
    certificates), for a process that is to run rounds later without waiting for them (the
    command line's warm process)."""
    load_builtin_checks()
    load_paramiko()
    load_requests()
    fleet_tls.preload()


def unknown_ids(ids: Iterable[str]) -> list[str]:
    """The ids in *ids* that no check is registered under."""
    load_builtin_checks()
    return [i for i in ids if i not in REGISTRY]


def make_context(settings: Settings, options: RunOptions | None = None) -> CheckContext:
    """The context of one round (the only place the product builds one)."""
    o = options or RunOptions()
    timeout = float(o.timeout_s if o.timeout_s is not None else settings.checks.timeout_s)
    kw: dict = {"settings": settings, "timeout_s": timeout,
                "env": dict(os.environ if o.env is None else o.env),
                "upnp": o.upnp, "ssh_options": o.ssh, "ssh_pool": o.ssh_pool or SshPool(),
                "paths": o.paths}
    ctx = CheckContext(**kw)
    # The ROS checks (and the programs they start here) open ~/.bashrc themselves: a write of
    # ours cut short is completed first (linux.hosts reads through read_bytes itself).
    settle(ctx.paths.bashrc_path, state_dir=ctx.paths.state_dir, wait_s=min(2.0, timeout / 2))
    return ctx


def prestart_ssh(settings: Settings, options: RunOptions | None = None,
                 steps: Iterable[str] | None = None) -> RunOptions:
    """*options* with the round's SSH connections already being made, when the checks of
    *steps* (every step when None) use the peers: the handshakes overlap whatever the caller
    still does before the round starts (``rosnet-tui check`` imports the checks)."""
    o = options or RunOptions()
    if steps is not None and not set(steps) & {"router", "linux", "ros"}:
        return o
    timeout = float(o.timeout_s if o.timeout_s is not None else settings.checks.timeout_s)
    pool = o.ssh_pool or SshPool()
    pool.prestart(replace(o.ssh, timeout_s=timeout, relay=relay_route(settings.relay)),
                  [p for p in settings.peers if p.ssh_user])
    return replace(o, ssh_pool=pool)


async def stream(specs: Iterable[CheckSpec], ctx: CheckContext) -> AsyncIterator[CheckResult]:
    """Run *specs* concurrently in *ctx*; yield each result as it lands (the wizard's way)."""
    async for result in run_checks(list(specs), ctx):
        yield result


def run_now(settings: Settings, specs: Iterable[CheckSpec], options: RunOptions | None = None,
            on_result: Callable[[CheckResult, int, int], None] | None = None
            ) -> list[CheckResult]:
    """Run *specs* to the end from synchronous code; results in *specs* order.

    *on_result(result, done, total)* is called as each verdict lands (progress lines).
    """
    specs = list(specs)
    ctx = make_context(settings, options)

    async def go() -> dict[str, CheckResult]:
        got: dict[str, CheckResult] = {}
        async for r in run_checks(specs, ctx):
            got[r.id] = r
            if on_result is not None:
                on_result(r, len(got), len(specs))
        return got

    got = asyncio.run(go())
    return [got[s.id] for s in specs if s.id in got]
