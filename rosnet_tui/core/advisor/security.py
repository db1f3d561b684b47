"""The rules that read security.ssh_auth (Linux step) and security.outsider (ROS step): what a
stranger on the internet gets, and what to do about it (issue 22).

The outsider check names its cause in ``cause``; each cause has one rule here. Certificate
details the ROS 2 checks find themselves (S1's fleet TLS: expiry warnings, pairing) have their
own rules next to those checks; these rules explain only what the outsider's probe saw.
"""

from __future__ import annotations

from rosnet_tui.core.advisor.engine import Hit, rule
from rosnet_tui.core.advisor.evidence import Evidence, join_and
from rosnet_tui.core.results import Status


def _ssh_fix(ev: Evidence, user: str) -> list[str]:
    me = ev.me
    return [f"From each machine that logs in to {me}: `ssh-copy-id {user}@{me}`, then check that "
            f"`ssh {user}@{me} true` needs no password.",
            f"On {me}, in /etc/ssh/sshd_config.d/10-rosnet-tui.conf: `PasswordAuthentication no`, "
            "`KbdInteractiveAuthentication no` and `PermitRootLogin prohibit-password`.",
            "`sudo sshd -t && sudo systemctl reload ssh`, then run the checks again."]


@rule("security.ssh.password", "linux", ("security.ssh_auth",),
      "sshd offers password or keyboard-interactive to the internet",
      "Anyone who reaches the forwarded SSH port may guess passwords; bots try within hours of "
      "the forward.",
      "Install keys (`ssh-copy-id`), then `PasswordAuthentication no` and "
      "`KbdInteractiveAuthentication no`, and reload sshd.",
      "linux", "fail")
def _ssh_password(ev: Evidence) -> list[Hit]:
    d = ev.data("security.ssh_auth")
    if not ev.is_fail("security.ssh_auth") or not (d.get("password") or d.get("keyboard_interactive")):
        return []
    offered = [m for m in d.get("methods") or [] if m != "publickey"]
    return [Hit(f"{ev.me}'s sshd, seen from {d.get('from') or 'a peer'} at {d.get('target')}:"
                f"{d.get('port')}, offers {join_and(offered)} to anyone: the internet can guess "
                "passwords on it.", _ssh_fix(ev, str(d.get("user") or "USER")),
                evidence=[f"auth_none({d.get('user')}) -> {', '.join(d.get('methods') or [])}"])]


@rule("security.ssh.root_password", "linux", ("security.ssh_auth",),
      "sshd offers root a password",
      "The methods sshd offers the user root include a password: if PermitRootLogin allows it, "
      "a guessed root password owns the robot.",
      "`PermitRootLogin prohibit-password` (or `no`), keys for root if needed, reload sshd.",
      "linux", "fail", superseded_by=("security.ssh.password",))
def _ssh_root(ev: Evidence) -> list[Hit]:
    d = ev.data("security.ssh_auth")
    if not ev.is_fail("security.ssh_auth") or not d.get("root_password"):
        return []
    return [Hit(f"{ev.me}'s sshd offers the user root {join_and(d.get('root_methods') or [])} "
                "(seen with auth_none for root; sshd lists the same methods whatever "
                "PermitRootLogin says, so check it with `sudo sshd -T | grep -i permitrootlogin`).",
                _ssh_fix(ev, "root"),
                evidence=[f"auth_none(root) -> {', '.join(d.get('root_methods') or [])}"])]


@rule("security.ssh.password_here", "linux", ("security.ssh_auth",),
      "sshd offers a password, though the internet does not reach it now",
      "No peer reached this component's SSH port from the internet, so strangers get nothing "
      "today; but its sshd offers a password: forwarding port 22 (or a DMZ host), or a firewall "
      "that shuts out only the peer that looked, would let anyone guess passwords.",
      "Install keys (`ssh-copy-id`), then `PasswordAuthentication no` and "
      "`KbdInteractiveAuthentication no`, and reload sshd.",
      "linux", "warn")
