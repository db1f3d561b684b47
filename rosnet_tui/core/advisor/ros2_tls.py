"""Step 4 for ROS 2 under mutual TLS ([ros] security = "mtls", the default): the rules that read
what ros2.router reports about this component's fleet certificate (``tls``) and, when the
session to the master failed, what a TLS handshake with it said (``tls.handshake``)."""

from __future__ import annotations

from rosnet_tui.core.advisor.engine import Hit, rule
from rosnet_tui.core.advisor.evidence import Evidence


def _tls(ev: Evidence) -> dict:
    return ev.data("ros2.router").get("tls") or {} if ev.s.ros2 else {}


def _facts(ev: Evidence) -> list[str]:
    t = _tls(ev)
    out = [f"ros2.router: this component's certificate: {t.get('problem') or 'fine'}"
           + (f" (CN {t.get('cn')}, until {str(t.get('not_after'))[:10]})" if t.get("cn") else "")]
    if t.get("handshake"):
        out.append(f"ros2.router: TLS handshake with the master: {t.get('handshake')}")
    return out


def _ids(ev: Evidence) -> list[str]:
    return [c for c in ("ros2.router",) if ev.status(c)]


@rule("ros2.tls.missing", "ros", ("ros2.router",),
      "this component has no fleet certificate",
      "Under mutual TLS the master's router admits only certificates from the fleet CA; without "
      "one this component's router cannot link.",
      "Run `rosnet-tui ros apply` (on a member it pairs with the master over SSH) or "
      "`rosnet-tui ros pair`.",
      "ros", "fail")
def _missing(ev: Evidence) -> list[Hit]:
    if _tls(ev).get("problem") not in ("missing", "unreadable"):
        return []
    return [Hit(f"{ev.me} has no usable fleet certificate, so the master's router refuses its "
                "router under mutual TLS.",
                [f"On {ev.me}: `rosnet-tui ros apply` (the master makes the CA; a member pairs "
                 "with the master over SSH), or `rosnet-tui ros pair`.",
                 "Without SSH to the master: `rosnet-tui ros pair --print-request` here, "
                 "`--sign` on the master, `--install` here (paste the text both ways)."],
                check_ids=_ids(ev), evidence=_facts(ev))]


@rule("ros2.tls.foreign_ca", "ros", ("ros2.router",),
      "a member's certificate is from another CA",
      "The master's router trusts only its own fleet CA: a certificate signed by another CA (an "
      "old fleet, a rotated CA, another robot's) is refused.",
      "Pair again: `rosnet-tui ros pair --renew` on the member.",
      "ros", "fail")
def _foreign(ev: Evidence) -> list[Hit]:
    t = _tls(ev)
    if t.get("problem") != "foreign_ca" and t.get("handshake") not in ("rejected_foreign",
                                                                       "master_foreign_ca"):
        return []
    return [Hit(f"{ev.me}'s fleet certificate and the master's CA do not match (another CA "
                "signed one of them, e.g. before the CA was rotated): the master's router refuses "
                "the link.",
                [f"On {ev.me}: `rosnet-tui ros pair --renew` (the master signs a new "
                 "certificate over SSH), then restart the router there."],
                check_ids=_ids(ev), evidence=_facts(ev))]


@rule("ros2.tls.expired", "ros", ("ros2.router",),
      "a fleet certificate has expired, or expires within 30 days",
      "An expired certificate is refused by the other router; the link drops on the day.",
      "Renew: `rosnet-tui ros pair --renew` (members), `rosnet-tui ros pair --renew` on the "
      "master for its own certificate.",
      "ros", "fail")
def _expired(ev: Evidence) -> list[Hit]:
    t = _tls(ev)
    expired = t.get("problem") == "expired" or t.get("handshake") == "rejected_expired"
    if not expired and t.get("problem") != "expiring":
        return []
    when = str(t.get("not_after") or "")[:10]
    head = (f"{ev.me}'s fleet certificate has expired ({when})" if expired else
            f"{ev.me}'s fleet certificate expires on {when}")
    return [Hit(head + ": the master's router refuses an expired certificate.",
                [f"On {ev.me}: `rosnet-tui ros pair --renew`, then restart the router there "
                 "(the sync service renews it before expiry where SSH to the master works)."],
                check_ids=_ids(ev), evidence=_facts(ev))]


@rule("ros2.tls.wrong_name", "ros", ("ros2.router",),
      "the master's certificate does not name the master as members dial it",
      "Members check the name they dial (verify_name_on_connect) against the master's "
      "certificate; a certificate for another name is refused.",
      "On the master: `rosnet-tui ros pair --renew` (or `ros apply`) makes a certificate that "
      "names it.",
      "ros", "fail")
def _wrong_name(ev: Evidence) -> list[Hit]:
    t = _tls(ev)
    if t.get("handshake") != "wrong_name" and not (ev.s.is_master
                                                   and t.get("problem") == "wrong_name"):
        return []
    master = ev.s.master_name or "the master"
    return [Hit(f"The master's router certificate does not name {master}, the name the members "
                "dial, so they refuse it.",
                [f"On {master}: `rosnet-tui ros pair --renew` makes its certificate again for "
                 f"{master} (and its public IP), then restart its router."],
                check_ids=_ids(ev), evidence=_facts(ev))]
