"""Bad news within the timeout (issue 14): with the peer unreachable or silent, every check gives
its verdict within timeout_s + 0.5 s. The connect phase of every probe is bounded by timeout_s;
only checks that got a connection may use their longer budgets.

The `unplugged` variant with ``side="robot", silent=True`` is the robot unplugged while its modem
drops what it would forward to it: nothing comes back, not even an ICMP error.
"""

from __future__ import annotations

import json

import pytest

pytestmark = pytest.mark.lab

TIMEOUT_S = 3.0       # the lab's [checks] timeout_s
SLACK_S = 0.5


def durations(lab, host: str, state) -> dict[str, tuple[float, str, str]]:
    env = dict(lab.ros_env(host), XDG_STATE_HOME=str(state))
    r = lab.rosnet(host, "check", "--json", "-q", "--config", str(lab.config_path(host)),
                   env=env, timeout=120)
    assert r.stdout.strip(), r.stderr
    return {c["id"]: (c["duration_s"], c["status"], c["summary"])
            for c in json.loads(r.stdout)["checks"]}


@pytest.mark.parametrize("variant, options, host", [
    ("unplugged", {"side": "robot", "silent": True}, "laptop"),
    ("unplugged", {}, "robot"),
    ("no_forwarding", {}, "laptop"),
], ids=["robot-unplugged-silent", "laptop-unplugged", "robot-modem-drops"])
def test_every_verdict_within_the_timeout(ros1_lab, tmp_path, variant, options, host):
    with ros1_lab.variant(variant, **options):
        got = durations(ros1_lab, host, tmp_path)
    assert len(got) == 22            # security.ssh_auth and security.outsider too; ros.link
    late = {cid: d for cid, d in got.items() if d[0] > TIMEOUT_S + SLACK_S}
    assert not late, late
    # the peer's side could not run: those checks say so (no pass from a dead peer)
    for cid in ("linux.ssh", "linux.chat_out", "linux.chat_in"):
        assert got[cid][1] == "fail", got[cid]
