"""The modem configured for you, proven on a real miniupnpd (Debian's, in the robot modem's
namespace: tests/lab/upnp.py): map and unmap through the product, reachability from the internet
namespace before and after, ROS 2 checks from the member, refusals in words (secure mode, a port
held by another LAN host, carrier-grade NAT), a modem without any of it, each protocol."""

from __future__ import annotations

import json
import sys
import time

import pytest

from tests.lab import ADDR
from tests.lab.ros2 import Ros2World
from tests.lab.upnp import LAN2_IP, UpnpModem
from tests.lab.verdicts import explain

pytestmark = pytest.mark.lab

ZPORT = 7447


def reachable(lab, port: int, ip: str = ADDR.ROBOT_PUBLIC) -> bool:
    """A TCP connection from the internet namespace to the robot's public address."""
    r = lab.run("internet", ["nc", "-z", "-w", "2", ip, str(port)], timeout=10)
    return r.returncode == 0


def rosnet(lab, w: Ros2World, host: str, *args: str, timeout: float = 60):
    return lab.rosnet(host, *args, "--config", str(w.config_path(host)), env=w.env(host),
                      timeout=timeout)


def wait_checks(w: Ros2World, host: str, want: dict[str, str], step: str = "ros",
                tries: int = 4) -> dict:
    """Run a step's checks until the named ones have the wanted status (bounded: *tries* runs;
    a member's router re-links on its own retry timer)."""
    res: dict = {}
    for _ in range(tries):
        res = w.check(host, step=step)
        if all(res[c]["status"] == s for c, s in want.items()):
            return res
        time.sleep(1.0)
    return res


@pytest.fixture
def world(lab):
    with Ros2World(lab) as w:
        yield w


# ---------------------------------------------------------------------------- done when
def test_map_makes_the_member_work_and_undo_takes_it_back(lab, world):
    w = world
    with UpnpModem(lab) as modem:
        assert not reachable(lab, ZPORT), "no forward yet: the router must not be reachable"
        before = w.check("laptop")
        assert before["ros2.router"]["status"] == "fail", explain(before)

        t = time.monotonic()
        r = rosnet(lab, w, "robot", "router", "map", "--yes")
        took = time.monotonic() - t
        assert r.returncode == 0, r.stdout + r.stderr
        assert f"Forwarded TCP {ZPORT} -> {ADDR.ROBOT_LOCAL}:{ZPORT} (UPnP IGD" in r.stdout
        assert "PASS router.upnp" in r.stdout, r.stdout
        assert modem.wait_mapped(ZPORT)
        assert reachable(lab, ZPORT)
        print(f"router map --yes (with the checks after it): {took:.2f} s")

        router = w.check("robot", step="router")
        assert router["router.upnp"]["status"] == "pass", explain(router)
        assert router["router.upnp"]["data"]["present"] == [ZPORT]
        assert router["router.port_open"]["status"] == "pass", explain(router)
        member = wait_checks(w, "laptop", {c: "pass" for c in
                                           ("ros2.router", "ros2.graph", "ros2.pubsub_out",
                                            "ros2.pubsub_in")})
        for cid in ("ros2.router", "ros2.graph", "ros2.pubsub_out", "ros2.pubsub_in"):
            assert member[cid]["status"] == "pass", explain(member)

        r = rosnet(lab, w, "robot", "undo", "--yes")
        assert r.returncode == 0, r.stdout + r.stderr
        assert f"TCP {ZPORT}: removed from the modem" in r.stdout
        assert modem.wait_mapped(ZPORT, present=False)
        assert not reachable(lab, ZPORT)
        # Established sessions outlive a removed forward (the modem's connection tracking):
        # the member's router is restarted so it has to connect anew, as after a reboot.
        w.stop_router("laptop")
        w.start_router("laptop")
        after = w.check("laptop")
        for cid in ("ros2.router", "ros2.graph", "ros2.pubsub_out", "ros2.pubsub_in"):
            assert after[cid]["status"] == "fail", explain(after)
        advice = " ".join(a["meaning"] + " " + " ".join(a["actions"])
                          for a in after["ros2.router"]["advice"])
        assert f"does not forward TCP {ZPORT}" in advice, advice
        assert "rosnet-tui router map" in advice, advice
        # Nothing is left in the journal to undo for the modem.
        r = rosnet(lab, w, "robot", "router", "unmap", "--yes")
        assert "nothing to remove" in r.stdout


