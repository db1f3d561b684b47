"""Issue 34, rows 1-9: a modem that answers badly, played by small servers of the tests' own on
loopback (real sockets). Nothing hangs, nothing raises anything but a ModemError, no control
character reaches a person, notes stay few, and a forward is said gone only when the modem said
so. (tests/test_upnp_lab.py plays the same modem at a lab host's gateway, through the commands.)"""

from __future__ import annotations

import socket
import struct
import threading
import time
from collections.abc import Callable

import pytest

from rosnet_tui.core import addresses
from rosnet_tui.core.checks import isp
from rosnet_tui.core.results import Status
from rosnet_tui.core.upnp import forwards as fw
from rosnet_tui.core.upnp import igd, journal, pmp, wire
from rosnet_tui.core.upnp.modem import Modem, find_modem
from rosnet_tui.core.upnp.wire import HostileAnswer, ModemError, NoAnswer
from tests.test_upnp_client import (
    HOST,
    FakeHttp,
    FakeUdp,
    description,
    http,
    igd_at,
    soap_error,
    soap_ok,
    soon,
)


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


def ends(fn: Callable[[], object], limit: float = 5.0) -> dict:
    """Run *fn* on a thread: {"ok": value} or {"err": exception}; the test fails when it has not
    ended within *limit* seconds (a loop without end spins on, in a daemon thread)."""
    box: dict = {}

    def run() -> None:
        try:
            box["ok"] = fn()
        except BaseException as exc:  # noqa: BLE001 - the test looks at what it was
            box["err"] = exc

    th = threading.Thread(target=run, daemon=True)
    th.start()
    th.join(limit)
    assert not th.is_alive(), f"still running after {limit} s: a loop with no end"
    return box


def chunked(*chunks: bytes, status: str = "200 OK") -> bytes:
    return (f"HTTP/1.1 {status}\r\nContent-Type: text/xml\r\nTransfer-Encoding: chunked\r\n\r\n"
            .encode() + b"".join(chunks))


def good_igd(reply_soap: Callable[[bytes], bytes]) -> Callable[[bytes], bytes]:
    """A modem whose description is fine and whose SOAP answers are *reply_soap(request)*."""
    def reply(req: bytes) -> bytes:
        if req.startswith(b"GET"):
            return http(description())
        return reply_soap(req)
    return reply


# --------------------------------------------------------------------------- row 1
@pytest.mark.parametrize("where", ["description", "GetExternalIPAddress"])
def test_row1_a_negative_chunk_size_is_refused_and_nothing_spins(serve, where):
    bad = chunked(b"5\r\n<root\r\n", b"-6\r\nxxxxxx\r\n", b"0\r\n\r\n")
    s = serve(lambda req: bad if where == "description" or req.startswith(b"POST")
              else http(description()))

    def ask():
        g = igd.describe(s.url(), HOST, soon())
        return igd.external_ip(g, soon())

    got = ends(ask)
    assert isinstance(got.get("err"), HostileAnswer), got
    assert "chunk" in str(got["err"])


def test_row1_a_good_chunked_answer_ends_without_waiting_for_the_close(serve):
    body = soap_ok("GetExternalIPAddress", NewExternalIPAddress="203.0.113.2").encode()

    def keep_open(conn: socket.socket) -> None:
        conn.sendall(chunked(f"{len(body):x}\r\n".encode() + body + b"\r\n", b"0\r\n\r\n"))
        time.sleep(10)    # a modem that keeps the connection open after its last chunk

    s = serve(lambda req: http(description()) if req.startswith(b"GET") else keep_open)
    g = igd.describe(s.url(), HOST, soon())
    t = time.monotonic()
    assert igd.external_ip(g, soon(20)) == "203.0.113.2"
    assert time.monotonic() - t < 5       # at its last chunk, not the close 10 s later


# --------------------------------------------------------------------------- row 2
SUP1 = "\u00b9"   # superscript one: str.isdigit() says yes, int() says no


@pytest.mark.parametrize("raw", [
    f"HTTP/1.1 2{SUP1}0 OK\r\nContent-Length: 0\r\n\r\n".encode("latin-1"),
    f"HTTP/1.1 200 OK\r\nContent-Length: 1{SUP1}\r\n\r\nxx".encode("latin-1"),
])
def test_row2_non_ascii_digits_in_http_are_refused(serve, raw):
    s = serve(lambda req: raw)
    got = ends(lambda: igd.describe(s.url(), HOST, soon()))
    assert isinstance(got.get("err"), HostileAnswer), got


