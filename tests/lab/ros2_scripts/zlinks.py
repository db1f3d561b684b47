"""Wait (bounded) until the Zenoh router at ENDPOINT has sessions with at least N other routers,
then print them: ``ZLINKS {"router": zid, "routers": [zid, ...]}`` (what its admin space says).

    python zlinks.py tcp/127.0.0.1:7447 N TIMEOUT_S
"""

import json
import sys
import time

import zenoh

endpoint, want, timeout = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
deadline = time.monotonic() + timeout
cfg = zenoh.Config()
cfg.insert_json5("mode", '"client"')
cfg.insert_json5("connect/endpoints", json.dumps([endpoint]))
cfg.insert_json5("scouting/multicast/enabled", "false")
session = zenoh.open(cfg)
rzid = str(next(iter(session.info.routers_zid())))
routers: list[str] = []
while True:
    for reply in session.get(f"@/{rzid}/router", timeout=1.0):
        if reply.ok is not None:
            body = json.loads(reply.ok.payload.to_bytes())
            routers = sorted(str(x.get("peer")) for x in body.get("sessions") or []
                             if x.get("whatami") == "router")
    if len(routers) >= want or time.monotonic() > deadline:
        break
    time.sleep(0.05)
print("ZLINKS " + json.dumps({"router": rzid, "routers": routers}), flush=True)
session.close()
