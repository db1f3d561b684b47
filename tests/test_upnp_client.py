"""The UPnP IGD / NAT-PMP / PCP client against broken and hostile modems, played by small servers
on loopback: huge or endless answers, entities, wrong types, addresses of other hosts, garbage
datagrams. Each is refused with a clear message, within its deadline, and nothing is used."""

from __future__ import annotations

import socket
import struct
import threading
import time
from collections.abc import Callable

import pytest

from rosnet_tui.core.files import undo_journal as uj
from rosnet_tui.core.upnp import igd, pmp, wire
from rosnet_tui.core.upnp.forwards import Wanted, explain_refusal, needs, wan_kind
from rosnet_tui.core.upnp.modem import Modem
from rosnet_tui.core.upnp.wire import HostileAnswer, NoAnswer, Refused

HOST = "127.0.0.1"


class FakeHttp:
    """A one-thread HTTP server on loopback; *reply(request bytes) -> raw bytes or a callable
    that writes to the socket itself*."""

    def __init__(self, reply: Callable[[bytes], bytes | Callable[[socket.socket], None]]) -> None:
        self.reply = reply
        self.sock = socket.socket()
        self.sock.bind((HOST, 0))
        self.sock.listen(8)
        self.port = self.sock.getsockname()[1]
        self.requests: list[bytes] = []
        self.stop = False
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def url(self, path: str = "/rootDesc.xml") -> str:
        return f"http://{HOST}:{self.port}{path}"

    def _serve(self) -> None:
        self.sock.settimeout(0.1)
        while not self.stop:
            try:
                conn, _ = self.sock.accept()
            except OSError:
                continue
            with conn:
                conn.settimeout(2)
                data = b""
                try:
                    while b"\r\n\r\n" not in data:
                        data += conn.recv(4096)
                    head, _, body = data.partition(b"\r\n\r\n")
                    n = next((int(ln.split(b":")[1]) for ln in head.split(b"\r\n")
                              if ln.lower().startswith(b"content-length")), 0)
                    while len(body) < n:
                        body += conn.recv(4096)
                    self.requests.append(head + b"\r\n\r\n" + body)
                    out = self.reply(head + b"\r\n\r\n" + body)
                    if callable(out):
                        out(conn)
                    else:
                        conn.sendall(out)
                except OSError:
                    pass

    def close(self) -> None:
        self.stop = True
        self.sock.close()
        self.thread.join(2)


@pytest.fixture
def serve():
    servers: list[FakeHttp] = []

    def make(reply):
        s = FakeHttp(reply)
        servers.append(s)
        return s

    yield make
    for s in servers:
        s.close()


def http(body: bytes | str, status: str = "200 OK", extra: str = "") -> bytes:
    if isinstance(body, str):
        body = body.encode()
    return (f"HTTP/1.1 {status}\r\nContent-Type: text/xml\r\n{extra}Content-Length: {len(body)}"
            f"\r\n\r\n").encode() + body


def description(control: str = "/ctl/IPConn", base: str = "") -> str:
    return (f'<?xml version="1.0"?><root xmlns="urn:schemas-upnp-org:device-1-0">{base}<device>'
            "<deviceType>urn:schemas-upnp-org:device:InternetGatewayDevice:2</deviceType>"
            "<friendlyName>fake modem</friendlyName><UDN>uuid:1234</UDN><deviceList><device>"
            "<serviceList><service><serviceType>urn:schemas-upnp-org:service:WANIPConnection:2"
            f"</serviceType><controlURL>{control}</controlURL></service></serviceList></device>"
            "</deviceList></device></root>")


def soap_ok(action: str, **out: str) -> str:
    args = "".join(f"<{k}>{v}</{k}>" for k, v in out.items())
    return ('<?xml version="1.0"?><s:Envelope xmlns:s="http://schemas.xmlsoap.org/soap/envelope/">'
            f'<s:Body><u:{action}Response xmlns:u="urn:x">{args}</u:{action}Response></s:Body>'
            "</s:Envelope>")


