"""The live checks of each step: a registry of small async functions, each under a timeout.

A check is ``async def check(ctx: CheckContext) -> Outcome``, registered with :func:`check`.
:func:`run_checks` runs a selection concurrently and yields each result as it lands; a check that
raises or overruns its timeout becomes a ``fail`` result, never an exception.
"""

from __future__ import annotations

import asyncio
import functools
import time
from collections.abc import AsyncIterator, Awaitable, Callable, Iterable
from dataclasses import dataclass, field, replace
from typing import Any

from rosnet_tui.core.checks import data as data_decl
from rosnet_tui.core.config.paths import Paths
from rosnet_tui.core.config.settings_model import Settings
from rosnet_tui.core.net.listener import ListenerPool
from rosnet_tui.core.procedure import STEP_IDS
from rosnet_tui.core.results import CheckResult, Outcome, Status
from rosnet_tui.core.ssh.options import SshOptions, relay_route


@dataclass
class CheckContext:
    """Everything a check may use in one round. Built by :mod:`rosnet_tui.core.checks.runner`
    (the one door every caller goes through); tests build one pointed at the network lab."""

    settings: Settings
    timeout_s: float = 3.0
    # The hosts file, ~/.bashrc and the state dir the checks read (the session's, in the wizard).
    paths: Paths = field(default_factory=Paths)
    env: dict[str, str] = field(default_factory=dict)
    # Results of checks that already ran in this round, by id (for checks that build on others).
    results: dict[str, CheckResult] = field(default_factory=dict)
    # What the SSH layer needs (keys folder, known_hosts files, agent); its timeout is ours.
    ssh_options: SshOptions = field(default_factory=SshOptions)
    # isp.cgnat may ask the modem over UPnP (SSDP multicast on the LAN); tests outside the lab
    # turn it off so nothing leaves the machine.
    upnp: bool = True
    # Our own test-port listeners, shared by the checks of a round (router.*, linux.chat_in);
    # each is bound only while a check holds it.
    listeners: ListenerPool = field(default_factory=ListenerPool)
    # One SSH connection per peer for the round (an SshPool; None: one per session). The runner
    # gives every round one; run_checks closes it when the round ends.
    ssh_pool: Any = None
    # The round's peer agents (a core.peer.peer_agent.PeerAgents, made by the first check that needs
    # one; None: none yet): one program per peer serving every probe; closed with the round.
    peer_agents: Any = None
    # The ids of the checks this round runs (run_checks sets it): a check that must not overlap
    # another (ros2.link's bursts after the pub/sub checks) knows whether to wait for it.
    round_ids: frozenset[str] = frozenset()

    async def after(self, ids: Iterable[str], until: float) -> None:
        """Wait, until the monotonic time *until* at the latest, for those of *ids* this round
        runs to end: a check whose work would slow theirs goes after them."""
        wanted = [c for c in ids if c in self.round_ids]
        while time.monotonic() < until and any(c not in self.results for c in wanted):
            await asyncio.sleep(0.01)     # (a look costs nothing: 10 ms late at most)

    @property
    def ssh(self) -> SshOptions:
        """The SSH options with this round's timeout, its shared connections and the relay of
        the settings (the jump host to the peers with a tunnel there)."""
        o = self.ssh_options
        route = relay_route(self.settings.relay)
        if o.timeout_s == self.timeout_s and o.pool is self.ssh_pool and o.relay == route:
            return o
        return replace(o, timeout_s=self.timeout_s, pool=self.ssh_pool, relay=route)


CheckFunc = Callable[[CheckContext], Awaitable[Outcome]]


@dataclass(frozen=True)
class CheckSpec:
    id: str
    step: str
    title: str
    func: CheckFunc
    # Seconds this check may take, as a multiple of the context's timeout (some do several probes).
    timeout_factor: float = 1.0
    # The ROS version the check belongs to (1: roscore, 2: rmw_zenoh); None: every version.
    ros: int | None = None
    # A settings table whose ``enabled`` must be true for the check to apply ("rosbridge");
    # None: no switch.
    switch: str | None = None

    def switched_off(self, settings: Settings) -> bool:
        return self.switch is not None and getattr(getattr(settings, self.switch, None),
                                                   "enabled", False) is not True

    def applies(self, settings: Settings) -> bool:
        """Whether this check belongs to *settings*' ROS version ([ros] version) and its switch,
        if it has one, is on."""
        if self.switched_off(settings):
            return False
        return self.ros is None or self.ros == settings.ros.version

    def not_applicable(self, settings: Settings) -> str:
        """Why the check is skipped under *settings* (the SKIP result's summary)."""
        if self.switched_off(settings) and self.switch == "relay":
            return "skipped: no relay in the settings ([relay] host)"
        if self.switched_off(settings) and self.switch == "relay":
            return "skipped: no relay in the settings ([relay] host is not set)"
        if self.switched_off(settings):
            return (f"skipped: [{self.switch}] enabled = false in the settings (set it to true "
                    "to check this)")
        other = {1: "ROS 1 (roscore)", 2: "ROS 2 over rmw_zenoh"}
        return (f"skipped: this check is for {other.get(self.ros or 0, '?')}, and the settings say "
                f"{other.get(settings.ros.version, '?')} ([ros] version = {settings.ros.version})")


