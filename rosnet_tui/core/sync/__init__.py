"""Address sync between components (issue 7): when a modem restart changes a public IP, every
peer's hosts entry and ROS_MASTER_URI follow without anyone touching them.

- the record each component publishes, its validation, choosing among copies, and the record of
  each peer last applied here live a floor below, in :mod:`rosnet_tui.core.saved.sync_records`
  and :mod:`rosnet_tui.core.saved.sync_applied` (the checks read them too);
- :mod:`.folder`, :mod:`.dnsstore`: the stores (a shared folder; RFC 2136 + TSIG on DNS);
- :mod:`.watcher`: this component's own addresses (netlink, public-IP polling);
- :mod:`.plan`: the hosts set by evidence (same public IP -> on this LAN);
- :mod:`.service`: the service (the settings, its rounds), with its parts, each owning its state:
  :class:`.watcher.AddressWatch` (our addresses), :mod:`.publisher` (the store, the records),
  :mod:`.applier` (the safe writer, the affected checks), :mod:`.loop` (wake-ups, stop) and
  :class:`.state.Report` (the status document, the messages);
- :mod:`.status`: what ``rosnet-tui sync status`` shows.
"""

from __future__ import annotations

from .affected import run_affected_checks
from .backoff import Backoff, backoff_cap
from .choose_store import make_store
from .folder import FolderStore
from .outcome import RoundResult, SyncError
from .plan import Plan, PlanError, plan_hosts
from .service import SyncService
from .status import load_status, render_status, status_path
from .store import FetchResult, Refusal, StoreConfigError, StoreError

__all__ = [
    "Backoff", "FetchResult", "FolderStore", "Plan", "PlanError", "Refusal", "RoundResult",
    "StoreConfigError", "StoreError", "SyncError", "SyncService", "backoff_cap", "load_status",
    "make_store", "plan_hosts", "render_status", "run_affected_checks", "status_path",
]
