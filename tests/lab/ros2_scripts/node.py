"""A stand-in for a ROS 2 node on rmw_zenoh (no ROS 2 distribution installs here).

It behaves on the wire as an rmw_zenoh node does, written here from rmw_zenoh's documented
format and independently of rosnet-tui's own code (so a mistake there is not copied here):
liveliness tokens ``@ros2_lv/<domain>/<zid>/<nid>/<id>/<NN|MP|MS>/...``, the data key
``<domain>/<topic>/<type>/<hash>``, a CDR std_msgs/String payload and the 33-byte attachment.
Sessions are configured as rmw_zenoh's default session config does (peer, listening on
loopback, multicast off, gossip to the router), or in client mode.

    python node.py talker|listener --connect tcp/127.0.0.1:7447 [--mode peer|client]
        [--domain 0] [--topic /chatter] [--name talker] [--distro jazzy|humble] [--lifetime S]
"""

import argparse
import json
import os
import struct
import sys
import threading
import time

import zenoh

HASHES = {"jazzy": "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18",
          "humble": "TypeHashNotSupported"}
TYPE = "std_msgs::msg::dds_::String_"

ap = argparse.ArgumentParser()
ap.add_argument("role", choices=("talker", "listener"))
ap.add_argument("--connect", required=True)
ap.add_argument("--mode", default="peer", choices=("peer", "client"))
ap.add_argument("--domain", type=int, default=0)
ap.add_argument("--topic", default="/chatter")
ap.add_argument("--name", default=None)
ap.add_argument("--distro", default="jazzy", choices=tuple(HASHES))
ap.add_argument("--lifetime", type=float, default=600.0)
a = ap.parse_args()
name = a.name or a.role

cfg = zenoh.Config()
cfg.insert_json5("mode", json.dumps(a.mode))
cfg.insert_json5("connect/endpoints", json.dumps([a.connect]))
cfg.insert_json5("scouting/multicast/enabled", "false")
if a.mode == "peer":
    cfg.insert_json5("listen/endpoints", '["tcp/localhost:0"]')
    cfg.insert_json5("scouting/gossip/target", '{"router": ["router", "peer"], "peer": ["router"]}')
session = zenoh.open(cfg)
zid = str(session.zid())
dom, thash = a.domain, HASHES[a.distro]
chunk = lambda s: s.replace("/", "%") or "%"  # noqa: E731
node_key = f"@ros2_lv/{dom}/{zid}/0/0/NN/%/%/{name}"
kind = "MP" if a.role == "talker" else "MS"
ep_key = (f"@ros2_lv/{dom}/{zid}/0/10/{kind}/%/%/{name}/{chunk(a.topic)}/{TYPE}/{thash}/"
          "::,:,:,:,,")
tokens = [session.liveliness().declare_token(node_key), session.liveliness().declare_token(ep_key)]
data_key = f"{dom}/{a.topic.strip('/')}/{TYPE}/{thash}"
gid = os.urandom(16)
print(f"NODE {name} {zid} {a.mode} {data_key}", flush=True)
end = time.monotonic() + a.lifetime

if a.role == "talker":
    n = 0
    while time.monotonic() < end:
        n += 1
        text = f"hello from {os.uname().nodename} {n}".encode() + b"\0"
        payload = b"\x00\x01\x00\x00" + struct.pack("<I", len(text)) + text
        session.put(data_key, payload,
                    attachment=struct.pack("<qqB", n, time.time_ns(), 16) + gid)
        time.sleep(0.2)
else:
    done = threading.Event()

    def heard(sample):
        raw = bytes(sample.payload.to_bytes())
        att = sample.attachment
        ok = att is not None and len(bytes(att.to_bytes())) == 33
        size = struct.unpack_from("<I", raw, 4)[0]
        print(f"heard: {raw[8:8 + size - 1].decode()} (attachment {'ok' if ok else 'missing'})",
              flush=True)

    sub = session.declare_subscriber(data_key, heard)
    done.wait(a.lifetime)
for t in tokens:
    t.undeclare()
session.close()
sys.exit(0)
