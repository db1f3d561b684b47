"""How often the sync service does what: its periods, gaps and bounded waits."""

from __future__ import annotations

VERIFY_EVERY_S = 30.0        # look at the hosts file again even when nothing changed
HEARTBEAT_S = 3600.0         # republish an unchanged record this often (its age then says alive)
DEBOUNCE_S = 0.3             # netlink: wait for the burst of messages of one change to end
FORCED_GAP_S = 2.0           # a network change asks for the public IP at most this often
MAX_WAIT_S = 5.0
WORKER_STOP_S = 2.0          # stopping waits this long at most for a check or lookup under way
FOLDER_SETTLE_S = 0.05       # a watched folder: its events are taken at most this often
RECHECK_AFTER_S = (5.0, 15.0, 45.0)   # re-run failing checks after a change, then give up


def read_period(interval_s: float) -> float:
    """How often peers' records are read: a quarter of the poll interval, 0.25 .. 1 s (a
    watched folder is read when a record changes, and every interval_s besides)."""
    return min(1.0, max(0.25, float(interval_s) / 4))
