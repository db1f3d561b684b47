"""``linux.firewall``: ROS 1, only the peers reach the forwarded ports (rosnet_tui.core.exposure.firewall).

Reads our own table (`table inet rosnet_tui`): present, its rules the ones the settings give, its
peers' set holding exactly the peers' current addresses, and its LAN and [firewall] allow sets
the ones of this machine and the settings now. Its evidence names who gets in (peers, LAN, allow
list, the SSH session that loaded it) and it warns when the address this check runs from over
SSH would not get in again. Reading nftables needs root: as another user the check is skipped
and says so. The outside proof (an outsider refused) is ``security.outsider``'s.
"""

from __future__ import annotations

import asyncio
from typing import Any

from rosnet_tui.core.checks import CheckContext, check
from rosnet_tui.core.exposure import firewall as fw
from rosnet_tui.core.net import netinfo
from rosnet_tui.core.results import Outcome, Status
from rosnet_tui.core.ssh import origin


def _read() -> tuple[str | None, dict[str, list[str]] | None]:
    now = fw.current_ruleset()
    return now, (fw.current_sets() if now is not None else None)


def _client() -> tuple[origin.Session | None, str]:
    """The SSH session this check runs in (None: none), and why it is not known ("")."""
    try:
        return origin.detect_session(), ""
    except origin.SessionError as exc:
        return None, str(exc)


def who_evidence(loaded: fw.Admission) -> list[str]:
    """Who the loaded table lets in, one line per kind."""
    sessions = ", ".join(f"{x.address} (port {x.port})" for x in loaded.sessions)
    return [f"peers (SSH and ROS): {', '.join(loaded.peers) or 'nobody'}",
            f"this machine's LAN (SSH and ROS): {', '.join(loaded.lan) or 'none'}",
            f"[firewall] allow (SSH): {', '.join(loaded.allow) or 'none'}",
            f"the SSH session that loaded it (SSH, until the next firewall apply): "
            f"{sessions or 'none'}"]


def client_words(adm: fw.Admission, client: origin.Session) -> tuple[str, str]:
    """(why *client* gets in under *adm*, "" when it does not; the evidence line)."""
    why = fw.admitted(adm, client.address, client.port)
    return why, (f"this check runs over SSH from {client.address} (sshd port {client.port}): "
                 + (f"gets in as {why}" if why else "would NOT get in once this session drops"))


@check("linux.firewall", "linux", "Only the peers reach the forwarded ports (ROS 1 firewall)",
       1.0, ros=1)