@pytest.mark.parametrize("field,value", [("NewExternalPort", f"744{SUP1}"),
                                         ("NewInternalPort", f"744{SUP1}"),
                                         ("NewLeaseDuration", f"36{SUP1}")])
def test_row2_non_ascii_digits_in_the_mapping_list_are_refused(serve, field, value):
    entry = {"NewProtocol": "TCP", "NewExternalPort": "7447", "NewInternalPort": "7447",
             "NewInternalClient": "10.10.10.1", "NewEnabled": "1",
             "NewPortMappingDescription": "x", "NewLeaseDuration": "3600", field: value}
    s = serve(good_igd(lambda req: http(soap_ok("GetGenericPortMappingEntry", **entry))))
    got = ends(lambda: igd.list_mappings(igd_at(s), soon()))
    assert isinstance(got.get("err"), HostileAnswer), got


def test_row2_a_non_ascii_upnp_error_code_is_refused(serve):
    s = serve(good_igd(lambda req: http(soap_error(f"7{SUP1}8"), "500 Internal Server Error")))
    got = ends(lambda: igd.add_mapping(igd_at(s), "TCP", 7447, HOST, 7447, "x", 3600, soon()))
    assert isinstance(got.get("err"), HostileAnswer), got
    assert "malformed UPnP error code" in str(got["err"])


# --------------------------------------------------------------------------- row 3
def test_row3_a_control_url_outside_ascii_is_refused(serve):
    s = serve(good_igd(lambda req: http(soap_ok("GetExternalIPAddress",
                                                NewExternalIPAddress="203.0.113.2"))))
    s.reply = lambda req: http(description("/ctl/\u2603")) if req.startswith(b"GET") else \
        http(soap_ok("GetExternalIPAddress", NewExternalIPAddress="203.0.113.2"))

    def ask():
        return igd.external_ip(igd.describe(s.url(), HOST, soon()), soon())

    got = ends(ask)
    assert isinstance(got.get("err"), HostileAnswer), got
    assert "outside printable ASCII" in str(got["err"])


# --------------------------------------------------------------------------- row 4
def test_row4_an_unconfirmed_roll_back_keeps_the_journal_entry_and_says_so(serve, tmp_path):
    """The modem forwards TCP 7447, refuses the test port, then refuses the roll-back's delete."""
    held: dict[int, bool] = {}

    def soap_reply(req: bytes) -> bytes:
        port = int(req.split(b"<NewExternalPort>")[1].split(b"<")[0]) \
            if b"<NewExternalPort>" in req else 0
        if b"#AddPortMapping" in req:
            if port == 7447:
                held[port] = True
                return http(soap_ok("AddPortMapping"))
            return http(soap_error("606", "ActionNotAuthorized"), "500 Internal Server Error")
        if b"#GetSpecificPortMappingEntry" in req:
            if not held.get(port):
                return http(soap_error("714", "NoSuchEntryInArray"), "500 Internal Server Error")
            return http(soap_ok("GetSpecificPortMappingEntry", NewInternalPort=str(port),
                                NewInternalClient=HOST, NewEnabled="1",
                                NewPortMappingDescription="rosnet-tui", NewLeaseDuration="86000"))
        if b"#DeletePortMapping" in req:
            return http(soap_error("501", "ActionFailed"), "500 Internal Server Error")
        return http(soap_error("401", "InvalidAction"), "500 Internal Server Error")

    s = serve(good_igd(soap_reply))
    m = Modem(HOST, HOST, ["upnp"], igd=igd_at(s), external_ip="203.0.113.2")
    from tests.test_upnp_client import _master

    wanted = [fw.Wanted("TCP", 7447, 86400, "the Zenoh router"),
              fw.Wanted("TCP", 23456, 900, "the test port", temporary=True)]
    with pytest.raises(fw.MapRefused) as exc:
        fw.map_forwards(_master(2), m, wanted, state_dir=tmp_path, timeout=3.0)
    assert exc.value.kind == "unconfirmed", exc.value.words
    words = exc.value.words
    assert "TCP 7447" in words and "may still forward" in words and "router unmap" in words
    assert "nothing was changed" not in exc.value.told()     # what the CLI and map screen say
    assert "nothing was changed" in fw.MapRefused("refused", "no").told()
    live = journal.live(tmp_path)
    assert [(r["protocol"], r["port"], r["state"]) for _e, r in live] == [("TCP", 7447, "made")]
    assert held[7447]


