"""Step 4: the rules that read ros2.link (ROS 2) and ros.link (ROS 1), the link to each peer
measured (round trip, throughput each way, the largest message delivered whole) and weighed
against what ``[[link.topic]]`` says the robot must carry. One rule per cause for both ROS
versions; what to do differs (Zenoh's settings under ROS 2, TCPROS's path under ROS 1).

"Small messages pass, large ones are dropped" is a cause of its own: every path check passes, yet
a camera or a point cloud never shows across the link.
"""

from __future__ import annotations

from rosnet_tui.core.advisor.engine import Hit, rule
from rosnet_tui.core.advisor.evidence import Evidence
from rosnet_tui.core.words import kb, mbit

WAYS = (("out", "up", "from {me} to {peer}"), ("in", "down", "from {peer} to {me}"))


def _cid(ev: Evidence) -> str:
    """The link check of the settings' ROS version."""
    return "ros2.link" if ev.s.ros2 else "ros.link"


def _peers(ev: Evidence) -> dict:
    if ev.s.ros2:
        return ev.data("ros2.link").get("peers") or {}
    return ev.data("ros.link").get("peers") or {}


def _dropped(ev: Evidence) -> list[tuple[str, str, str, int, int]]:
    """(peer, 'up'|'down', direction in words, size tried, largest whole) where a large message
    tried was lost while small ones came back."""
    out = []
    for name, d in _peers(ev).items():
        if d.get("rtt_ms") is None:
            continue
        for way, word, where in WAYS:
            tried, got = d.get(f"tried_{way}") or 0, d.get(f"largest_{way}") or 0
            if tried and got < tried:
                out.append((name, word, where.format(me=ev.me, peer=name), tried, got))
    return out


@rule("ros2.link.large_dropped", "ros", ("ros2.link", "ros.link"),
      "small messages pass the link, large ones are dropped",
      "Pings and small messages cross the link both ways, but a message of 64 kB or 1 MB "
      "does not arrive whole. ROS 2: Zenoh's congestion control drops a large message's fragments when "
      "the link's queue is full (rmw_zenoh's default QoS), shared memory on the publisher's "
      "host keeps large payloads off the wire, a size filter drops them, or the link is too "
      "thin for them. ROS 1 (TCP): full-size packets lost on the path (an MTU black hole on a "
      "mobile, PPPoE or VPN link) or a link too thin for them. Topics such as images and point clouds are then listed but "
      "never arrive.",
      "Publish the large topics RELIABLE with KEEP_ALL history, or let the sending router wait "
      "longer before dropping fragments; turn shared memory off for nodes whose topics cross the "
      "internet; remove a low_pass_filter (ROS 2). Lower the MTU on a path that loses "
      "full-size packets (ROS 1). Make the messages smaller.",
      "ros", "warn")
def _large(ev: Evidence) -> list[Hit]:
    lost = _dropped(ev)
    if not lost:
        return []
    peer, word, where, tried, got = lost[0]
    d = _peers(ev)[peer]
    rate = d.get(f"{'out' if word == 'up' else 'in'}_bps")
    big = [t for t in ev.s.link.topics if t.bytes > min(x[4] for x in lost)]
    facts = [f"{_cid(ev)}: {p}: {w}, {kb(t)} tried, largest whole {kb(g) if g else 'none'}"
             f" (round trip {_peers(ev)[p].get('rtt_ms')} ms)" for p, w, _x, t, g in lost]
    time_words = (f" At the {mbit(rate)} measured, {kb(tried)} takes "
                  f"{tried * 8 / rate:.1f} s on the wire." if rate else "")
    needs = (f" {', '.join(t.name for t in big)} ({', '.join(kb(t.bytes) for t in big)} a "
             "message) will not arrive." if big else "")
    what = (f"Small messages cross the link {where} (the round trip is {d.get('rtt_ms')} ms), "
            f"but a {kb(tried)} message sent that way never arrived whole (the largest that did: "
            f"{kb(got) if got else 'none of the large ones'}).{time_words}{needs} This is not "
            "the path: it is what happens to large messages on it.")
    if not ev.s.ros2:
        return [Hit(what, _ROS1_LARGE, severity="fail" if big else None, evidence=facts)]
    return [Hit(what,
                ["Congestion control: rmw_zenoh drops a message whose fragments find the link's "
                 "queue full, unless the publisher's QoS is RELIABLE with KEEP_ALL history. Give "
                 "the large topics that QoS, or give the sending side's router more time before "
                 "it drops fragments, in its config (ZENOH_ROUTER_CONFIG_URI): `transport: { "
                 "link: { tx: { queue: { congestion_control: { drop: { "
                 "max_wait_before_drop_fragments: 500000 } } } } } }` (microseconds; the "
                 "default is 50000), then restart that router.",
                 "Shared memory: on the publisher's host, start the nodes with "
                 "`export ZENOH_CONFIG_OVERRIDE='transport/shared_memory/enabled=false'` (or "
                 "that key in the ZENOH_SESSION_CONFIG_URI file) when their topics must cross "
                 "the internet.",
                 "A size filter: look for `low_pass_filter` in both routers' configs; a "
                 "`size_limit` below the message size drops it. Raise it or remove it.",
                 "Or make the messages smaller: compressed images (image_transport's "
                 "`compressed` topics), a lower resolution, a voxel-filtered cloud. Then re-run "
                 "the ROS step."],
                severity="fail" if big else None, evidence=facts)]


