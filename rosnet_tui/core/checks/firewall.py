"""``linux.firewall``: ROS 1, only the peers reach the forwarded ports (rosnet_tui.core.firewall).

Reads our own table (`table inet rosnet_tui`): present, its rules the ones the settings give, and
its set holding exactly the peers' current addresses. Reading nftables needs root: as another
user the check is skipped and says so. The outside proof (an outsider refused) is
``security.outsider``'s.
"""

from __future__ import annotations

import asyncio
from typing import Any

from rosnet_tui.core import firewall as fw
from rosnet_tui.core.checks import CheckContext, check
from rosnet_tui.core.results import Outcome, Status


def _read() -> tuple[str | None, list[str] | None]:
    now = fw.current_ruleset()
    return now, (fw.current_allowed() if now is not None else None)


@check("linux.firewall", "linux", "Only the peers reach the forwarded ports (ROS 1 firewall)",
       1.0, ros=1)
async def check_firewall(ctx: CheckContext) -> Outcome:
    s = ctx.settings
    mode = s.ros.security
    data: dict[str, Any] = {"security": mode, "wanted": fw.wanted(s), "present": None,
                            "readable": None, "allowed": [], "expected": [], "missing": [],
                            "extra": [], "rules_match": None}
    try:
        expected = sorted(fw.allowed_addresses(s))
    except fw.FirewallSettingsError as exc:
        expected = []
        why = str(exc)
    else:
        why = ""
    data["expected"] = expected
    try:
        now, allowed = await asyncio.wait_for(asyncio.to_thread(_read), ctx.timeout_s)
    except (fw.FirewallError, asyncio.TimeoutError) as exc:
        data["readable"] = False
        reason = str(exc) or f"nft did not answer within {ctx.timeout_s:g} s"
        if mode == "none":
            return Outcome(Status.WARN, "[ros] security = \"none\": the forwarded ports are open "
                           "to anyone on the internet", [f"the firewall table: {reason}"], data)
        return Outcome(Status.SKIP, f"skipped: {reason}", [], data)
    data["readable"] = True
    data["present"] = now is not None
    data["allowed"] = allowed or []
    if now is None:
        if mode == "none":
            return Outcome(Status.WARN, "[ros] security = \"none\": the forwarded ports (22, the "
                           "ROS range, the master's port) are open to anyone on the internet",
                           ["no table inet rosnet_tui is loaded (opted out in the settings)"],
                           data)
        # Exposure, not a broken link (every peer still gets through): a warning.
        return Outcome(Status.WARN, "no firewall: the forwarded ports are open to anyone on the "
                       "internet (rosnet-tui firewall apply)",
                       [f"no table {fw.TABLE} is loaded"], data)
    evidence = [f"table {fw.TABLE} loaded; allowed: {', '.join(allowed or []) or 'nobody'}"]
    if why:
        return Outcome(Status.WARN, f"the table is loaded, but the settings give no address "
                       f"list to compare it with: {why}", evidence, data)
    missing = [a for a in expected if a not in (allowed or [])]
    extra = [a for a in (allowed or []) if a not in expected]
    data["missing"], data["extra"] = missing, extra
    data["rules_match"] = fw.normalize(now) == fw.normalize(fw.render_ruleset(s, allowed or []))
    evidence.append(f"the peers' addresses now: {', '.join(expected)}")
    if missing or extra:
        # A peer left out is shut out (fail); a past address still allowed is only a leftover.
        parts = ([f"missing {', '.join(missing)} (that peer is shut out)"] if missing else []) + \
                ([f"no peer has {', '.join(extra)}"] if extra else [])
        return Outcome(Status.FAIL if missing else Status.WARN, "the allowed set is stale: "
                       + "; ".join(parts) + " (rosnet-tui firewall apply, or the sync service)",
                       evidence, data)
    if not data["rules_match"]:
        return Outcome(Status.WARN, "the table's rules differ from the ones the settings give "
                       "(ports or priority changed): rosnet-tui firewall apply", evidence, data)
    note = "" if mode == "firewall" else f" ([ros] security is \"{mode}\")"
    return Outcome(Status.PASS, f"only the {len(expected)} peer address"
                   f"{'es' if len(expected) != 1 else ''} reach the forwarded ports{note}",
                   evidence, data)
