"""The advisor's ROS 2 rules over check results shaped as the ros2.* checks report them
(recorded into the golden inputs by tests/golden/record.py, next to the ROS 1 cases)."""

from __future__ import annotations

from rosnet_tui.core.advisor import advice_by_check, advise
from rosnet_tui.core.results import CheckResult, Status
from tests.advisor_support import fresh_names
from tests.builders import ros2_master as master
from tests.builders import ros2_member as member


def r(cid: str, status: str, data: dict, step: str = "ros", summary: str = "s") -> CheckResult:
    return CheckResult(cid, step, Status(status), summary, [], 0.1, 3.0, data)


def ids(findings) -> list[str]:
    return [f.rule for f in findings]


def test_dds_is_explained_with_what_to_do_instead():
    fs = advise([r("ros2.env", "fail", {"dds": True, "rmw": None, "bashrc_rmw": None})], member())
    f = next(f for f in fs if f.rule == "ros2.env.dds")
    assert "multicast" in f.meaning and "rmw_zenoh" in " ".join(f.actions)


def test_router_refused_from_a_member_means_not_running():
    fs = advise([r("ros2.router", "fail", {"failure": "refused", "endpoint": "tcp/turtlebot:7447",
                                           "address": "203.0.113.2", "reachable": False})],
                member())
    assert ids(fs)[0] == "ros2.router.not_running" and "turtlebot" in fs[0].meaning


def test_router_timeout_from_a_member_means_the_forward_is_missing():
    fs = advise([r("ros2.router", "fail", {"failure": "timeout", "endpoint": "tcp/turtlebot:7447",
                                           "address": "203.0.113.2", "reachable": False}),
                 r("ros2.pubsub_out", "fail", {"ok": False, "failed_hop": "master_router",
                                               "peer": "turtlebot"})], member())
    f = next(f for f in fs if f.rule == "ros2.port.not_forwarded")
    assert "TCP 7447" in f.actions[0] and "ros2.pubsub_out" in f.check_ids
    assert "ros2.link.missing" not in ids(fs)


def test_master_port_test_closed_reads_table_1_for_zenoh_port():
    fs = advise([r("router.port_open", "fail", {"zenoh_port": 7447, "zenoh_port_open": False,
                                                "zenoh_listener": "router", "ports": []},
                   "router")], master())
    assert "ros2.port.not_forwarded" in ids(fs) and "security.exposed" not in ids(fs)
    fs = advise([r("router.port_open", "pass", {"zenoh_port": 7447, "zenoh_port_open": True,
                                                "zenoh_listener": "router", "ports": []},
                   "router")], master())
    assert "security.zenoh_exposed" in ids(fs) and "security.exposed" not in ids(fs)


def test_loopback_and_ipv6_listen_problems():
    fs = advise([r("ros2.router", "fail", {"listen_problem": "loopback", "listening": ["127.0.0.1"],
                                           "reachable": True})], master())
    assert "ros2.router.loopback" in ids(fs)
    fs = advise([r("ros2.router", "fail", {"listen_problem": "ipv6_only", "listening": [],
                                           "ipv6": False, "reachable": False})], master())
    assert "ros2.router.ipv6_only" in ids(fs)


def test_peer_mode_and_distro_mismatch_are_told_apart():
    dropped = r("ros2.pubsub_out", "fail", {"ok": False, "failed_hop": "data_dropped",
                                            "peer": "turtlebot", "graph_seen": True})
    fs = advise([dropped, r("ros2.router", "warn", {"remote_peers": ["1 from 198.51.100.2"],
                                                    "reachable": True})], member())
    assert "ros2.peer_mode" in ids(fs)
    fs = advise([dropped, r("ros2.env", "fail", {"distro": "jazzy", "distro_mismatch": ["turtlebot"],
                                                 "peer_distros": {"turtlebot": "humble"}})],
                member())
    assert "ros2.env.distro" in ids(fs) and "ros2.peer_mode" not in ids(fs)


def test_domain_mismatch_is_named_from_either_side():
    fs = advise([r("ros2.env", "fail", {"domain_ok": False, "domain_id": "5"})], member())
    assert "ros2.env.domain" in ids(fs)
    fs = advise([r("ros2.pubsub_out", "fail", {"ok": False, "failed_hop": "peer_subscriber",
                                               "detail": "the peer's nodes use ROS_DOMAIN_ID 5, "
                                                         "ours 0", "peer": "sami"})], master())
    assert "ros2.env.domain" in ids(fs)