_ROS1_LARGE = [
    "A path that loses full-size packets (an MTU black hole: PPPoE, a mobile carrier, a VPN): "
    "from each side, `ping -M do -s 1472 <the other's name>` must answer; if only smaller "
    "sizes do, lower this component's MTU to what passes plus 28 (`sudo ip link set dev <its "
    "interface> mtu 1400`, then in its network settings to keep it), or turn on MSS clamping "
    "in the modem.",
    "A link too thin for them in time: see the throughput measured each way; send less.",
    "Or make the messages smaller: compressed images (image_transport's `compressed` topics), "
    "a lower resolution, a voxel-filtered cloud. Then re-run the ROS step."]


def _key_expr(ev: Evidence, topic: str) -> str:
    return f"{ev.s.ros.domain_id}/{topic.strip('/')}/**"


@rule("ros2.link.too_thin", "ros", ("ros2.link", "ros.link"),
      "the topics in [[link.topic]] need more than the link carries",
      "The sum of what the robot must carry (bytes x hz of every [[link.topic]]) is above the "
      "throughput measured: queues fill, messages are dropped or arrive "
      "late, and a teleoperation topic waits behind the images.",
      "Send less: compressed images (image_transport), a lower rate at the source, or (ROS 2) "
      "Zenoh's downsampling of the named topics on the sending router's WAN link (max_hz), or "
      "(ROS 1) topic_tools throttle on the sending side.",
      "ros", "warn")
def _thin(ev: Evidence) -> list[Hit]:
    need = ev.s.link.need_bps(downsampled=ev.s.ros2)
    if not need:
        return []
    short = [(name, word, where.format(me=ev.me, peer=name), d[f"{way}_bps"])
             for name, d in _peers(ev).items() for way, word, where in WAYS
             if d.get(f"{way}_bps") is not None and d[f"{way}_bps"] < need]
    if not short:
        return []
    name, word, where, got = short[0]
    rate = (lambda tp: tp.bps) if ev.s.ros2 else (lambda tp: tp.full_bps)
    top = max(ev.s.link.topics, key=rate)
    top_bps = rate(top)
    freq = max(0.5, round(top.hz * max(0.1, (got * 0.8 - (need - top_bps)) / top_bps), 1)) \
        if top_bps else 1.0
    if ev.s.ros2:
        proto = '"tls"' if ev.s.ros.security == "mtls" else '"tcp"'
        cut = (f"Or let the sending side's router cut it down on the WAN link only: in its "
               f"config (ZENOH_ROUTER_CONFIG_URI) `downsampling: [{{ id: \"wan\", "
               f"link_protocols: [{proto}], flows: [\"egress\"], messages: [\"put\"], rules: "
               f"[{{ key_expr: \"{_key_expr(ev, top.name)}\", freq: {freq:g} }}] }}]`, and "
               f"write `max_hz = {freq:g}` under its [[link.topic]] so the check counts it "
               "at that rate; restart the router, then re-run the ROS step.")
    else:
        cut = (f"Or throttle it on the sending side only for the link: `rosrun topic_tools "
               f"throttle messages {top.name} {freq:g} {top.name}_wan` there, and subscribe to "
               f"{top.name}_wan across the link; write hz = {freq:g} under its [[link.topic]] "
               "(max_hz is ROS 2's: under ROS 1 the check counts hz), then re-run the ROS step.")
    return [Hit(f"The topics in [[link.topic]] need {mbit(need)}; the link {where} carried "
                f"{mbit(got)} (short by {mbit(need - got)}). "
                f"The largest need is {top.name}: {top.bytes} bytes x {top.hz:g} Hz = "
                f"{mbit(top_bps)}.",
                [f"Compress: publish {top.name} through image_transport's `compressed` "
                 "transport (or a compressed point cloud) and subscribe to that across the "
                 "link; set bytes under its [[link.topic]] to the new size.",
                 f"Or lower the rate at the source (the driver's frame rate), below about "
                 f"{freq:g} Hz for {top.name}.",
                 cut],
                evidence=[f"{_cid(ev)}: {n}: {w} {mbit(g)}" for n, w, _x, g in short]
                + [f"settings: [[link.topic]] need {mbit(need)}"])]
