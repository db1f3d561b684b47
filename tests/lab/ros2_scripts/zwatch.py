"""Watch a Zenoh router from its own machine, with timestamps (time.monotonic(), which every
network namespace shares): the routers it has sessions with, and a topic's data arriving.

    python zwatch.py tcp/127.0.0.1:7447 KEY_EXPR [LIFETIME_S]

Prints ``ROUTERS <t> <zid,zid,...>`` at start and whenever that set changes (its admin space read
every 0.1 s), and ``DATA <t> <n>`` for a sample that comes after 0.5 s or more without one (the
first sample, and the first after a gap), n counting every sample so far.
"""

import json
import sys
import threading
import time

import zenoh

endpoint, key = sys.argv[1], sys.argv[2]
lifetime = float(sys.argv[3]) if len(sys.argv) > 3 else 600.0
cfg = zenoh.Config()
cfg.insert_json5("mode", '"client"')
cfg.insert_json5("connect/endpoints", json.dumps([endpoint]))
cfg.insert_json5("scouting/multicast/enabled", "false")
session = zenoh.open(cfg)
rzid = str(next(iter(session.info.routers_zid())))
lock = threading.Lock()
state = {"last": 0.0, "n": 0}


def heard(_sample) -> None:
    now = time.monotonic()
    with lock:
        state["n"] += 1
        if now - state["last"] >= 0.5:
            print(f"DATA {now:.3f} {state['n']}", flush=True)
        state["last"] = now


sub = session.declare_subscriber(key, heard)
print(f"ZWATCH {rzid}", flush=True)
seen = None
end = time.monotonic() + lifetime
while time.monotonic() < end:
    routers = None
    for reply in session.get(f"@/{rzid}/router", timeout=1.0):
        if reply.ok is not None:
            body = json.loads(reply.ok.payload.to_bytes())
            routers = sorted(str(x.get("peer")) for x in body.get("sessions") or []
                             if x.get("whatami") == "router")
    if routers is not None and routers != seen:
        seen = routers
        print(f"ROUTERS {time.monotonic():.3f} {','.join(routers)}", flush=True)
    time.sleep(0.1)
sub.undeclare()
session.close()