def test_carrier_nat_matters_on_the_master_only():
    cg = r("isp.cgnat", "warn", {"cgnat": True, "double_nat": False, "hop": "100.64.0.1",
                                 "method": "traceroute"}, "isp")
    fs = advise([cg], master())
    f = next(f for f in fs if f.rule == "ros2.cgnat")
    assert f.severity == "fail" and "VPS" in " ".join(f.actions) and "isp.cgnat" not in ids(fs)
    fs = advise([cg], member())
    f = next(f for f in fs if f.rule == "ros2.cgnat")
    assert f.severity == "info" and "does not matter" in f.meaning


def test_an_unlinked_member_router_is_named():
    fs = advise([r("ros2.graph", "fail", {"missing": ["turtlebot"]}),
                 r("ros2.pubsub_in", "fail", {"ok": False, "failed_hop": "peer_router",
                                              "peer": "sami", "detail": "no link"})], master())
    assert "ros2.link.missing" in ids(fs)


def test_ros1_rules_stay_quiet_on_ros2_results():
    fs = advise([r("ros2.env", "pass", {"dds": False, "domain_ok": True})], member())
    assert not [f for f in fs if f.rule.startswith("ros.")]


def test_ros2_env_warnings_are_explained():
    """ros2.env warns when rmw_zenoh is exported in one place only, when ROS_DISTRO is unset and
    when localhost-only or DDS settings linger: each gets advice, not "no rule explains it"."""
    def env(**data):
        base = {"dds": False, "rmw": "rmw_zenoh_cpp", "bashrc_rmw": "rmw_zenoh_cpp",
                "rmw_ok": True, "domain_ok": True, "distro": "jazzy", "warnings": []}
        return [r("ros2.env", "warn", {**base, **data})]

    def only(fs, rule):
        assert "check.unexplained" not in ids(fs), ids(fs)
        return next(f for f in fs if f.rule == rule)

    f = only(advise(env(bashrc_rmw=None, rmw_ok=False), member()), "ros2.env.rmw_one_place")
    assert f.severity == "warn" and "~/.bashrc" in f.meaning and "new shell" in f.meaning
    assert any("rosnet-tui ros apply" in a for a in f.actions)
    f = only(advise(env(rmw=None, rmw_ok=False), member()), "ros2.env.rmw_one_place")
    assert "this shell" in f.meaning and any("source ~/.bashrc" in a for a in f.actions)
    f = only(advise(env(distro=None), member()), "ros2.env.no_distro")
    assert "ROS_DISTRO" in f.meaning and any("/opt/ros/" in a for a in f.actions)
    f = only(advise(env(warnings=["localhost_only", "dds_settings"]), member()),
             "ros2.env.leftovers")
    assert "ROS_LOCALHOST_ONLY" in f.meaning and "DDS" in f.meaning
    # a healthy environment: none of them
    assert not [f for f in advise(env(), member()) if f.rule.startswith("ros2.env")]


# Cases for tests/test_advisor_rules.py's CASES (every rule fires on its case and stays silent on the
# healthy ROS 1 network): rule id -> () -> (results by id, settings).
def _case(settings, *results: CheckResult):
    return lambda: ({x.id: x for x in results}, settings())


