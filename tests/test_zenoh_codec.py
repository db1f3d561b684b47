"""rmw_zenoh's wire format read back: every length check of the decoders refuses what is too
short, too long or inconsistent (a token with missing fields, an attachment of 32 or 34 bytes, a
CDR string whose length runs past its payload) instead of reading garbage (issue 36)."""

from __future__ import annotations

import struct

import pytest

from rosnet_tui.core.peer import zenohproto as z

NODE = "@ros2_lv/0/abc/7/7/NN/%/%/talker"
PUB = z.endpoint_token(0, "abc", "7", "8", "MP", "talker", "/chatter")


def test_a_node_token_has_exactly_nine_fields():
    assert z.parse_token(NODE)["name"] == "talker"
    assert z.parse_token(NODE + "/extra") is None
    assert z.parse_token(NODE.rsplit("/", 1)[0]) is None          # eight fields


@pytest.mark.parametrize("i", range(9))
def test_an_empty_field_among_the_first_nine_is_not_a_token(i):
    parts = NODE.split("/")
    parts[i] = ""
    assert z.parse_token("/".join(parts)) is None


def test_an_endpoint_token_needs_its_topic_type_hash_and_qos():
    parts = PUB.split("/")
    assert len(parts) == 13 and z.parse_token(PUB)["qos"] == z.DEFAULT_QOS
    assert z.parse_token("/".join(parts[:12])) is None           # no QoS
    assert z.parse_token("/".join(parts[:9])) is None            # an endpoint with no topic
    tok = z.parse_token(PUB + "/more")                           # QoS holding a "/"
    assert tok is not None and tok["qos"] == z.DEFAULT_QOS + "/more"
    assert z.parse_token(PUB.replace("/MP/", "/XX/")) is None     # unknown kind
    assert z.parse_token(PUB.replace("@ros2_lv", "@ros2_lx")) is None
    for kind in ("MS", "SS", "SC"):
        assert z.parse_token(PUB.replace("/MP/", f"/{kind}/"))["kind"] == kind


def test_a_cdr_string_is_read_within_its_payload_only():
    p = z.encode_string("hi")
    assert z.decode_string(p) == "hi"
    assert z.decode_string(p + b"junk") == "hi"                  # padding after it: ignored
    assert z.decode_string(p[:-1]) is None                        # length runs past the end
    assert z.decode_string(p[:7]) is None                         # no room for the length
    assert z.decode_string(b"\x00\x01\x00\x00") is None
    assert z.decode_string(b"\x00\x00" + p[2:]) is None           # big-endian header: not ours
    assert z.decode_string(b"\x01\x01" + p[2:]) is None
    empty = b"\x00\x01\x00\x00" + struct.pack("<I", 0)
    assert z.decode_string(empty) is None                         # no room for the NUL
    assert z.decode_string(b"\x00\x01\x00\x00" + struct.pack("<I", 1) + b"\0") == ""
    assert z.decode_string(z.encode_string("héllo")) == "héllo"


def test_an_attachment_has_exactly_33_bytes_and_a_gid_of_16():
    gid = bytes(range(16))
    att = z.encode_attachment(-5, 2**40, gid)
    assert z.decode_attachment(att) == (-5, 2**40, gid)
    assert z.decode_attachment(att[:32]) is None
    assert z.decode_attachment(att + b"\0") is None
    assert z.decode_attachment(None) is None
    assert z.decode_attachment(att[:16] + b"\x0f" + att[17:]) is None
    for bad in (gid[:15], gid + b"\0"):
        with pytest.raises(ValueError, match="16 bytes"):
            z.encode_attachment(1, 1, bad)
    assert len(z.make_gid("x")) == 16 and z.make_gid("x") != z.make_gid("y")


def test_every_field_of_a_token_is_read_from_its_own_place():
    node = z.node_token(3, "zid1", "n7", "talker", "/robot1", "/enc")
    assert z.parse_token(node) == {"domain": "3", "zid": "zid1", "nid": "n7", "id": "n7",
                                   "kind": "NN", "enclave": "/enc", "namespace": "/robot1",
                                   "name": "talker"}
    ep = z.endpoint_token(4, "zid2", "n8", "e9", "MS", "listener", "/chatter",
                          namespace="/ns", enclave="/e", qos="q1")
    assert z.parse_token(ep) == {"domain": "4", "zid": "zid2", "nid": "n8", "id": "e9",
                                 "kind": "MS", "enclave": "/e", "namespace": "/ns",
                                 "name": "listener", "topic": "/chatter",
                                 "type": "std_msgs/msg/String", "hash": z.STRING_HASH,
                                 "qos": "q1"}
    with pytest.raises(ValueError, match="unknown endpoint kind 'XX'"):
        z.endpoint_token(0, "a", "1", "2", "XX", "n", "/t")


@pytest.mark.parametrize(("wire", "ros"), [
    ("pkg::dds_::msg::dds_::T_", "pkg/dds_/msg/T"),     # the last dds_ part is the DDS one
    ("x::dds_::T_", "x/T"),                              # a two-letter name loses its "_"
    ("x::dds_::_", "x/_"),                               # a lone "_" is the name itself
])
def test_the_dds_suffix_is_taken_from_the_last_part_only(wire, ros):
    assert z.ros_type(wire) == ros


def test_bytes_that_are_not_utf_8_are_replaced_not_raised():
    bad = b"\x00\x01\x00\x00" + struct.pack("<I", 3) + b"a\xff\x00"
    assert z.decode_string(bad) == "a\ufffd"


def test_a_report_line_holds_an_object_or_counts_as_none():
    assert z.parse_report(f"x\n{z.REPORT_MARK}{{\"ok\": true}}\n") == {"ok": True}
    assert z.parse_report(f"{z.REPORT_MARK}[1, 2]\n") is None
    assert z.parse_report(f"{z.REPORT_MARK}{{\"a\": 1}}\n{z.REPORT_MARK}{{\"a\": 2}}") == {"a": 2}
    assert z.parse_report(f"{z.REPORT_MARK}{{bad\n") is None
    assert z.parse_report("") is None