def _ssh_password_here(ev: Evidence) -> list[Hit]:
    d = ev.data("security.ssh_auth")
    local = [str(m) for m in d.get("local_methods") or []]
    root = [str(m) for m in d.get("local_root_methods") or []]
    pw = ("password", "keyboard-interactive", "none")
    offered = [m for m in local if m in pw] or [f"{m} (to root)" for m in root if m in pw]
    if ev.status("security.ssh_auth") != Status.WARN or d.get("reachable") is not False \
            or not offered:
        return []
    return [Hit(f"No peer reached {ev.me}'s sshd at {d.get('target')}:{d.get('port')} "
                f"({d.get('from') or 'a peer'}: {d.get('tcp')}), but it offers "
                f"{join_and(offered)}: one forward of port {d.get('port')} would put a password "
                "prompt on the internet.", _ssh_fix(ev, str(d.get("user") or "USER")),
                evidence=[f"sshd here: auth_none({d.get('user')}) -> {', '.join(local)}; "
                          f"auth_none(root) -> {', '.join(root)}"])]


def _cause(ev: Evidence, *causes: str) -> bool:
    return ev.is_fail("security.outsider") and ev.data("security.outsider").get("cause") in causes


@rule("security.outsider.off", "ros", ("security.outsider",),
      "an outsider gets in and [ros] security is \"none\"",
      "Security is switched off: whoever reaches the forwarded port reads the graph and "
      "publishes (ROS 2), or commands the master (ROS 1).",
      "Set `[ros] security` back to its default (\"mtls\" on ROS 2, \"firewall\" on ROS 1) and "
      "apply it.", "ros", "fail")
def _off(ev: Evidence) -> list[Hit]:
    if not _cause(ev, "security_off"):
        return []
    d = ev.data("security.outsider")
    if ev.s.ros2:
        acts = ["In the settings: `[ros] security = \"mtls\"` (or choose it on the set-up screen).",
                "`rosnet-tui ros apply` on the master, then on each member (it pairs them).",
                "Run the checks again: security.outsider must pass."]
    else:
        acts = ["In the settings: `[ros] security = \"firewall\"`.",
                "`rosnet-tui firewall apply` on every component (a preview first, one "
                "nftables transaction).", "Run the checks again: security.outsider must pass."]
    return [Hit(f"An outsider gets in at {d.get('target')}: [ros] security is "
                f"\"{d.get('security')}\", so nothing checks who connects.", acts)]


@rule("security.outsider.plain", "ros", ("security.outsider",),
      "the master's Zenoh port takes plain or certificate-less sessions although security is on",
      "The settings ask for mutual TLS, but the master's router still listens without it (its "
      "config predates `ros apply`, or the router was not restarted).",
      "`rosnet-tui ros apply` on the master and restart its router.", "ros", "fail")
def _plain(ev: Evidence) -> list[Hit]:
    if not _cause(ev, "plain_open", "no_mtls"):
        return []
    d = ev.data("security.outsider")
    how = ("a plain TCP session" if d.get("cause") == "plain_open"
           else "a TLS session without a fleet certificate")
    return [Hit(f"{ev.s.master_name}'s Zenoh port ({d.get('target')}) accepts {how}: the router "
                "does not run the mutual-TLS config.",
                [f"On {ev.s.master_name}: `rosnet-tui ros apply`, then restart its router "
                 "(rmw_zenohd) so it reads the new config.", "Run the checks again."])]


@rule("security.outsider.foreign_ca", "ros", ("security.outsider",),
      "the fleet certificate and the master's are from different CAs",
      "This component's certificate (or the CA it trusts) is not the master's fleet CA: paired "
      "with another master, or the master's CA was made anew.",
      "Pair again: `rosnet-tui ros pair`.", "ros", "fail")
def _foreign(ev: Evidence) -> list[Hit]:
    if not _cause(ev, "foreign_ca"):
        return []
    d = ev.data("security.outsider")
    return [Hit(f"The master at {d.get('target')} and {d.get('from')} do not share a CA: the "
                "fleet certificate there is refused, or the master's certificate is not trusted.",
                [f"On {d.get('from')}: `rosnet-tui ros pair` (the master signs a new "
                 "certificate; the key stays there).", "Run the checks again."])]


