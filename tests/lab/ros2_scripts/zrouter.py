"""A Zenoh router for the lab: what ``rmw_zenohd`` is (a router-mode Zenoh session), started with
the JSON5 config file ZENOH_ROUTER_CONFIG_URI would name. Lives until killed or *lifetime* s.

    python zrouter.py CONFIG.json5 [LIFETIME_S]
"""

import signal
import sys
import threading

import zenoh

path = sys.argv[1]
lifetime = float(sys.argv[2]) if len(sys.argv) > 2 else 900.0
stop = threading.Event()
signal.signal(signal.SIGTERM, lambda *_: stop.set())
signal.signal(signal.SIGINT, lambda *_: stop.set())
config = zenoh.Config.from_file(path)
# The lab's computers are namespaces of one machine and share /dev/shm: left on, two routers
# would pass large payloads through shared memory, which no two real computers can (issue 31:
# the link measured saw 70 Mbit/s across a modem shaped to 2).
config.insert_json5("transport/shared_memory/enabled", "false")
session = zenoh.open(config)
print(f"ZROUTER {session.zid()}", flush=True)
stop.wait(lifetime)
session.close()