def soap_error(code: str, desc: str = "ConflictInMappingEntry") -> str:
    return ('<?xml version="1.0"?><s:Envelope xmlns:s="http://schemas.xmlsoap.org/soap/envelope/">'
            "<s:Body><s:Fault><faultcode>s:Client</faultcode><faultstring>UPnPError</faultstring>"
            '<detail><UPnPError xmlns="urn:schemas-upnp-org:control-1-0">'
            f"<errorCode>{code}</errorCode><errorDescription>{desc}</errorDescription>"
            "</UPnPError></detail></s:Fault></s:Body></s:Envelope>")


def igd_at(server: FakeHttp) -> igd.Igd:
    return igd.Igd(HOST, server.url(), server.url("/ctl"), igd.WAN_SERVICES[0], "uuid:1234")


def soon(s: float = 2.0) -> float:
    return time.monotonic() + s


# --------------------------------------------------------------------------- description
def test_a_good_description_gives_the_wan_service_on_the_same_host(serve):
    s = serve(lambda req: http(description()))
    got = igd.describe(s.url(), HOST, soon())
    assert got.control_url == s.url("/ctl/IPConn")
    assert (got.udn, got.friendly_name, got.version) == ("uuid:1234", "fake modem", 2)


@pytest.mark.parametrize("control", ["http://192.0.2.66:5000/ctl", "//192.0.2.66/ctl",
                                     "https://127.0.0.1/ctl", "file:///etc/passwd"])
def test_a_control_url_to_another_host_or_scheme_is_refused(serve, control):
    s = serve(lambda req: http(description(control)))
    with pytest.raises(HostileAnswer, match="another host|only plain http"):
        igd.describe(s.url(), HOST, soon())


def test_a_urlbase_to_another_host_is_refused(serve):
    s = serve(lambda req: http(description(base="<URLBase>http://192.0.2.66:80/</URLBase>")))
    with pytest.raises(HostileAnswer, match="another host"):
        igd.describe(s.url(), HOST, soon())


def test_a_redirect_is_not_followed(serve):
    s = serve(lambda req: http("", "302 Found", "Location: http://192.0.2.66/rootDesc.xml\r\n"))
    with pytest.raises(HostileAnswer, match="HTTP 302"):
        igd.describe(s.url(), HOST, soon())
    assert len(s.requests) == 1


def test_entities_are_refused_before_parsing(serve):
    bomb = ('<?xml version="1.0"?><!DOCTYPE r [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;">'
            ']><root><device><UDN>&b;</UDN></device></root>')
    s = serve(lambda req: http(bomb))
    with pytest.raises(HostileAnswer, match="DOCTYPE or entities"):
        igd.describe(s.url(), HOST, soon())


def test_a_huge_answer_is_refused_early(serve):
    s = serve(lambda req: http(b"<root>" + b"x" * (3 * 1024 * 1024) + b"</root>"))
    t = time.monotonic()
    with pytest.raises(HostileAnswer, match="announces a body|larger than"):
        igd.describe(s.url(), HOST, soon(30))
    assert time.monotonic() - t < 10      # refused early: far from the 30 s deadline


def test_an_endless_answer_without_length_is_cut_off(serve):
    def endless(conn: socket.socket) -> None:
        conn.sendall(b"HTTP/1.1 200 OK\r\nContent-Type: text/xml\r\n\r\n<root>")
        with pytest.raises(OSError):
            for _ in range(10_000):
                conn.sendall(b"<a>x</a>" * 512)

    s = serve(lambda req: endless)
    with pytest.raises(HostileAnswer, match="larger than"):
        igd.describe(s.url(), HOST, soon())


def test_a_slow_drip_is_stopped_at_the_deadline(serve):
    def drip(conn: socket.socket) -> None:
        try:
            for _ in range(100):
                conn.sendall(b"H")
                time.sleep(0.1)
        except OSError:
            pass

    s = serve(lambda req: drip)
    t = time.monotonic()
    with pytest.raises(NoAnswer, match="in time"):
        igd.describe(s.url(), HOST, soon(0.8))
    assert time.monotonic() - t < 5       # at its 0.8 s deadline, not the drip's 10 s


