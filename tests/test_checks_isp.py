"""ISP checks on loopback: a local what-is-my-IP web server, the real probe server, real sockets
(the ``web`` and ``probe_server`` fixtures are in tests/plugins/web.py)."""

from __future__ import annotations

import json
from pathlib import Path

from rosnet_tui.core.checks import REGISTRY, CheckContext, load_builtin_checks, run_check
from rosnet_tui.core.checks.isp import Hop, judge_path, judge_wan, ttl_probe
from rosnet_tui.core.config.paths import Paths
from rosnet_tui.core.config.settings_model import ProbeSettings, Settings, ThisComponent
from rosnet_tui.core.exposure.public_ip import parse_ip
from rosnet_tui.core.results import Status
from rosnet_tui.core.saved.state import public_ip_history, record_public_ip
from rosnet_tui.core.ssh.options import SshOptions
from tests.builders import free_port

load_builtin_checks()


def make_ctx(tmp_path: Path, urls: list[str], port_check_url: str = "http://127.0.0.1:9",
             public_ip: str = "", timeout: float = 2.0) -> CheckContext:
    s = Settings(this=ThisComponent(name="turtlebot", local_ip="127.0.0.1", public_ip=public_ip),
                 probe=ProbeSettings(port=free_port(), public_ip_urls=urls,
                                     port_check_url=port_check_url))
    return CheckContext(settings=s, timeout_s=timeout, paths=Paths(state_dir=tmp_path / "state"),
                        upnp=False, ssh_options=SshOptions(ssh_agent=False, ssh_dir=tmp_path / "no-ssh"))


async def run(check_id: str, ctx: CheckContext):
    return await run_check(REGISTRY[check_id], ctx)


# --------------------------------------------------------------------------- isp.internet
async def test_internet_passes_with_dns_and_http(web, tmp_path):
    web.routes["/ip"] = (200, "203.0.113.9\n")
    web.routes["/"] = (200, "203.0.113.9\n")
    r = await run("isp.internet", make_ctx(tmp_path, [web.url("/ip", "localhost")], web.url("/")))
    assert r.status is Status.PASS, r
    assert r.data["dns_ok"] is True and r.data["http_ok"] is True and r.data["failed_part"] is None
    assert r.data["url"] == web.url("/ip", "localhost")
    assert any("resolve localhost -> 127.0.0.1" in e for e in r.evidence)


async def test_internet_says_http_failed_when_nothing_answers(tmp_path):
    dead = f"http://localhost:{free_port()}/ip"
    r = await run("isp.internet", make_ctx(tmp_path, [dead], dead))
    assert r.status is Status.FAIL
    assert r.data["failed_part"] == "http" and r.data["dns_ok"] is True and r.data["http_ok"] is False
    assert "refused" in " ".join(r.evidence)


async def test_internet_warns_when_one_endpoint_fails(web, tmp_path):
    web.routes["/ip"] = (200, "203.0.113.9")
    r = await run("isp.internet", make_ctx(tmp_path, [web.url("/ip")], web.url("/broken")))
    assert r.status is Status.WARN
    assert r.data["url"] == web.url("/broken") and r.data["http_ok"] is False
    assert r.data["dns_ok"] is None  # an IP literal needs no DNS