ROS2_CASES = {
    "ros2.env.dds": _case(member, r("ros2.env", "fail", {"dds": True, "rmw": None})),
    "ros2.env.domain": _case(member, r("ros2.env", "fail", {"domain_ok": False,
                                                            "domain_id": "5"})),
    "ros2.env.rmw_one_place": _case(member, r("ros2.env", "warn", {
        "dds": False, "rmw": "rmw_zenoh_cpp", "bashrc_rmw": None, "rmw_ok": False})),
    "ros2.env.no_distro": _case(member, r("ros2.env", "warn", {"distro": None})),
    "ros2.env.leftovers": _case(member, r("ros2.env", "warn", {"warnings": ["localhost_only"]})),
    "ros2.env.distro": _case(member, r("ros2.env", "fail", {
        "distro": "jazzy", "distro_mismatch": ["turtlebot"],
        "peer_distros": {"turtlebot": "humble"}})),
    "ros2.router.not_running": _case(member, r("ros2.router", "fail", {
        "failure": "refused", "endpoint": "tcp/turtlebot:7447", "address": "203.0.113.2"})),
    "ros2.router.loopback": _case(master, r("ros2.router", "fail", {
        "listen_problem": "loopback", "listening": ["127.0.0.1"]})),
    "ros2.router.ipv6_only": _case(master, r("ros2.router", "fail", {
        "listen_problem": "ipv6_only", "listening": [], "ipv6": False})),
    "ros2.peer_mode": _case(member, r("ros2.router", "warn", {
        "remote_peers": ["1 from 198.51.100.2"], "reachable": True})),
    "ros2.link.missing": _case(master, r("ros2.pubsub_in", "fail", {
        "ok": False, "failed_hop": "peer_router", "peer": "sami", "detail": "no link"})),
    "ros2.port.not_forwarded": _case(master, r("router.port_open", "fail", {
        "zenoh_port": 7447, "zenoh_port_open": False, "zenoh_listener": "router", "ports": []},
        "router")),
    "ros2.cgnat": _case(master, r("isp.cgnat", "warn", {
        "cgnat": True, "double_nat": False, "hop": "100.64.0.1", "method": "traceroute"}, "isp")),
    "security.zenoh_exposed": _case(master, r("router.port_open", "pass", {
        "zenoh_port": 7447, "zenoh_port_open": True, "zenoh_listener": "router", "ports": []},
        "router")),    # mutual TLS (ros2.router's tls data)
    "ros2.tls.missing": _case(member, r("ros2.router", "fail", {
        "security": "mtls", "tls": {"problem": "missing"}, "endpoint": "tls/turtlebot:7447"})),
    "ros2.tls.foreign_ca": _case(member, r("ros2.router", "fail", {
        "security": "mtls", "endpoint": "tls/turtlebot:7447",
        "tls": {"problem": "foreign_ca", "cn": "sami", "not_after": "2027-12-01T00:00:00+00:00",
                "handshake": "rejected_foreign"}})),
    "ros2.tls.expired": _case(member, r("ros2.router", "fail", {
        "security": "mtls", "endpoint": "tls/turtlebot:7447",
        "tls": {"problem": "expired", "cn": "sami", "not_after": "2026-01-01T00:00:00+00:00",
                "handshake": "rejected_expired"}})),
    "ros2.tls.wrong_name": _case(member, r("ros2.router", "fail", {
        "security": "mtls", "endpoint": "tls/turtlebot:7447",
        "tls": {"problem": None, "cn": "sami", "handshake": "wrong_name"}})),
    "ros2.link.large_dropped": _case(member, r("ros2.link", "warn", {"peers": {"turtlebot": {
        "rtt_ms": 40.0, "out_bps": 2_000_000, "in_bps": 2_000_000, "largest_out": 1 << 20,
        "largest_in": 65536, "tried_out": 1 << 20, "tried_in": 1 << 20}}})),
    "ros2.link.too_thin": _case(lambda: needing(member(), 50000, 10), r("ros2.link", "warn", {
        "peers": {"turtlebot": {"rtt_ms": 40.0, "out_bps": 2_100_000, "in_bps": 9_000_000,
                                "largest_out": 1 << 20, "largest_in": 1 << 20,
                                "tried_out": 1 << 20, "tried_in": 1 << 20}}})),
    "relay.router.down": _case(lambda: relayed(member()), r("relay.router", "fail", {
        "failure": "timeout", "endpoint": "tls/relay:7447", "address": "198.51.100.9"})),
}


def needing(s, size: int, hz: float):
    """*s* with one [[link.topic]] of *size* bytes at *hz*."""
    from rosnet_tui.core.config.settings_model import LinkTopic

    s.link.topics = [LinkTopic("/camera/image/compressed", size, hz)]
    return s


def relayed(s):
    """*s* with both sites meeting at a relay ([relay] host = "relay")."""
    from rosnet_tui.core.config.settings_model import RelaySettings

    s.relay = RelaySettings(host="relay", ssh_user="root")
    return s


def test_a_relay_that_does_not_answer_comes_first_and_says_what_to_open():
    fs = advise([r("relay.router", "fail", {"failure": "timeout", "endpoint": "tls/relay:7447"}),
                 r("ros2.router", "fail", {"failure": "timeout", "endpoint": "tls/relay:7447"}),
                 r("router.port_open", "fail", {}, step="router")], relayed(master()))
    assert ids(fs)[0] == "relay.router.down"
    assert "TCP 7447" in fs[0].actions[0] and "ros2.router" in fs[0].check_ids
    assert "ros2.port.not_forwarded" not in ids(fs)


