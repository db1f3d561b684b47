"""Step 3 (Linux), ROS 1: the rules that read linux.firewall (the peers-only nftables table)."""

from __future__ import annotations

from rosnet_tui.core.advisor.engine import Hit, rule
from rosnet_tui.core.advisor.evidence import Evidence, join_and
from rosnet_tui.core.exposure.router_card import ros1_exposure

TABLE = "table inet rosnet_tui"


def firewall_action(ev: Evidence, name: str) -> str:
    """What lets this machine's new address through *name*'s peers-only firewall (ROS 1)."""
    seen = ev.data("isp.public_ip").get("public_ip") or "this machine's public IP"
    return (f"Give {name}'s firewall this machine's address {seen}: set public_ip = \"{seen}\" "
            f"under [this] here and under the [[peer]] named {ev.me} on {name}, then "
            f"`rosnet-tui firewall apply` on {name}; with the sync service running on both, "
            "its set follows by itself.")


@rule("security.firewall.off", "linux", ("linux.firewall",),
      "[ros] security = \"none\" on ROS 1",
      "The settings opt out of the peers-only firewall: the forwarded ports (22, the ROS range, "
      "the master's port) answer anyone on the internet, and ROS 1 has no authentication.",
      "Set `security = \"firewall\"` under [ros] and run `rosnet-tui firewall apply`, or "
      "restrict the forward by source address on the modem.",
      "linux", "security")
def _off(ev: Evidence) -> list[Hit]:
    d = ev.data("linux.firewall")
    if d.get("security") != "none" or ev.s.ros2:
        return []
    return [Hit(f"The settings of {ev.me} say `[ros] security = \"none\"`: nothing but the modem "
                "stands between the internet and the ROS master, every node and SSH here. "
                + ros1_exposure(ev.s),
                [f"On {ev.me}, set `security = \"firewall\"` under [ros] (the set-up screen asks "
                 "it), then run `rosnet-tui firewall apply` (a preview first; through sudo).",
                 "Or, where the modem can restrict a forward by source address, allow only the "
                 "peers' public addresses there (the Router step says how)."],
                evidence=["linux.firewall: security none"])]


@rule("security.firewall.missing", "linux", ("linux.firewall",),
      "no peers-only firewall loaded (ROS 1)",
      "The forwarded ports answer anyone on the internet: the peers-only table is not loaded, "
      "though the settings ask for it.",
      "Run `rosnet-tui firewall apply` (or press w on the Linux step).",
      "linux", "security")
def _missing(ev: Evidence) -> list[Hit]:
    d = ev.data("linux.firewall")
    if ev.s.ros2 or d.get("security") == "none" or d.get("present") is not False:
        return []
    peers = [p.name for p in ev.s.peers]
    return [Hit(f"{ev.me} has no {TABLE}: the ports its modem forwards (22, the ROS range, "
                f"the master's port) answer the whole internet, not only "
                f"{join_and(peers) or 'the peers'}. " + ros1_exposure(ev.s),
                [f"On {ev.me}: `rosnet-tui firewall apply` (or `w` on the Linux step): a "
                 "preview, then one nft transaction through sudo; `rosnet-tui undo` takes it "
                 "back.",
                 "Keep the sync service running: it replaces the allowed addresses when a "
                 "peer's public address changes."],
                evidence=[f"linux.firewall: no {TABLE} loaded"])]


@rule("security.firewall.stale", "linux", ("linux.firewall",),
      "the firewall's allowed set differs from the peers' addresses",
      "The peers-only table lets in addresses no peer has now, or leaves a peer's current address "
      "out (that peer is shut out of the master and SSH); or it leaves out this machine's LAN or "
      "[firewall] allow, or its rules are not the ones the settings give.",
      "Run `rosnet-tui firewall apply`; keep the sync service running so the set follows "
      "address changes.",
      "linux", "warn")
def _stale(ev: Evidence) -> list[Hit]:
    d = ev.data("linux.firewall")
    missing, extra = d.get("missing") or [], d.get("extra") or []
    lan_out = [n for n in d.get("expected_lan") or [] if n not in (d.get("lan") or [])]
    allow_out = [n for n in d.get("expected_allow") or [] if n not in (d.get("allow") or [])]
    older = d.get("rules_match") is False
    if ev.s.ros2 or not d.get("present") or not (missing or extra or lan_out or allow_out
                                                  or older):
        return []
    parts = []
    if missing:
        parts.append(f"it leaves out {join_and(missing)}, a peer's address now: that peer cannot "
                     f"reach {ev.me}'s forwarded ports (ROS master, nodes, SSH)")
    if extra:
        parts.append(f"it still lets in {join_and(extra)}, which no peer has now")
    if lan_out:
        parts.append(f"it shuts out this machine's LAN {join_and(lan_out)}")
    if allow_out:
        parts.append(f"it shuts out {join_and(allow_out)} of [firewall] allow")
    if older and not (missing or extra or lan_out or allow_out):
        parts.append("its rules are not the ones the settings give (an older table, or the "
                     "ports changed)")
    return [Hit(f"The allowed set of {TABLE} on {ev.me} is stale: " + "; ".join(parts) + ".",
                [f"On {ev.me}: `rosnet-tui firewall apply` (the preview shows the new set).",
                 "Run the sync service (`rosnet-tui sync install-service`): it replaces the set "
                 "in one transaction when a peer's record changes."],
                severity="fail" if missing else "warn",
                evidence=[f"linux.firewall: missing {join_and(missing) or '-'}, extra "
                          f"{join_and(extra) or '-'}"])]


@rule("security.firewall.lockout", "linux", ("linux.firewall",),
      "the address this check runs from over SSH would not get in again",
      "The peers-only table lets in the peers, this machine's LAN, [firewall] allow (SSH) and "
      "the SSH session that loaded it; the address this check came in from over SSH is none of "
      "them. The open session lives on; once it drops, SSH from there is refused.",
      "Add that address (or its network) to [firewall] allow in the settings, then run "
      "`rosnet-tui firewall apply`.",
      "linux", "warn")
def _lockout(ev: Evidence) -> list[Hit]:
    d = ev.data("linux.firewall")
    client = d.get("client")
    if ev.s.ros2 or not d.get("present") or not client or d.get("client_in") != "":
        return []
    return [Hit(f"This SSH session on {ev.me} comes from {client}, which {TABLE} does not let "
                "in: it is no peer's address, not on this machine's LAN and not in [firewall] "
                "allow. The session lives on; once it drops, SSH from "
                f"{client} is refused until someone at a peer, on the LAN or at the console "
                "lets it in.",
                [f"On {ev.me}, add \"{client}\" (or its network) to `allow` under [firewall] in "
                 "the settings, then run `rosnet-tui firewall apply` from this very session.",
                 "Or log in from a peer or from this machine's LAN next time."],
                evidence=[f"linux.firewall: client {client} not admitted"])]