# --------------------------------------------------------------------------- isp.public_ip
async def test_public_ip_agrees_records_history_and_notices_a_change(web, tmp_path):
    web.routes["/a"] = (200, "203.0.113.9\n")
    web.routes["/b"] = (200, '{"ip": "203.0.113.9", "country": "x"}')
    ctx = make_ctx(tmp_path, [web.url("/a"), web.url("/b")], public_ip="203.0.113.9")
    r = await run("isp.public_ip", ctx)
    assert r.status is Status.PASS, r.summary
    d = r.data
    assert d["public_ip"] == "203.0.113.9" and d["agree"] and d["matches_settings"] is True
    assert d["previous_ip"] is None and d["changed"] is False and len(d["history"]) == 1
    assert d["sources"] == {web.url("/a"): "203.0.113.9", web.url("/b"): "203.0.113.9"}

    r = await run("isp.public_ip", ctx)  # same address again: still one history entry
    assert r.status is Status.PASS and r.data["previous_ip"] == "203.0.113.9"
    assert len(r.data["history"]) == 1 and "unchanged since" in r.summary

    web.routes["/a"] = web.routes["/b"] = (200, "203.0.113.77")  # the modem restarted
    r = await run("isp.public_ip", ctx)
    assert r.status is Status.WARN
    assert r.data["changed"] and r.data["previous_ip"] == "203.0.113.9"
    assert r.data["matches_settings"] is False and "203.0.113.9" in r.summary
    history = public_ip_history(ctx.paths.state_dir)
    assert [h["ip"] for h in history] == ["203.0.113.9", "203.0.113.77"]


async def test_under_a_relay_a_moved_address_does_not_send_peers_to_their_hosts_files(
        web, tmp_path):
    """Under a relay (ROS 2) the peers reach this component through the relay: the summary
    said to update the peers' hosts files when the address moved. With its own tunnel nothing
    uses the address (a pass that says so); without one only the peers' SSH does (a warning
    that says that much). The data fields stay as they are."""
    from rosnet_tui.core.config.settings_model import RelaySettings, RosSettings

    web.routes["/a"] = (200, "203.0.113.9")
    ctx = make_ctx(tmp_path, [web.url("/a")], public_ip="203.0.113.9")
    ctx.settings.ros = RosSettings(version=2, master="turtlebot", security="mtls")
    ctx.settings.relay = RelaySettings(host="relay", tunnels={"turtlebot": 2201})
    assert (await run("isp.public_ip", ctx)).status is Status.PASS
    web.routes["/a"] = (200, "203.0.113.77")                    # the carrier moved it
    r = await run("isp.public_ip", ctx)
    assert r.status is Status.PASS, r.summary
    assert "hosts" not in r.summary and "through the relay relay" in r.summary, r.summary
    assert "was 203.0.113.9" in r.summary and "does not matter" in r.summary
    assert r.data["changed"] and r.data["matches_settings"] is False
    assert r.data["previous_ip"] == "203.0.113.9" and r.data["public_ip"] == "203.0.113.77"
    ctx.settings.relay.tunnels = {}                  # no tunnel: the peers SSH to this address
    web.routes["/a"] = (200, "203.0.113.78")
    r = await run("isp.public_ip", ctx)
    assert r.status is Status.WARN and r.data["changed"], r.summary
    assert "the ROS path goes through the relay relay and does not use it" in r.summary
    assert "SSH" in r.summary


async def test_public_ip_sources_that_disagree_fail(web, tmp_path):
    web.routes["/a"] = (200, "203.0.113.9")
    web.routes["/b"] = (200, "198.51.100.4")
    r = await run("isp.public_ip", make_ctx(tmp_path, [web.url("/a"), web.url("/b")]))
    assert r.status is Status.FAIL and r.data["agree"] is False and "disagree" in r.summary
    assert not (tmp_path / "state" / "public_ip.json").exists()


async def test_public_ip_with_one_broken_source_warns(web, tmp_path):
    web.routes["/a"] = (200, "203.0.113.9")
    web.routes["/b"] = (200, "<html>hello</html>")
    r = await run("isp.public_ip", make_ctx(tmp_path, [web.url("/a"), web.url("/b")]))
    assert r.status is Status.WARN and r.data["public_ip"] == "203.0.113.9"
    assert r.data["agree"] is False and r.data["sources"][web.url("/b")].startswith("error:")


async def test_public_ip_without_any_answer_fails(tmp_path):
    r = await run("isp.public_ip", make_ctx(tmp_path, [f"http://127.0.0.1:{free_port()}/ip"]))
    assert r.status is Status.FAIL and r.data["public_ip"] is None