def test_mtls_closes_the_exposure_finding_and_security_none_keeps_it():
    port = r("router.port_open", "pass", {"zenoh_port": 7447, "zenoh_port_open": True,
                                          "zenoh_listener": "router", "ports": []}, "router")
    on = r("ros2.router", "pass", {"security": "mtls", "tls": {"problem": None}})
    off = r("ros2.router", "pass", {"security": "none"})
    assert "security.zenoh_exposed" not in ids(advise([port, on], master()))
    assert "security.zenoh_exposed" in ids(advise([port, off], master(security="none")))
    expiring = r("ros2.router", "warn", {"security": "mtls", "tls": {
        "problem": "expiring", "not_after": "2026-12-01T00:00:00+00:00"}})
    fs = advise([expiring], member())
    assert ids(fs)[:1] == ["ros2.tls.expired"] and "2026-12-01" in fs[0].meaning



# --------------------------------------------------------------------------- a fresh install
def _fresh(settings, ros2_router: dict) -> dict[str, CheckResult]:
    """A fresh install's round under ROS 2 (issue 29, section 4, row 4), the data as the checks
    give it: no name resolves (tests/advisor_support.py's fresh_names), so ros2.router stops at
    the master's name, and no router runs here, so the graph and both exchanges fail at ours."""
    rs = {k: v for k, v in fresh_names().items() if not k.startswith("ros.")}
    here = "no Zenoh router answered at tcp/127.0.0.1:7447 within 2.0 s"
    rs.update((x.id, x) for x in (
        r("ros2.router", "fail", {"endpoint": "tls/turtlebot:7447", "reachable": False,
                                  "address": None, "failure": "resolve", **ros2_router}),
        r("ros2.graph", "fail", {"nodes": [], "topics": [], "seen_from": [], "missing": []},
          summary="cannot read the graph: this machine's router does not answer at "
                  "tcp/127.0.0.1:7447"),
        *(r(c, "fail", {"peer": "turtlebot", "ok": False, "failed_hop": "our_router",
                        "detail": here}) for c in ("ros2.pubsub_out", "ros2.pubsub_in"))))
    return rs


def test_a_fresh_member_gets_advice_for_every_failed_check():
    rs = _fresh(member, {"role": "member", "local_router": {
        "reachable": False, "endpoint": "tcp/127.0.0.1:7447", "failure": "nothing listens"}})
    fs = advise(rs, member(), strict=True)
    assert "check.unexplained" not in ids(fs), [(f.rule, f.meaning) for f in fs]
    advice = advice_by_check(fs)
    assert [f.rule for f in advice["ros2.graph"]] == ["ros2.router.not_running"]
    f = advice["ros2.graph"][0]
    assert f.meaning.startswith("sami's own router is not running: nodes here look for")
    assert "master's router answers" not in f.meaning
    assert {f.rule for f in advice["ros2.router"]} == {"linux.name.unresolved",
                                                      "ros2.router.not_running"}


def test_a_fresh_master_gets_advice_for_every_failed_check():
    rs = _fresh(master, {"role": "master", "listening": [], "listen_problem": "not_running"})
    for cid in ("linux.ping", "linux.ssh", "linux.chat_out", "linux.chat_in"):
        rs[cid].data["peers"] = {"sami": rs[cid].data["peers"]["turtlebot"]}
    fs = advise(rs, master(), strict=True)
    assert "check.unexplained" not in ids(fs), [(f.rule, f.meaning) for f in fs]
    advice = advice_by_check(fs)
    assert [f.rule for f in advice["ros2.graph"]] == ["ros2.router.not_running"]
    assert "Nothing listens on TCP 7447 on turtlebot" in advice["ros2.graph"][0].meaning


def test_a_master_behind_carrier_nat_is_led_to_a_relay_by_its_commands():
    """Without a relay, the master's carrier NAT led with "make another component the master"
    (nothing here says another site can forward) and then hand-written Zenoh config for a VPS;
    now the relay comes first, by the commands that set it up, and the other master is offered
    on the condition that its own ISP step passes."""
    cg = r("isp.cgnat", "warn", {"cgnat": True, "double_nat": False, "hop": "100.64.0.1",
                                 "method": "traceroute"}, "isp")
    f = next(f for f in advise([cg], master()) if f.rule == "ros2.cgnat")
    first = f.actions[0]
    for cmd in ("`rosnet-tui relay apply --yes`", "`rosnet-tui relay serve`",
                "`rosnet-tui relay tunnel`", "`rosnet-tui ros apply --yes`"):
        assert cmd in first, first
    assert "connect/endpoints" not in " ".join(f.actions)
    assert "its own ISP step passes" in f.actions[1]