def test_not_xml_and_not_http_are_refused(serve):
    s = serve(lambda req: http("<root><device>"))
    with pytest.raises(HostileAnswer, match="not well-formed"):
        igd.describe(s.url(), HOST, soon())
    s2 = serve(lambda req: b"SSH-2.0-OpenSSH\r\n\r\n")
    with pytest.raises(HostileAnswer, match="not HTTP"):
        igd.describe(s2.url(), HOST, soon())


def test_a_chunked_description_is_read(serve):
    body = description().encode()
    chunked = b"".join(b"%x\r\n%s\r\n" % (len(body[i:i + 100]), body[i:i + 100])
                       for i in range(0, len(body), 100)) + b"0\r\n\r\n"
    s = serve(lambda req: b"HTTP/1.1 200 OK\r\nTransfer-Encoding: chunked\r\n\r\n" + chunked)
    assert igd.describe(s.url(), HOST, soon()).udn == "uuid:1234"


# --------------------------------------------------------------------------- SOAP
@pytest.mark.parametrize("field,value,match", [
    ("NewInternalPort", "abc", "not a port"),
    ("NewInternalPort", "70000", "not a port"),
    ("NewInternalClient", "evil.example", "not an IPv4"),
    ("NewInternalClient", "::1", "not an IPv4"),
    ("NewLeaseDuration", "-5", "seconds"),
    ("NewEnabled", "maybe", "yes/no"),
    ("NewPortMappingDescription", "x" * 300, "characters long"),
])
def test_wrong_types_in_an_answer_are_refused(serve, field, value, match):
    good = {"NewInternalPort": "7447", "NewInternalClient": "10.10.10.1", "NewEnabled": "1",
            "NewPortMappingDescription": "rosnet-tui", "NewLeaseDuration": "3600"}
    good[field] = value
    s = serve(lambda req: http(soap_ok("GetSpecificPortMappingEntry", **good)))
    with pytest.raises(HostileAnswer, match=match):
        igd.get_mapping(igd_at(s), "TCP", 7447, soon())


def test_an_external_address_that_is_not_one_is_refused(serve):
    s = serve(lambda req: http(soap_ok("GetExternalIPAddress",
                                       NewExternalIPAddress="<b>1.2.3.4</b>".replace("<", "&lt;"))))
    with pytest.raises(HostileAnswer, match="not an IPv4"):
        igd.external_ip(igd_at(s), soon())
    empty = serve(lambda req: http(soap_ok("GetExternalIPAddress", NewExternalIPAddress="")))
    assert igd.external_ip(igd_at(empty), soon()) == ""


def test_a_upnp_error_becomes_a_refusal_in_words_and_a_bad_one_is_refused(serve):
    s = serve(lambda req: http(soap_error("718"), "500 Internal Server Error"))
    with pytest.raises(Refused) as exc:
        igd.add_mapping(igd_at(s), "TCP", 7447, "10.10.10.1", 7447, "x", 3600, soon())
    assert exc.value.code == 718 and "another machine" in exc.value.words
    assert b"<NewInternalClient>10.10.10.1</NewInternalClient>" in s.requests[-1]
    bad = serve(lambda req: http(soap_error("7x8"), "500 Internal Server Error"))
    with pytest.raises(HostileAnswer, match="malformed UPnP error"):
        igd.add_mapping(igd_at(bad), "TCP", 7447, "10.10.10.1", 7447, "x", 3600, soon())


def test_listing_stops_at_the_end_and_at_a_cap(serve, monkeypatch):
    entry = soap_ok("GetGenericPortMappingEntry", NewRemoteHost="", NewExternalPort="7447",
                    NewProtocol="TCP", NewInternalPort="7447", NewInternalClient="10.10.10.1",
                    NewEnabled="1", NewPortMappingDescription="d", NewLeaseDuration="0")
    n = {"i": 0}

    def reply(req: bytes) -> bytes:
        n["i"] += 1
        return http(entry) if n["i"] <= 2 else http(soap_error("713", "x"), "500 Error")

    s = serve(reply)
    assert len(igd.list_mappings(igd_at(s), soon())) == 2
    forever = serve(lambda req: http(entry))
    monkeypatch.setattr(igd, "MAX_LISTED", 5)
    assert len(igd.list_mappings(igd_at(forever), soon())) == 5