async def test_public_ip_from_the_real_probe_server_is_the_callers(probe_server, tmp_path):
    r = await run("isp.public_ip", make_ctx(tmp_path, [probe_server.url + "/ip", probe_server.url + "/"]))
    assert r.data["public_ip"] == "127.0.0.1" and r.data["agree"]
    assert r.status is Status.WARN and "not a public address" in r.summary


def test_state_history_is_atomic_json_and_bounded(tmp_path):
    for i in range(120):
        record_public_ip(tmp_path, f"203.0.113.{i % 2 + 1}", when=f"2024-01-01T00:00:{i:02d}")
    data = json.loads((tmp_path / "public_ip.json").read_text())
    assert len(data["history"]) == 100
    (tmp_path / "public_ip.json").write_text("{broken")
    rec = record_public_ip(tmp_path, "203.0.113.5")
    assert rec.previous_ip is None and len(rec.history) == 1


def test_parse_ip():
    assert parse_ip("203.0.113.4\n") == "203.0.113.4"
    assert parse_ip('{"ip":"198.51.100.2"}') == "198.51.100.2"
    assert parse_ip("<html>") is None and parse_ip("2001:db8::1") is None


# --------------------------------------------------------------------------- isp.cgnat
async def test_ttl_probe_reaches_loopback_in_one_hop():
    hops = await ttl_probe("127.0.0.1", 4, 1.0)
    assert hops == [Hop(1, "127.0.0.1", reached=True)]


async def test_cgnat_check_does_not_probe_a_service_on_this_machine(web, tmp_path):
    web.routes["/ip"] = (200, "203.0.113.9")
    r = await run("isp.cgnat", make_ctx(tmp_path, [web.url("/ip")]))
    assert r.status is Status.SKIP and "this machine" in r.summary
    assert r.data["method"] == "none" and r.data["cgnat"] is False


def test_judging_the_path_out():
    public = [Hop(1, "10.10.10.254"), Hop(2, "203.0.113.1"), Hop(3, "192.0.2.10", True)]
    assert judge_path(public, "192.0.2.10", "10.10.10.1")[0] is Status.PASS
    cgn = [Hop(1, "10.10.10.254"), Hop(2, "100.64.0.1"), Hop(3, None)]
    st, summary, upd = judge_path(cgn, "192.0.2.10", "10.10.10.1")
    assert st is Status.WARN and upd == {"cgnat": True, "hop": "100.64.0.1"} and "hop 2" in summary
    double = [Hop(1, "192.168.1.1"), Hop(2, "192.168.0.1"), Hop(3, "203.0.113.1")]
    assert judge_path(double, "192.0.2.10", "192.168.1.5")[2] == {"double_nat": True,
                                                                  "hop": "192.168.0.1"}
    # A first hop in the carrier range is our own LTE modem's gateway: the source tells.
    assert judge_path([Hop(1, "100.64.0.1")], "192.0.2.10", "100.70.1.2")[2]["cgnat"]
    assert judge_path([Hop(1, "10.0.0.1"), Hop(2, None)], "192.0.2.10", "10.0.0.2")[0] is Status.PASS


def test_judging_the_modem_wan_address():
    assert judge_wan("100.64.3.2", None)[2] == {"cgnat": True, "hop": "100.64.3.2"}
    assert judge_wan("192.168.0.20", None)[2]["double_nat"]
    assert judge_wan("203.0.113.2", "203.0.113.99")[2]["double_nat"]
    assert judge_wan("203.0.113.2", "203.0.113.2")[0] is Status.PASS


async def test_public_ip_still_answers_when_the_state_folder_is_unusable(web, tmp_path):
    web.routes["/a"] = (200, "203.0.113.9")
    ctx = make_ctx(tmp_path, [web.url("/a")])
    ctx.paths = Paths(state_dir=tmp_path / "a-file")
    ctx.paths.state_dir.write_text("not a folder")
    r = await run("isp.public_ip", ctx)
    assert r.status is Status.PASS and r.data["public_ip"] == "203.0.113.9"
    assert any("could not record" in e for e in r.evidence)