def test_row4_a_confirmed_roll_back_closes_the_entry(serve, tmp_path):
    held: dict[int, bool] = {}

    def soap_reply(req: bytes) -> bytes:
        port = int(req.split(b"<NewExternalPort>")[1].split(b"<")[0])
        if b"#AddPortMapping" in req:
            if port == 7447:
                held[port] = True
                return http(soap_ok("AddPortMapping"))
            return http(soap_error("606", "ActionNotAuthorized"), "500 Internal Server Error")
        if b"#GetSpecificPortMappingEntry" in req and held.get(port):
            return http(soap_ok("GetSpecificPortMappingEntry", NewInternalPort=str(port),
                                NewInternalClient=HOST, NewEnabled="1",
                                NewPortMappingDescription="rosnet-tui", NewLeaseDuration="86000"))
        if b"#DeletePortMapping" in req:
            held.pop(port, None)
            return http(soap_ok("DeletePortMapping"))
        return http(soap_error("714", "NoSuchEntryInArray"), "500 Internal Server Error")

    s = serve(good_igd(soap_reply))
    m = Modem(HOST, HOST, ["upnp"], igd=igd_at(s), external_ip="203.0.113.2")
    from tests.test_upnp_client import _master

    wanted = [fw.Wanted("TCP", 7447, 86400, "z"), fw.Wanted("TCP", 23456, 900, "t", True)]
    with pytest.raises(fw.MapRefused) as exc:
        fw.map_forwards(_master(2), m, wanted, state_dir=tmp_path, timeout=3.0)
    assert exc.value.kind == "not_allowed"
    assert journal.live(tmp_path) == [] and held == {}


# --------------------------------------------------------------------------- row 5
NOT_AN_INTERNET_ADDRESS = ["0.0.0.0", "127.0.0.1", "169.254.3.4", "224.0.0.9",
                           "255.255.255.255", "240.0.0.1"]


@pytest.mark.parametrize("ip", NOT_AN_INTERNET_ADDRESS)
def test_row5_isp_cgnat_never_passes_on_an_external_address_that_is_not_public(ip):
    status, summary, _data = isp.judge_wan(ip, None)
    assert status is not Status.PASS, summary
    assert fw.wan_kind(ip) == "none"
    assert not addresses.is_public_v4(ip)


@pytest.mark.parametrize("ip", ["127.0.0.1", "224.0.0.9", "255.255.255.255", "0.0.0.0"])
def test_row5_a_natpmp_external_address_that_is_not_one_is_read_as_none(udp, ip):
    udp(lambda req: [struct.pack("!BBHI", 0, 128, 0, 9) + socket.inet_aton(ip)])
    notes: list[str] = []
    m = find_modem(1.0, gateway=HOST, protocols=("natpmp",), notes=notes)
    assert m is not None and m.external_ip == "", (m, notes)
    if ip != "0.0.0.0":
        assert any(ip in n and "no public address" in n for n in notes), notes


# --------------------------------------------------------------------------- row 6
def test_row6_a_utf16_description_with_a_doctype_is_refused(serve):
    doc = ('<?xml version="1.0" encoding="UTF-16"?><!DOCTYPE root [<!ENTITY n "EVIL NAME">]>'
           + description().split("?>", 1)[1].replace("fake modem", "&n;"))
    s = serve(lambda req: http(doc.encode("utf-16")))
    got = ends(lambda: igd.describe(s.url(), HOST, soon()))
    assert isinstance(got.get("err"), HostileAnswer), got
    assert "DOCTYPE" in str(got["err"])


# --------------------------------------------------------------------------- row 7
C1 = "\u009b31m\u009d0;x\u009c"


def test_row7_c1_controls_in_the_modems_name_and_a_forwards_description_are_not_shown(serve):
    entry = {"NewProtocol": "TCP", "NewExternalPort": "7447", "NewInternalPort": "7447",
             "NewInternalClient": "10.10.10.1", "NewEnabled": "1",
             "NewPortMappingDescription": f"x{C1}y", "NewLeaseDuration": "3600"}

    def reply(req: bytes) -> bytes:
        if req.startswith(b"GET"):
            return http(description().replace("fake modem", f"fake{C1}modem"))
        if b"<NewPortMappingIndex>0<" in req:
            return http(soap_ok("GetGenericPortMappingEntry", **entry))
        return http(soap_error("713", "SpecifiedArrayIndexInvalid"), "500 Internal Server Error")

    s = serve(reply)
    g = igd.describe(s.url(), HOST, soon())
    assert g.friendly_name.isprintable() and g.friendly_name.startswith("fake")
    listed = igd.list_mappings(g, soon())
    assert len(listed) == 1 and listed[0].description.isprintable(), listed
    assert listed[0].description.startswith("x") and listed[0].description.endswith("y")