def test_a_description_is_escaped_in_the_request(serve):
    s = serve(lambda req: http(soap_ok("AddPortMapping")))
    igd.add_mapping(igd_at(s), "TCP", 7447, "10.10.10.1", 7447, "a<b>&c", 3600, soon())
    assert b"a&lt;b&gt;&amp;c" in s.requests[-1]


# --------------------------------------------------------------------------- SSDP
def test_ssdp_answers_are_checked():
    ok = (b"HTTP/1.1 200 OK\r\nST: urn:schemas-upnp-org:device:InternetGatewayDevice:2\r\n"
          b"LOCATION: http://10.10.10.254:5000/rootDesc.xml\r\n\r\n")
    assert wire.parse_ssdp(ok, "10.10.10.254").location.endswith(":5000/rootDesc.xml")
    with pytest.raises(HostileAnswer, match="another host"):
        wire.parse_ssdp(ok, "10.10.10.9")
    with pytest.raises(HostileAnswer, match="bytes: refused"):
        wire.parse_ssdp(ok + b"X-Pad: " + b"x" * 3000 + b"\r\n", "10.10.10.254")
    with pytest.raises(HostileAnswer, match="without LOCATION"):
        wire.parse_ssdp(b"HTTP/1.1 200 OK\r\nST: x\r\n\r\n", "10.10.10.254")


# --------------------------------------------------------------------------- NAT-PMP and PCP
class FakeUdp:
    def __init__(self, answers: Callable[[bytes], list[bytes]]) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((HOST, 0))
        self.port = self.sock.getsockname()[1]
        self.answers = answers
        self.got: list[bytes] = []
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.stop = False
        self.thread.start()

    def _serve(self) -> None:
        self.sock.settimeout(0.05)
        while not self.stop:
            try:
                data, addr = self.sock.recvfrom(2048)
            except OSError:
                continue
            self.got.append(data)
            for a in self.answers(data):
                self.sock.sendto(a, addr)

    def close(self) -> None:
        self.stop = True
        self.thread.join(2)
        self.sock.close()


@pytest.fixture
def udp(monkeypatch):
    made: list[FakeUdp] = []

    def make(answers):
        u = FakeUdp(answers)
        monkeypatch.setattr(pmp, "PORT", u.port)
        made.append(u)
        return u

    yield make
    for u in made:
        u.close()


def test_natpmp_garbage_is_ignored_and_the_real_answer_taken(udp):
    good = struct.pack("!BBHI", 0, 128, 0, 99) + socket.inet_aton("203.0.113.2")
    udp(lambda req: [b"\x00", b"\x00\x80\x00\x00" + b"x" * 40, b"junk" * 100, good])
    notes: list[str] = []
    assert pmp.natpmp_external(HOST, soon(), notes=notes) == ("203.0.113.2", 99)
    assert any("12 expected" in n for n in notes)


def test_natpmp_only_garbage_ends_in_no_answer_at_the_deadline(udp):
    u = udp(lambda req: [b"\x00\x80\x00\x00" + b"x" * 40])
    t = time.monotonic()
    with pytest.raises(NoAnswer):
        pmp.natpmp_external(HOST, soon(0.6))
    assert time.monotonic() - t < 5       # at its 0.6 s deadline, not NAT-PMP's retries (64 s)
    assert len(u.got) >= 2   # retransmitted (250 ms, then 500 ms)


def test_natpmp_network_failure_is_a_refusal_in_words(udp):
    udp(lambda req: [struct.pack("!BBHI", 0, 128, 3, 1) + b"\x00" * 4])
    with pytest.raises(Refused) as exc:
        pmp.natpmp_external(HOST, soon())
    assert exc.value.code == 3 and "no public address" in exc.value.words


