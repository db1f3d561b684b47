"""The advisor after a fresh install, on the network lab: the real checks, the real CLI.

Issue 29 (section 4, row 4): the settings saved, nothing applied yet (no hosts lines, no
ROS_MASTER_URI or rmw_zenoh settings in ~/.bashrc, no router running), all four steps run. Every
failed check gets the advice of the rule that explains it (none "no rule explains it"), and the
titles say what is wrong: names that do not resolve, a ROS_MASTER_URI that is not set.
"""

from __future__ import annotations

import pytest

from tests.advisor_support import explain_report, lab_report

pytestmark = pytest.mark.lab

FRESH_HOSTS = "127.0.0.1\tlocalhost\n::1\tlocalhost ip6-localhost ip6-loopback\n"


def unexplained(doc: dict) -> list[str]:
    """The checks left to the catch-all: none, the security checks included (SSH to a peer
    whose name does not resolve is why they could not run)."""
    return [c for f in doc["findings"] if f["rule"] == "check.unexplained"
            for c in f["check_ids"]]


def every_failure_explained(doc: dict) -> None:
    """Every check that failed or warned is named by a finding other than the catch-alls."""
    named = {c for f in doc["findings"] if f["rule"] not in ("check.unexplained",
                                                            "check.no_verdict")
             for c in f["check_ids"]}
    bad = [c["id"] for c in doc["checks"] if c["status"] in ("fail", "warn")
           and c["id"] not in named]
    assert bad == [], explain_report(doc)


def titles(doc: dict) -> set[str]:
    return {f["condition"] for f in doc["findings"]}


def names_do_not_resolve(doc: dict, me: str, peer: str) -> None:
    assert "a name resolves to the wrong address" not in titles(doc), explain_report(doc)
    un = [f for f in doc["findings"] if f["rule"] == "linux.name.unresolved"]
    assert sorted(f["meaning"].split()[0] for f in un) == sorted([me, peer]), explain_report(doc)
    assert all(f["condition"] == "a name does not resolve" for f in un)
    assert any("linux.hosts" in f["check_ids"] for f in un)


@pytest.mark.parametrize("host", ["laptop", "robot"])
def test_ros1_fresh_install(ros1_lab, tmp_path, host):
    lab = ros1_lab
    try:
        lab.write_hosts(host, FRESH_HOSTS)
        lab.bashrc_path(host).write_text("# ~/.bashrc of a fresh install\n")
        env = dict(lab.env(host), XDG_STATE_HOME=str(tmp_path))
        doc = lab_report(lab, host, lab.config_path(host), env)
    finally:
        lab.reset()
    me, peer = lab.hostname(host), lab.hostname("laptop" if host == "robot" else "robot")
    assert unexplained(doc) == [], explain_report(doc)
    every_failure_explained(doc)
    names_do_not_resolve(doc, me, peer)
    uri = [f for f in doc["findings"] if f["rule"] == "ros.env.master_uri_unset"]
    assert [f["condition"] for f in uri] == ["ROS_MASTER_URI not set"], explain_report(doc)
    assert "export ROS_MASTER_URI=http://turtlebot:11311" in " ".join(uri[0]["actions"])
    assert "ROS_MASTER_URI wrong for the role" not in titles(doc)
    master = next(f for f in doc["findings"] if f["rule"] == "ros.master.unreachable")
    assert master["goto_step"] == "linux", explain_report(doc)


@pytest.mark.parametrize("host", ["laptop", "robot"])
def test_ros2_fresh_install(ros2, tmp_path, host):
    lab = ros2.lab
    lab.write_hosts(host, FRESH_HOSTS)
    ros2.stop_router(host)
    ros2.write_bashrc(host, RMW_IMPLEMENTATION="", ROS_DOMAIN_ID="", ZENOH_ROUTER_CONFIG_URI="")
    ros2.router_config_path(host).unlink()
    env = dict(ros2.env(host), XDG_STATE_HOME=str(tmp_path))
    doc = lab_report(lab, host, ros2.config_path(host), env)
    me, peer = lab.hostname(host), lab.hostname("laptop" if host == "robot" else "robot")
    assert unexplained(doc) == [], explain_report(doc)
    every_failure_explained(doc)
    names_do_not_resolve(doc, me, peer)
    graph = [f["rule"] for f in doc["findings"] if "ros2.graph" in f["check_ids"]]
    assert "ros2.router.not_running" in graph, explain_report(doc)