async def check_firewall(ctx: CheckContext) -> Outcome:
    s = ctx.settings
    mode = s.ros.security
    data: dict[str, Any] = {"security": mode, "wanted": fw.wanted(s), "present": None,
                            "readable": None, "allowed": [], "expected": [], "missing": [],
                            "extra": [], "rules_match": None, "lan": [], "allow": [],
                            "sessions": [], "expected_lan": [], "expected_allow": [],
                            "client": None, "client_in": None}
    client, client_unknown = _client()
    data["client"] = client.address if client else None
    why = ""
    expected: list[str] = []
    try:
        expected = sorted(fw.allowed_addresses(s))
    except fw.FirewallSettingsError as exc:
        why = str(exc)
    try:
        expected_allow = fw.allow_networks(s)
    except fw.FirewallSettingsError as exc:
        expected_allow, why = [], why or str(exc)
    expected_lan = netinfo.lan_networks()
    data.update(expected=expected, expected_lan=expected_lan, expected_allow=expected_allow)
    try:
        now, sets = await asyncio.wait_for(asyncio.to_thread(_read), ctx.timeout_s)
    except (fw.FirewallError, asyncio.TimeoutError) as exc:
        data["readable"] = False
        reason = str(exc) or f"nft did not answer within {ctx.timeout_s:g} s"
        if mode == "none":
            return Outcome(Status.WARN, "[ros] security = \"none\": the forwarded ports are open "
                           "to anyone on the internet", [f"the firewall table: {reason}"], data)
        return Outcome(Status.SKIP, f"skipped: {reason}", [], data)
    data["readable"] = True
    data["present"] = now is not None
    if now is None or sets is None:
        if mode == "none":
            return Outcome(Status.WARN, "[ros] security = \"none\": the forwarded ports (22, the "
                           "ROS range, the master's port) are open to anyone on the internet",
                           ["no table inet rosnet_tui is loaded (opted out in the settings)"],
                           data)
        # Exposure, not a broken link (every peer still gets through): a warning.
        return Outcome(Status.WARN, "no firewall: the forwarded ports are open to anyone on the "
                       "internet (rosnet-tui firewall apply)",
                       [f"no table {fw.TABLE} is loaded"], data)
    loaded = fw.loaded_admission(sets)
    allowed = loaded.peers
    data.update(allowed=allowed, lan=loaded.lan, allow=loaded.allow,
                sessions=[x.element for x in loaded.sessions])
    evidence = [f"table {fw.TABLE} loaded; allowed: {', '.join(allowed) or 'nobody'}",
                *who_evidence(loaded)]
    warnings: list[str] = []
    if client is not None:
        client_in, line = client_words(loaded, client)
        data["client_in"] = client_in
        evidence.append(line)
        if not client_in:
            warnings.append(f"{client.address}, where this check runs from over SSH, would not "
                            "get in again once this session drops: add it to [firewall] allow, "
                            "then rosnet-tui firewall apply")
    elif client_unknown:
        evidence.append(client_unknown)
    if why:
        return Outcome(Status.WARN, f"the table is loaded, but the settings give no address "
                       f"list to compare it with: {why}", evidence, data)
    missing = [a for a in expected if a not in allowed]
    extra = [a for a in allowed if a not in expected]
    data["missing"], data["extra"] = missing, extra
    data["rules_match"] = fw.normalize(now) == fw.normalize(fw.render_ruleset(s, loaded))
    evidence.append(f"the peers' addresses now: {', '.join(expected)}")
    if missing:
        # A peer left out is shut out (fail); a past address still allowed is only a leftover.
        parts = [f"missing {', '.join(missing)} (that peer is shut out)"] + \
                ([f"no peer has {', '.join(extra)}"] if extra else [])
        return Outcome(Status.FAIL, "the allowed set is stale: " + "; ".join(parts)
                       + " (rosnet-tui firewall apply, or the sync service)", evidence, data)
    if extra:
        warnings.append(f"the allowed set is stale: no peer has {', '.join(extra)} "
                        "(rosnet-tui firewall apply, or the sync service)")
    lan_out = [n for n in expected_lan if n not in loaded.lan]
    allow_out = [n for n in expected_allow if n not in loaded.allow]
    if lan_out or allow_out:
        warnings.append("shut out though they should get in: "
                        + "; ".join(([f"this machine's LAN {', '.join(lan_out)}"] if lan_out
                                     else [])
                                    + ([f"[firewall] allow {', '.join(allow_out)}"] if allow_out
                                       else []))
                        + " (rosnet-tui firewall apply)")
    elif set(loaded.lan) != set(expected_lan) or set(loaded.allow) != set(expected_allow):
        warnings.append("the table lets in networks that are no longer this machine's LAN or "
                        "in [firewall] allow (rosnet-tui firewall apply)")
    if not data["rules_match"]:
        warnings.append("the table's rules differ from the ones the settings give (ports or "
                        "priority changed, or an older table): rosnet-tui firewall apply")
    if warnings:
        evidence += warnings[1:]
        return Outcome(Status.WARN, warnings[0], evidence, data)
    note = "" if mode == "firewall" else f" ([ros] security is \"{mode}\")"
    return Outcome(Status.PASS, f"only the {len(expected)} peer address"
                   f"{'es' if len(expected) != 1 else ''}, this machine's LAN and [firewall] allow "
                   f"reach the forwarded ports{note}", evidence, data)
