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