def test_a_closed_port_answers_at_once(monkeypatch):
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind((HOST, 0))
    monkeypatch.setattr(pmp, "PORT", s.getsockname()[1])
    s.close()
    t = time.monotonic()
    with pytest.raises(NoAnswer, match="closed"):
        pmp.natpmp_external(HOST, soon(30))
    assert time.monotonic() - t < 10      # at once: far from the 30 s deadline


def test_pcp_answers_with_another_nonce_are_not_ours(udp):
    nonce = bytes(range(12))

    def answers(req: bytes) -> list[bytes]:
        head = struct.pack("!BBBBIII", 2, 0x81, 0, 0, 600, 5, 0) + b"\x00" * 8
        def body_of(n: bytes) -> bytes:
            return n + struct.pack("!B3xHH", 6, 7447, 7447) + pmp._v6("203.0.113.2")

        return [head + body_of(b"\xff" * 12), head + body_of(req[24:36])]

    udp(answers)
    got = pmp.pcp_map(HOST, HOST, "TCP", 7447, 7447, 600, nonce, soon())
    assert (got.external_ip, got.external_port, got.lifetime) == ("203.0.113.2", 7447, 600)


def test_pcp_result_codes_are_refusals_in_words(udp):
    def answers(req: bytes) -> list[bytes]:
        return [struct.pack("!BBBBIII", 2, 0x81, 0, 8, 0, 5, 0) + b"\x00" * 8 + req[24:36]
                + struct.pack("!B3xHH", 6, 7447, 0) + b"\x00" * 16]

    udp(answers)
    with pytest.raises(Refused) as exc:
        pmp.pcp_map(HOST, HOST, "TCP", 7447, 7447, 600, bytes(12), soon())
    assert exc.value.code == 8 and exc.value.name == "NO_RESOURCES"


# --------------------------------------------------------------------------- safety and words
def modem(external_ip: str | None = "203.0.113.2") -> Modem:
    return Modem("10.10.10.254", "10.10.10.1", ["upnp"], external_ip=external_ip)


@pytest.mark.parametrize("client,port,lease,match", [
    ("10.10.10.3", 7447, 3600, "another machine"),
    ("10.10.10.1", 80, 3600, "below 1024"),
    ("10.10.10.1", 22, 3600, "below 1024"),
    ("10.10.10.1", 7447, 0, "never for ever"),
    ("10.10.10.1", 7447, 10 ** 9, "never for ever"),
])
def test_the_guard_refuses_before_anything_is_sent(client, port, lease, match):
    with pytest.raises(ValueError, match=match):
        modem()._guard(client, port, lease)


@pytest.mark.parametrize("port,lease,match", [(1023, 3600, "below 1024"),
                                              (7447, 0, "never for ever")])
def test_add_applies_the_guard_with_no_modem_to_ask(port, lease, match):
    with pytest.raises(ValueError, match=match):    # the modem object points nowhere real
        modem().add("TCP", port, lease, "x", soon())


@pytest.mark.parametrize("ip,kind", [("", "none"), ("0.0.0.0", "none"), ("100.64.0.2", "shared"),
                                     ("192.168.0.2", "private"), ("10.1.2.3", "private"),
                                     ("203.0.113.2", "public"), (None, "unknown")])
def test_wan_kinds(ip, kind):
    assert wan_kind(ip) == kind


@pytest.mark.parametrize("protocol,code", [("upnp", 501), ("natpmp", 3), ("pcp", 8)])
@pytest.mark.parametrize("ip", ["", "100.64.0.2", "192.168.1.2"])
def test_a_refusal_with_no_public_address_is_carrier_grade_nat_in_words(protocol, code, ip):
    kind, words = explain_refusal(modem(ip), Refused(protocol, code, "X", "y"),
                                  Wanted("TCP", 7447, 3600, ""))
    assert kind == "cgnat" and words.startswith("carrier-grade NAT"), words
    assert f"error {code}" in words