def test_row7_shown_text_keeps_no_c0_or_c1_controls():
    for c in [*map(chr, range(32)), "\x7f", *map(chr, range(0x80, 0xa0))]:
        assert wire.shown(f"a{c}b") == "a?b"
    assert wire.shown("caf\u00e9 \u2603") == "caf\u00e9 \u2603"


# --------------------------------------------------------------------------- row 8
def test_row8_a_flood_of_junk_natpmp_answers_leaves_a_few_notes(udp):
    udp(lambda req: [b"\x00\x80\x00\x00" + b"x" * 40] * 300)
    notes: list[str] = []
    got = ends(lambda: pmp.natpmp_external(HOST, soon(0.6), notes=notes))
    assert isinstance(got.get("err"), NoAnswer), got
    assert "12 expected" in str(got["err"])              # the last refusal, said at the end
    assert len(notes) <= wire.MAX_NOTES + 1, len(notes)
    assert "more unusable answers ignored" in notes[-1]
    assert sum(len(n) for n in notes) < 2000


def test_row8_a_flood_of_junk_ssdp_answers_leaves_a_few_notes(monkeypatch):
    junk = FakeUdp(lambda req: [b"HTTP/1.1 200 OK\r\nST: x\r\n\r\n"] * 300)
    try:
        monkeypatch.setattr(wire, "SSDP_ADDR", (HOST, junk.port))
        notes: list[str] = []
        got = ends(lambda: wire.ssdp_search(0.5, gateway=HOST, notes=notes))
        assert got.get("ok") is None and "err" not in got, got
        assert len(notes) <= wire.MAX_NOTES + 1, notes[:8]
        assert "more unusable answers ignored" in notes[-1]
    finally:
        junk.close()


# --------------------------------------------------------------------------- row 9
def _natpmp_answer(op: int, life: int) -> bytes:
    return struct.pack("!BBHIHHI", 0, 128 + op, 0, 5, 7447, 7447, life)


def test_row9_a_natpmp_delete_answered_by_a_late_copy_of_the_forward_is_not_a_removal(udp):
    udp(lambda req: [_natpmp_answer(2, 86400)])
    m = Modem(HOST, HOST, ["natpmp"])
    got = ends(lambda: m.remove({"protocol": "TCP", "port": 7447, "via": "natpmp"}, soon(0.8)))
    assert isinstance(got.get("err"), ModemError), got
    assert "late answer" in str(got["err"])


def test_row9_a_natpmp_success_with_lifetime_0_is_not_a_forward(udp):
    udp(lambda req: [_natpmp_answer(2, 0)])
    m = Modem(HOST, HOST, ["natpmp"])
    got = ends(lambda: m.add("TCP", 7447, 3600, "x", soon(0.8), via="natpmp"))
    assert isinstance(got.get("err"), ModemError), got
    assert "lifetime of 0 s" in str(got["err"])


def test_row9_a_pcp_delete_answered_by_a_late_copy_with_the_same_nonce_is_not_a_removal(udp):
    def answers(req: bytes) -> list[bytes]:
        head = struct.pack("!BBBBIII", 2, 0x81, 0, 0, 86400, 5, 0) + b"\x00" * 8
        return [head + req[24:36] + struct.pack("!B3xHH", 6, 7447, 7447)
                + pmp._v6("203.0.113.2")]

    udp(answers)
    m = Modem(HOST, HOST, ["pcp"])
    rec = {"protocol": "TCP", "port": 7447, "via": "pcp", "nonce": bytes(range(12)).hex()}
    got = ends(lambda: m.remove(rec, soon(0.8)))
    assert isinstance(got.get("err"), ModemError), got


def test_row9_a_confirmed_natpmp_delete_is_a_removal(udp):
    udp(lambda req: [struct.pack("!BBHIHHI", 0, 130, 0, 5, 7447, 0, 0)])
    m = Modem(HOST, HOST, ["natpmp"])
    assert "removed" in m.remove({"protocol": "TCP", "port": 7447, "via": "natpmp"}, soon())


