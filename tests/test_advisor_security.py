"""The advisor's rules for security.ssh_auth and security.outsider (issue 22): one case per rule
(tests/test_advisor.py runs every rule on its case), and the words each cause gets."""

from __future__ import annotations

from rosnet_tui.core.advisor import advise
from rosnet_tui.core.results import CheckResult, Status
from tests.test_ros2 import master, member


def r(cid: str, status: str, data: dict, step: str) -> CheckResult:
    return CheckResult(cid, step, Status(status), "s", ["e"], 0.1, 3.0, data)


def _ssh(status: str = "fail", **d):
    data = {"target": "203.0.113.2", "port": 22, "user": "root", "from": "sami",
            "methods": ["publickey"], "root_methods": ["publickey"], "password": False,
            "keyboard_interactive": False, "root_password": False, **d}

    def build():
        return {"security.ssh_auth": r("security.ssh_auth", status, data, "linux")}, master()
    return build


def _ssh_not_reached(**d):
    """security.ssh_auth's warning: no peer reached sshd, which offers a password here."""
    return _ssh("warn", **{"methods": [], "root_methods": [], "reachable": False,
                           "tcp": "refused", **d})


def _out(cause: str, ros2: bool = True, **d):
    data = {"security": "mtls" if ros2 else "firewall", "ros": 2 if ros2 else 1,
            "target": "turtlebot:7447" if ros2 else "203.0.113.2", "from": "sami",
            "cause": cause, **d}

    def build():
        s = member() if ros2 else master()
        return {"security.outsider": r("security.outsider", "fail", data, "ros")}, s
    return build


SECURITY_CASES = {
    "security.ssh.password": _ssh(methods=["publickey", "password"], password=True,
                                  root_methods=["publickey", "password"], root_password=True),
    "security.ssh.root_password": _ssh(root_methods=["publickey", "keyboard-interactive"],
                                       root_password=True),
    "security.ssh.password_here": _ssh_not_reached(local_methods=["publickey", "password"],
                                                   local_root_methods=["publickey", "password"]),
    "security.outsider.off": _out("security_off", security="none"),
    "security.outsider.plain": _out("plain_open"),
    "security.outsider.foreign_ca": _out("foreign_ca"),
    "security.outsider.expired": _out("expired", master_cert={"names": ["turtlebot"],
                                                              "not_after": "2026-01-01",
                                                              "expired": False}),
    "security.outsider.wrong_name": _out("wrong_name", master_cert={"names": ["robot.local"],
                                                                    "not_after": "2027-01-01",
                                                                    "expired": False}),
    "security.outsider.no_fleet_cert": _out("no_fleet_cert"),
    "security.outsider.firewall_missing": _out("firewall_missing", ros2=False,
                                               outsider_reachable={"11311": True, "40000": False}),
    "security.outsider.insider_blocked": _out("insider_blocked", ros2=False),
}


def _text(f) -> str:
    return f.meaning + "\n" + "\n".join(f.actions)


def _one(rule_id: str):
    results, s = SECURITY_CASES[rule_id]()
    fs = [f for f in advise(results, s, strict=True) if f.rule.startswith("security.")]
    assert [f.rule for f in fs] == [rule_id], [f.rule for f in fs]
    return fs[0]


def test_password_login_gets_the_fix_keys_first():
    t = _text(_one("security.ssh.password"))
    assert t.index("ssh-copy-id") < t.index("PasswordAuthentication no")
    assert "KbdInteractiveAuthentication no" in t and "reload ssh" in t


def test_root_alone_says_how_it_was_seen():
    t = _text(_one("security.ssh.root_password"))
    assert "auth_none for root" in t and "PermitRootLogin prohibit-password" in t


def test_an_sshd_out_of_reach_that_offers_passwords_is_a_warning_with_the_fix():
    f = _one("security.ssh.password_here")
    assert f.severity == "warn", f
    t = _text(f)
    assert "refused" in t and "password" in t and "PasswordAuthentication no" in t, t
    for quiet in (_ssh_not_reached(local_methods=["publickey"]),      # keys only: nothing to say
                  _ssh("pass", reachable=False, tcp="timeout", methods=[],
                       local_methods=["publickey"])):
        results, s = quiet()
        assert not [x for x in advise(results, s, strict=True)
                    if x.rule.startswith("security.")], results


def test_each_outsider_cause_names_its_command():
    assert "[ros] security = \"mtls\"" in _text(_one("security.outsider.off"))
    assert "ros apply" in _text(_one("security.outsider.plain"))
    assert "ros pair`" in _text(_one("security.outsider.foreign_ca"))
    assert "ros pair --renew" in _text(_one("security.outsider.expired"))
    t = _text(_one("security.outsider.wrong_name"))
    assert "robot.local" in t and "turtlebot" in t
    assert "firewall apply" in _text(_one("security.outsider.firewall_missing"))
    assert "11311" in _text(_one("security.outsider.firewall_missing"))