def test_needs_follow_the_settings():
    from rosnet_tui.core.config.settings_model import RosSettings, Settings, ThisComponent

    ros1 = Settings(this=ThisComponent(name="turtlebot", role="master", local_ip="10.10.10.1"))
    n = needs(ros1)
    assert not n.forwards and "no protocol maps a range" in n.refusal and "DMZ" in n.refusal
    ros2 = Settings(this=ThisComponent(name="turtlebot", role="master"),
                    ros=RosSettings(version=2, zenoh_port=7447))
    got = needs(ros2)
    assert [(w.port, w.temporary) for w in got.forwards] == [(7447, False), (12345, True)]
    member = Settings(this=ThisComponent(name="sami", role="member"),
                      ros=RosSettings(master="turtlebot", version=2))
    assert needs(member).forwards == [] and "needs no forward" in needs(member).note


def test_journal_entries_without_forwards_are_written_as_before(tmp_path):
    e = uj.JournalEntry("000001", "now", "hosts", [])
    assert "mappings" not in e.to_json()
    m = {"kind": "port_mapping", "protocol": "TCP", "port": 7447, "state": "made"}
    e2 = uj.JournalEntry.from_json({**e.to_json(), "mappings": [m, "junk", 3]})
    assert e2.mappings == [m]
    assert uj.JournalEntry.from_json(e2.to_json()).mappings == [m]


# --------------------------------------------------------------------------- the commands
def _cli(tmp_path, settings, *args: str):
    import subprocess
    import sys
    from pathlib import Path

    from rosnet_tui.core.saved.settings import render_settings

    cfg = tmp_path / "config.toml"
    cfg.write_text(render_settings(settings))
    root = Path(__file__).resolve().parents[1]
    env = {"PATH": "/usr/bin:/bin", "PYTHONPATH": str(root), "HOME": str(tmp_path),
           "XDG_STATE_HOME": str(tmp_path / "state")}
    return subprocess.run([sys.executable, "-m", "rosnet_tui", "router", *args, "--config",
                           str(cfg)], capture_output=True, text=True, timeout=60, env=env)


def _master(version: int):
    from rosnet_tui.core.config.settings_model import RosSettings, Settings, ThisComponent

    return Settings(this=ThisComponent(name="turtlebot", role="master", local_ip="10.10.10.1",
                                       interface="lo"),
                    ros=RosSettings(master="turtlebot", version=version))


def test_router_map_refuses_ros1_in_words_without_asking_any_modem(tmp_path):
    p = _cli(tmp_path, _master(1), "map", "--yes")
    assert p.returncode == 1, p.stdout + p.stderr
    assert "nothing was asked of the modem" in p.stderr
    assert "no protocol maps a range" in p.stderr and "DMZ" in p.stderr


def test_router_map_on_a_ros2_member_has_nothing_to_do(tmp_path):
    from rosnet_tui.core.config.settings_model import Peer

    s = _master(2)
    s.this.name, s.this.role = "sami", "member"
    s.peers = [Peer(name="turtlebot", public_ip="203.0.113.2")]
    p = _cli(tmp_path, s, "map", "--yes")
    assert p.returncode == 0 and "Nothing to forward" in p.stdout, p.stdout + p.stderr


@pytest.mark.parametrize("args,match", [
    (["map", "--lease", "0"], "--lease must be between"),
    (["map", "--lease", "999999999"], "--lease must be between"),
    (["map", "--timeout", "0"], "--timeout must be between"),
    (["map", "--protocol", "ssh"], "invalid choice"),
    ([], "ACTION"),
])
def test_router_bad_usage_is_exit_2(tmp_path, args, match):
    p = _cli(tmp_path, _master(2), *args)
    assert p.returncode == 2, p.stdout + p.stderr
    assert match in p.stderr
    assert "Traceback" not in p.stderr


def test_pcp_to_a_natpmp_only_modem_ends_at_once(udp):
    udp(lambda req: [struct.pack("!BBHI", 0, 128 + req[1], 1, 7)])   # "unsupported version"
    t = time.monotonic()
    with pytest.raises(NoAnswer, match="NAT-PMP only"):
        pmp.pcp_map(HOST, HOST, "TCP", 7447, 7447, 600, bytes(12), soon(30))
    with pytest.raises(NoAnswer, match="NAT-PMP only"):
        pmp.pcp_announce(HOST, HOST, soon(30))
    assert time.monotonic() - t < 10      # at once: far from the 30 s deadlines