# --------------------------------------------------------------------------- issue 32: the pace
def test_with_no_modem_discovery_ends_when_the_gateway_says_closed(monkeypatch):
    """A gateway that speaks none of the three answers "port unreachable" to each: the search
    ends then (and a short last look), not at the end of the SSDP window."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind((HOST, 0))
    closed = s.getsockname()[1]
    s.close()
    monkeypatch.setattr(pmp, "PORT", closed)
    monkeypatch.setattr(wire, "SSDP_ADDR", ("239.255.255.250", closed))
    notes: list[str] = []
    got = ends(lambda: find_modem(4.0, gateway=HOST, notes=notes))
    assert got == {"ok": None}, got
    assert any("does not listen for UPnP searches" in n for n in notes), notes
    # The search itself ends on the gateway's "closed", not at its window's end: given a window
    # of 60 s, it must end within ends()' 20 s (it takes SSDP_CLOSED_GRACE_S, 0.15 s; waiting
    # the window out is 60 s: a bound far from both, where `took < 0.8` against find_modem's
    # 0.8 s window was not).
    notes = []
    got = ends(lambda: wire.ssdp_search(60.0, gateway=HOST, notes=notes), limit=20.0)
    assert got == {"ok": None}, got
    assert any("does not listen for UPnP searches" in n for n in notes), notes


# --------------------------------------------------------------------------- the siblings
def test_a_peers_http_with_non_ascii_digits_is_refused_in_words():
    """The ROS XML-RPC reader (what a peer's master or node sends) holds to the same rule."""
    import io

    from rosnet_tui.core.net.probe_server import parse_listen
    from rosnet_tui.core.peer.rosproto import XmlRpcError, read_http

    with pytest.raises(XmlRpcError, match="bad Content-Length"):
        read_http(io.BytesIO(b"HTTP/1.0 200 OK\r\nContent-Length: 1\xb9\r\n\r\nxx"), True)
    with pytest.raises(ValueError, match="not ADDR:PORT"):
        parse_listen("80\u00b9")


def test_row1_the_renewal_with_a_hostile_modem_ends_and_the_next_round_is_planned(serve, tmp_path):
    """The sync service's renewal of a forward made two days ago, on a modem whose answer to
    AddPortMapping has a negative chunk size: it ends, says why, and names the next look."""
    def reply(req: bytes) -> bytes:
        if req.startswith(b"GET"):
            return http(description())
        return chunked(b"5\r\n<root\r\n", b"-6\r\nxxxxxx\r\n", b"0\r\n\r\n")

    s = serve(reply)
    m = Modem(HOST, HOST, ["upnp"], igd=igd_at(s), external_ip="203.0.113.2")
    two_days_ago = time.time() - 2 * 86400
    journal.new_entry("forward TCP 7447", [{
        "protocol": "TCP", "port": 7447, "internal_client": HOST, "via": "upnp",
        "lease_s": 86400, "temporary": False, "description": "rosnet-tui turtlebot Zenoh router",
        "modem": m.identity("upnp"), "state": "made", "made_at": two_days_ago,
        "renewed_at": two_days_ago}], tmp_path)
    from tests.test_upnp_client import _master

    got = ends(lambda: fw.renew_due(_master(2), state_dir=tmp_path, timeout=2.0, modem=m))
    said, next_in = got["ok"]
    assert any("could not renew TCP 7447" in line and "chunk" in line for line in said), said
    assert next_in is not None and next_in > 0
    assert [r["state"] for _e, r in journal.live(tmp_path)] == ["made"]


def test_an_offer_of_another_port_not_given_back_is_said(udp):
    """NAT-PMP maps another external port; giving it back is answered by a late copy: the
    refusal says that port may still be forwarded here, instead of "given back"."""
    udp(lambda req: [struct.pack("!BBHIHHI", 0, 130, 0, 5, 7447, 40000, 3600)])
    m = Modem(HOST, HOST, ["natpmp"])
    got = ends(lambda: m.add("TCP", 7447, 3600, "x", soon(1.0), via="natpmp"))
    err = got.get("err")
    assert isinstance(err, wire.Refused) and err.name == "PortTaken", got
    assert "not confirmed" in err.words and "40000" in err.words and "given back" not in \
        err.words.replace("giving the offer back", "")