def test_mappings_lists_ours_marked_and_map_again_only_renews(lab, world):
    w = world
    with UpnpModem(lab):
        r = rosnet(lab, w, "robot", "router", "map", "--yes", "--no-checks", "--no-test-port")
        assert r.returncode == 0, r.stderr
        r = rosnet(lab, w, "robot", "router", "map", "--yes", "--no-checks", "--no-test-port")
        assert r.returncode == 0, r.stderr
        assert f"Renewed the lease of TCP {ZPORT}" in r.stdout
        assert "Recorded as change" not in r.stdout
        r = rosnet(lab, w, "robot", "router", "mappings", "--json")
        got = json.loads(r.stdout)
        assert got["modem"]["external_ip"] == ADDR.ROBOT_PUBLIC
        assert got["modem"]["wan"] == "public"
        assert [(f["external_port"], f["internal_client"], f["ours"]) for f in got["forwards"]] \
            == [(ZPORT, ADDR.ROBOT_LOCAL, True)]
        assert len(got["recorded"]) == 1
        r = rosnet(lab, w, "robot", "router", "unmap", "--yes")
        assert r.returncode == 0 and f"TCP {ZPORT}: removed from the modem" in r.stdout
        assert not reachable(lab, ZPORT)
        r = rosnet(lab, w, "robot", "undo", "--yes", "--no-checks")
        assert "nothing to undo" in r.stdout   # unmap closed the entry


@pytest.mark.parametrize("protocol", ["pcp", "natpmp"])
def test_each_protocol_maps_and_unmaps(lab, world, protocol):
    w = world
    with UpnpModem(lab) as modem:
        r = rosnet(lab, w, "robot", "router", "map", "--yes", "--no-checks", "--no-test-port",
                   "--protocol", protocol)
        assert r.returncode == 0, r.stdout + r.stderr
        assert modem.wait_mapped(ZPORT)
        assert reachable(lab, ZPORT)
        res = w.check("robot", step="router")
        assert res["router.upnp"]["status"] == "pass", explain(res)
        r = rosnet(lab, w, "robot", "undo", "--yes", "--no-checks")
        assert r.returncode == 0, r.stdout + r.stderr
        assert modem.wait_mapped(ZPORT, present=False)
        assert not reachable(lab, ZPORT)


# ---------------------------------------------------------------------------- refusals
def test_a_port_held_by_another_lan_host_is_a_conflict_and_nothing_changes(lab, world):
    w = world
    with UpnpModem(lab, second_host=True) as modem:
        r = modem.run_lan2(["natpmpc", "-g", ADDR.ROBOT_GW, "-a", str(ZPORT), str(ZPORT), "tcp",
                            "300"])
        assert f"Mapped public port {ZPORT}" in r.stdout, r.stdout + r.stderr
        rules = modem.nat_rules()
        assert LAN2_IP in rules
        r = rosnet(lab, w, "robot", "router", "map", "--yes", "--no-checks")
        assert r.returncode == 1, r.stdout + r.stderr
        assert f"already forwarded to {LAN2_IP}:{ZPORT}, another machine" in r.stderr
        assert "Nothing was changed" in r.stderr
        assert modem.nat_rules() == rules
        res = w.check("robot", step="router")
        assert res["router.upnp"]["status"] == "fail", explain(res)
        assert res["router.upnp"]["data"]["conflicts"][0]["internal_client"] == LAN2_IP
        advice = " ".join(a["meaning"] for a in res["router.upnp"]["advice"])
        assert LAN2_IP in advice
        # NAT-PMP offers another port instead: given back, and refused in words.
        r = rosnet(lab, w, "robot", "router", "map", "--yes", "--no-checks", "--no-test-port",
                   "--protocol", "natpmp")
        assert r.returncode == 1, r.stdout + r.stderr
        assert "another machine" in r.stderr
        assert modem.nat_rules() == rules
        assert json.loads(rosnet(lab, w, "robot", "router", "mappings", "--json").stdout
                          )["recorded"] == []