REGISTRY: dict[str, CheckSpec] = {}


def check(id: str, step: str, title: str, timeout_factor: float = 1.0, ros: int | None = None,
          switch: str | None = None) -> Callable[[CheckFunc], CheckFunc]:
    """Register a check function under *id* for *step* (*ros*: only for that ROS version;
    *switch*: only when that settings table is enabled)."""
    if step not in STEP_IDS:
        raise ValueError(f"unknown step {step!r}")

    def deco(func: CheckFunc) -> CheckFunc:
        REGISTRY[id] = CheckSpec(id, step, title, func, timeout_factor, ros, switch)
        return func

    return deco


@functools.cache
def _builtin_modules() -> tuple[str, ...]:
    """The modules that register the built-in checks, in their order (by name); looked up once
    (checks_for asks on every step shown)."""
    import pkgutil

    return tuple(sorted(f"{__name__}.{m.name}" for m in pkgutil.iter_modules(__path__)
                        if not m.name.startswith("_")))


def load_builtin_checks() -> None:
    """Import the modules that register the built-in checks (idempotent)."""
    import importlib

    for name in _builtin_modules():
        importlib.import_module(name)


def checks_for(steps: Iterable[str] | None = None, settings: Settings | None = None
               ) -> list[CheckSpec]:
    """The registered checks of *steps* (all steps when None), in step order then id order;
    with *settings*, only those of its ROS version."""
    load_builtin_checks()
    wanted = list(steps) if steps else list(STEP_IDS)
    order = {s: i for i, s in enumerate(STEP_IDS)}
    specs = [c for c in REGISTRY.values() if c.step in wanted
             and (settings is None or c.applies(settings))]
    # By module, then as each module declares them: the same order whichever module some
    # other code imported first (registration order alone would follow that)
    modules = {m: i for i, m in enumerate(_builtin_modules())}
    ids = list(REGISTRY)
    return sorted(specs, key=lambda c: (order[c.step], modules.get(c.func.__module__, len(modules)),
                                        ids.index(c.id)))


async def run_check(spec: CheckSpec, ctx: CheckContext) -> CheckResult:
    """Run one check under its timeout; always returns a result."""
    timeout = ctx.timeout_s * spec.timeout_factor
    start = time.monotonic()
    if not spec.applies(ctx.settings):
        return CheckResult(spec.id, spec.step, Status.SKIP, spec.not_applicable(ctx.settings), [],
                           0.0, timeout, {})
    # The check runs as a task of its own, so that the runner's timeout is told apart from a
    # TimeoutError a wait inside the check lets out (asyncio.timeout would do it: Python 3.11+).
    task = asyncio.ensure_future(spec.func(ctx))
    try:
        try:
            done, _pending = await asyncio.wait({task}, timeout=timeout)
        except asyncio.CancelledError:
            task.cancel()
            raise
        if done:
            outcome = task.result()
        else:
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)
            outcome = Outcome(Status.FAIL, f"no verdict within {timeout:g} s (timed out)",
                              [f"the check was stopped after {timeout:g} s"])
    except asyncio.TimeoutError as exc:     # a wait inside the check gave up: not our timeout
        outcome = Outcome(Status.FAIL, "the check failed unexpectedly: a wait inside it "
                                       f"timed out after {time.monotonic() - start:.1f} s "
                                       "(not its own timeout)", [repr(exc)])
    except asyncio.CancelledError:
        raise
    except Exception as exc:  # a bug or an unexpected failure is a result, not a crash
        outcome = Outcome(Status.FAIL, f"the check failed unexpectedly: {type(exc).__name__}: {exc}",
                          [repr(exc)])
    extra = data_decl.undeclared(spec.id, outcome.data)
    if extra and data_decl.strict():
        raise data_decl.UndeclaredKeyError(
            f"{spec.id} reported keys its declaration lacks: {', '.join(extra)} "
            "(declare them in rosnet_tui/core/checks/data/)")
    return CheckResult(spec.id, spec.step, outcome.status, outcome.summary,
                       list(outcome.evidence), time.monotonic() - start, timeout,
                       dict(outcome.data))


async def run_checks(specs: Iterable[CheckSpec], ctx: CheckContext) -> AsyncIterator[CheckResult]:
    """Run *specs* concurrently; yield each result as soon as it lands."""
    specs = list(specs)
    ctx.round_ids = frozenset(s.id for s in specs)
    tasks = [asyncio.ensure_future(run_check(s, ctx)) for s in specs]
    try:
        for fut in asyncio.as_completed(tasks):
            result = await fut
            ctx.results[result.id] = result
            yield result
    finally:
        for t in tasks:
            t.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        await ctx.listeners.aclose()       # other runs sharing our listener finish first
        if ctx.peer_agents is not None:    # the round's peer agents end with it (before the
            ctx.peer_agents.close()        # connections their channels are on)
            ctx.peer_agents = None
        if ctx.ssh_pool is not None:       # the round's shared SSH connections end with it
            ctx.ssh_pool.close()
            ctx.ssh_pool = type(ctx.ssh_pool)()
