"""The advisor's ISP rules (no internet, the public address): the finding's words and links."""

from __future__ import annotations

from rosnet_tui.core.advisor import first_failure
from tests.advisor_support import (
    changed,
    differs,
    disagree,
    ids,
    no_dns,
    no_http,
    only,
    public_unknown,
    run,
    text,
)
from tests.builders import healthy_laptop, put


def test_no_internet_dns_vs_http():
    fs = run(no_dns()[0])
    assert "isp.no_internet.http" not in ids(fs)
    f = only(fs, "isp.no_internet.dns")
    assert "probe.lab.test" in text(f) and "resolv" in text(f)
    assert first_failure(fs) is f
    fs = run(no_http()[0])
    assert "isp.no_internet.dns" not in ids(fs)
    assert "captive portal" in text(only(fs, "isp.no_internet.http"))


def test_public_ip_unknown_is_superseded_by_no_internet():
    r, s = public_unknown()
    put(r, "isp.internet", "fail", dns_ok=False, failed_part="dns")
    fs = run(r, s)
    assert "isp.public_ip.unknown" not in ids(fs)


def test_public_ip_disagree_names_both_addresses_and_ignores_errors():
    f = only(run(disagree()[0]), "isp.public_ip.disagree")
    assert "198.51.100.2" in f.meaning and "192.0.2.77" in f.meaning
    r = healthy_laptop()
    put(r, "isp.public_ip", "warn", sources={"http://a/ip": "198.51.100.2",
                                             "http://b/ip": "error: timed out"}, agree=False)
    assert "isp.public_ip.disagree" not in ids(run(r))


def test_public_ip_changed_points_to_sync_and_peers_hosts():
    fs = run(changed()[0])
    f = only(fs, "isp.public_ip.changed")
    t = text(f)
    assert "rosnet-tui sync" in t
    assert "`198.51.100.9 sami`" in t and "on turtlebot" in t
    assert 'public_ip = "198.51.100.9"' in t
    assert "isp.public_ip.differs" not in ids(fs)      # superseded


def test_public_ip_differs_from_settings():
    f = only(run(differs()[0]), "isp.public_ip.differs")
    assert "198.51.100.9" in f.meaning and "198.51.100.2" in f.meaning
    assert 'public_ip = "198.51.100.9"' in text(f)


def test_under_a_relay_a_moved_address_is_only_news_for_ssh():
    """Under a relay the ROS path never uses this component's address: with its own tunnel the
    moved address asks nothing; without one the finding says only SSH to it needs the new one."""
    from rosnet_tui.core.config.settings_model import RelaySettings

    for case in (changed, differs):
        r, s = case()
        s.ros.version, s.ros.security = 2, "mtls"
        s.relay = RelaySettings(host="relay", tunnels={"sami": 2202})
        assert not [i for i in ids(run(r, s)) if i.startswith("isp.public_ip")], case
        s.relay.tunnels = {"turtlebot": 2201}
        f = only(run(r, s), f"isp.public_ip.{case.__name__}")
        assert "the ROS path goes through the relay relay" in f.meaning, f.meaning
        assert "SSH" in f.meaning
    r, s = public_unknown()
    s.ros.version, s.ros.security = 2, "mtls"
    s.relay = RelaySettings(host="relay", tunnels={"sami": 2202})
    t = text(only(run(r, s), "isp.public_ip.unknown"))
    assert "its public address does not matter" in t and "no peer can be given" not in t
