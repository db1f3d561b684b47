"""Picking the record store the settings' [sync] table names (folder or DNS).

Each store module imports :mod:`.store` (the protocol, results and errors); this module imports
the stores (the DNS store lazily, so a folder user never loads the DNS library).
"""

from __future__ import annotations

from pathlib import Path

from rosnet_tui.core.config.settings_model import Settings

from .folder import FolderStore
from .store import RecordStore, StoreConfigError


def make_store(settings: Settings, *, timeout_s: float | None = None) -> RecordStore:
    """The store the settings' [sync] table names. Raises StoreConfigError when incomplete."""
    y = settings.sync
    timeout = timeout_s if timeout_s is not None else max(1.0, float(settings.checks.timeout_s))
    if y.store == "folder":
        if not y.folder:
            raise StoreConfigError("the folder store needs sync.folder (the shared folder) in "
                                   "the settings")
        return FolderStore(Path(y.folder).expanduser())
    if y.store == "dns":
        from .dnsstore import DnsStore  # start-up cost: dnspython

        missing = [k for k in ("dns_server", "zone", "tsig_key_file") if not getattr(y, k)]
        if missing:
            raise StoreConfigError("the dns store needs " + " and ".join(f"sync.{k}" for k in missing)
                                   + " in the settings")
        return DnsStore(y.dns_server, y.zone, Path(y.tsig_key_file).expanduser(),
                        timeout_s=timeout)
    raise StoreConfigError(f"unknown store {y.store!r} (sync.store is 'folder' or 'dns')")