_SECURE = r"""
import json, sys, time
from rosnet_tui.core.upnp import igd
from rosnet_tui.core.upnp.forwards import Wanted, explain_refusal
from rosnet_tui.core.upnp.modem import find_modem
from rosnet_tui.core.upnp.wire import Refused
m = find_modem(3.0)
out = {}
try:
    m._guard(sys.argv[1], 7447, 3600)
except ValueError as exc:
    out["guard"] = str(exc)
try:
    # Below the product's guard (a test only): ask the modem for another host's address.
    igd.add_mapping(m.igd, "TCP", 7447, sys.argv[1], 7447, "x", 3600, time.monotonic() + 3)
except Refused as exc:
    out["code"] = exc.code
    out["kind"], out["words"] = explain_refusal(m, exc, Wanted("TCP", 7447, 3600, ""))
print(json.dumps(out))
"""


def test_secure_mode_refusal_718_is_explained_and_never_asked_by_the_product(lab):
    with UpnpModem(lab, secure=True) as modem:
        r = lab.run("robot", [sys.executable, "-c", _SECURE, "10.10.10.77"], timeout=30)
        got = json.loads(r.stdout.strip().splitlines()[-1])
        assert "never forwards a port to another machine" in got["guard"]
        assert got["code"] == 718
        assert got["kind"] == "secure_mode"
        assert "secure mode" in got["words"] and "UPnP IGD error 718" in got["words"]
        assert "10.10.10.77" not in modem.nat_rules()


# ---------------------------------------------------------------------------- other modems
def test_a_modem_without_upnp_skips_fast(lab, world):
    w = world
    res = w.check("robot", step="router")
    r = res["router.upnp"]
    assert r["status"] == "skip", explain(res)
    assert "no modem answered" in r["summary"]
    # Fast because each protocol ended on the modem's own "closed" (ICMP port unreachable), not
    # on a timeout: the notes say so (the event); the time is held only to the check's budget.
    tried = " | ".join(r["data"]["tried"])
    assert "does not listen for UPnP searches" in tried, tried
    assert tried.count("is closed (the modem does not speak it)") == 2, tried  # NAT-PMP, PCP
    limit = 3.0 * 1.5
    assert r["duration_s"] < limit, r["duration_s"]
    print(f"router.upnp with no modem to ask: {r['duration_s']:.2f} s (budget {limit:g} s)")
    t = time.monotonic()
    p = rosnet(lab, w, "robot", "router", "map", "--yes")
    assert p.returncode == 1 and "no modem answered" in p.stderr
    assert time.monotonic() - t < 10


def test_cgnat_modem_refuses_in_words_and_isp_cgnat_uses_it(lab, world):
    w = world
    with lab.variant("cgnat"):
        w.forward()
        with UpnpModem(lab, stun=False) as modem:
            for protocol, code in (("auto", "UPnP IGD error 501"), ("natpmp", "NAT-PMP error 3"),
                                   ("pcp", "PCP error 8")):
                r = rosnet(lab, w, "robot", "router", "map", "--yes", "--no-checks",
                           "--protocol", protocol)
                assert r.returncode == 1, r.stdout + r.stderr
                assert "carrier-grade NAT" in r.stderr, r.stderr
                assert code in r.stderr, r.stderr
                assert "nothing was changed" in r.stderr
            assert f"dport {ZPORT}" not in modem.nat_rules()
            res = w.check("robot", step="router")
            u = res["router.upnp"]
            assert u["status"] == "warn" and u["data"]["cgnat"] is True, explain(res)
            assert u["data"]["external_ip"] == "" and u["data"]["wan"] == "none"
            isp = w.check("robot", step="isp")["isp.cgnat"]
            assert isp["data"]["cgnat"] is True, isp
            assert isp["data"]["method"] == "upnp" and isp["data"]["wan_ip"] == ""
            assert "no public address" in isp["summary"], isp["summary"]


def test_isp_cgnat_reads_the_modems_empty_external_address_as_carrier_nat(lab, world):
    """miniupnpd behind carrier NAT reports an EMPTY external address (not 100.64.x): that is
    the modem's own word for carrier-grade NAT, and isp.cgnat must read it as such."""
    w = world
    with lab.variant("cgnat"), UpnpModem(lab, stun=False):
        isp = w.check("robot", step="isp")["isp.cgnat"]
        assert isp["data"]["method"] == "upnp", isp
        assert isp["data"]["wan_ip"] == "", isp
        assert isp["data"]["cgnat"] is True, isp
        assert "no public address" in isp["summary"], isp["summary"]
        assert not any(e.rstrip().endswith("WAN address is") for e in isp["evidence"]), isp