@rule("security.outsider.expired", "ros", ("security.outsider",),
      "a fleet certificate has expired",
      "An expired certificate is refused by the other side.",
      "Renew it: `rosnet-tui ros pair --renew`.", "ros", "fail")
def _expired(ev: Evidence) -> list[Hit]:
    if not _cause(ev, "expired"):
        return []
    d = ev.data("security.outsider")
    mc = d.get("master_cert") or {}
    whose = "the master's" if mc.get("expired") else f"{d.get('from')}'s"
    return [Hit(f"{whose} certificate has expired, so the fleet cannot connect at "
                f"{d.get('target')}.",
                [f"`rosnet-tui ros pair --renew` on {d.get('from')}"
                 + (" (and `rosnet-tui ros apply` on the master for its own)"
                    if mc.get("expired") else ""), "Run the checks again."])]


@rule("security.outsider.wrong_name", "ros", ("security.outsider",),
      "the master's certificate does not name the master",
      "Members dial the master by name; a certificate without that name fails the name check.",
      "Re-issue it on the master: `rosnet-tui ros apply`.", "ros", "fail")
def _wrong_name(ev: Evidence) -> list[Hit]:
    if not _cause(ev, "wrong_name"):
        return []
    d = ev.data("security.outsider")
    names = (d.get("master_cert") or {}).get("names") or []
    return [Hit(f"The master's certificate names {join_and(names) or 'nothing'}, not "
                f"{ev.s.master_name}, the name members dial.",
                [f"On {ev.s.master_name}: `rosnet-tui ros apply` (it re-issues the router "
                 "certificate with the master's name), then restart its router."])]


@rule("security.outsider.no_fleet_cert", "ros", ("security.outsider",),
      "this seat has no fleet certificate",
      "The seat the outsider probe ran on was never paired.",
      "Pair it: `rosnet-tui ros pair`.", "ros", "fail")
def _no_cert(ev: Evidence) -> list[Hit]:
    if not _cause(ev, "no_fleet_cert"):
        return []
    d = ev.data("security.outsider")
    return [Hit(f"{d.get('from')} has no fleet certificate (~/.config/rosnet-tui/tls), so it "
                "cannot prove it belongs to the fleet.",
                [f"On {d.get('from')}: `rosnet-tui ros pair`.", "Run the checks again."])]


@rule("security.outsider.firewall_missing", "ros", ("security.outsider",),
      "an outsider reaches the ROS ports although security is \"firewall\"",
      "The peers-only firewall is not in place on this component (never applied, undone, or "
      "removed by another tool).",
      "`rosnet-tui firewall apply`.", "ros", "fail")
def _firewall(ev: Evidence) -> list[Hit]:
    if not _cause(ev, "firewall_missing"):
        return []
    d = ev.data("security.outsider")
    open_ = [p for p, v in (d.get("outsider_reachable") or {}).items() if v]
    return [Hit(f"The port checker, which is no peer, reaches port {join_and(open_)} of "
                f"{d.get('target')}: only the peers should.",
                [f"On {ev.me}: `rosnet-tui firewall apply` (preview, then one nftables "
                 "transaction); `rosnet-tui firewall show` lists what it allows.",
                 "Run the checks again."])]


@rule("security.outsider.insider_blocked", "ros", ("security.outsider",),
      "the firewall refuses a peer too",
      "A peer's public address is not in the allowed set (it changed and the sync has not "
      "caught up, or the settings hold an old one).",
      "Update the peer's address (sync, or the settings), then `rosnet-tui firewall apply`.",
      "ros", "fail")
def _insider(ev: Evidence) -> list[Hit]:
    if not _cause(ev, "insider_blocked"):
        return []
    d = ev.data("security.outsider")
    return [Hit(f"Outsiders are refused at {d.get('target')}, but so is {d.get('from')}.",
                [f"Check {d.get('from')}'s public address in the settings (`rosnet-tui check "
                 "--step isp` on it shows the current one).",
                 f"On {ev.me}: `rosnet-tui firewall apply` with the right address."])]