# ---------------------------------------------------------------------------- leases and undo
def test_sync_renews_our_lease_and_removes_the_forward_when_stopped_if_asked(lab, world,
                                                                              tmp_path):
    import signal

    from rosnet_tui.core.config.settings_model import SyncSettings
    from rosnet_tui.core.saved.settings import atomic_write_text, render_settings

    w = world
    sd = tmp_path / "state"
    with UpnpModem(lab) as modem:
        r = rosnet(lab, w, "robot", "router", "map", "--yes", "--no-checks", "--no-test-port",
                   "--lease", "120", "--state-dir", str(sd))
        assert r.returncode == 0, r.stdout + r.stderr
        entry = next((sd / "journal").glob("*.json"))
        doc = json.loads(entry.read_text())
        doc["mappings"][0]["renewed_at"] -= 100          # most of the lease is gone
        entry.write_text(json.dumps(doc))
        s = w.settings("robot")
        (tmp_path / "shared").mkdir()
        s.sync = SyncSettings(store="folder", folder=str(tmp_path / "shared"), interval_s=2.0)
        s.has_sync = True
        cfg = tmp_path / "sync.toml"
        atomic_write_text(cfg, render_settings(s), mode=0o644)
        hosts = tmp_path / "hosts"
        hosts.write_text("127.0.0.1 localhost\n")
        proc = lab.spawn("robot", [sys.executable, "-m", "rosnet_tui", "sync", "--config",
                                   str(cfg), "--state-dir", str(sd), "--hosts-file", str(hosts),
                                   "--no-bashrc", "--no-checks", "--no-save-settings",
                                   "--unmap-on-stop"], env=w.env("robot"))
        try:
            assert lab.wait_output(proc, r"modem: renewed TCP 7447", timeout=20), \
                lab.output(proc)
            renewed = json.loads(entry.read_text())["mappings"][0]
            assert time.time() - renewed["renewed_at"] < 30
            assert reachable(lab, ZPORT)
            proc.send_signal(signal.SIGTERM)
            assert lab.wait_output(proc, r"sync stopped", timeout=20), lab.output(proc)
        finally:
            lab.kill(proc)
        assert "TCP 7447: removed from the modem" in lab.output(proc)
        assert modem.wait_mapped(ZPORT, present=False)
        assert not reachable(lab, ZPORT)


def test_undo_refuses_when_the_modem_is_gone_and_force_forgets(lab, world):
    w = world
    with UpnpModem(lab) as modem:
        r = rosnet(lab, w, "robot", "router", "map", "--yes", "--no-checks", "--no-test-port")
        assert r.returncode == 0, r.stderr
        modem.stop()                                # the robot is on another network now
        r = rosnet(lab, w, "robot", "undo", "--yes", "--no-checks")
        assert r.returncode == 1, r.stdout + r.stderr
        assert "cannot remove TCP 7447" in r.stderr and "no modem answers" in r.stderr
        assert "Nothing was changed" in r.stderr
        r = rosnet(lab, w, "robot", "undo", "--yes", "--no-checks", "--force")
        assert r.returncode == 0, r.stdout + r.stderr
        assert "forgotten, not removed" in r.stdout
        r = rosnet(lab, w, "robot", "undo", "--yes", "--no-checks")
        assert "nothing to undo" in r.stdout


def test_isp_cgnat_is_not_fooled_by_a_modem_that_learned_the_carriers_address_by_stun(lab, world):
    """With STUN, miniupnpd behind carrier NAT reports the carrier's public address as its own;
    the path still shows the carrier's 100.64 hop, and that wins."""
    w = world
    with lab.variant("cgnat"), UpnpModem(lab, stun=True):
        isp = w.check("robot", step="isp")["isp.cgnat"]
        assert isp["data"]["cgnat"] is True, isp
        assert isp["data"]["wan_ip"] == ADDR.CARRIER_PUBLIC, isp
        res = w.check("robot", step="router")
        r = rosnet(lab, w, "robot", "router", "map", "--yes", "--no-checks")
        assert r.returncode == 1, r.stdout + r.stderr
        assert "UPnP IGD error 501" in r.stderr, r.stderr
        assert res["router.upnp"]["status"] in ("warn", "fail"), explain(res)
