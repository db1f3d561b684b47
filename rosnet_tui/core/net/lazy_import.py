"""Importing a library without the optional parts of it this program never uses.

paramiko imports invoke (for ssh_config's ``Match exec``) and requests a character detector
(chardet or charset_normalizer, to guess a body's encoding): each as long to import as a good
part of the library itself, on the path of every round of checks, where the process is bound by
its CPU. :func:`import_without` imports a library with such modules held off: its own
``import`` of them fails as if they were not installed, which both libraries allow.
"""

from __future__ import annotations

import importlib
import sys
import threading
import warnings
from types import ModuleType

_GUARD = threading.Lock()
_LOCKS: dict[str, threading.Lock] = {}     # one a library: two libraries import side by side


def _lock_for(name: str) -> threading.Lock:
    with _GUARD:
        return _LOCKS.setdefault(name, threading.Lock())


def import_without(name: str, *held: str, quiet: str | None = None) -> ModuleType:
    """Module *name*, imported (the first time) with the modules *held* off: ``import`` of one of
    them inside it raises ImportError. Held modules already imported are left alone; afterwards
    any of them can be imported again as usual. *quiet*: a warning the import may give about
    a held module (a regular expression of its text), not shown (from then on). A module
    another thread is still importing is waited for, as ``import`` waits; the import of another
    library is not (the round's SSH login waited for requests' import otherwise, about 50 ms)."""
    if name in sys.modules:     # imported, or being imported: import waits for its end
        return importlib.import_module(name)
    with _lock_for(name):
        if name in sys.modules:
            return importlib.import_module(name)
        mine = [h for h in held if h not in sys.modules]
        for h in mine:
            sys.modules[h] = None  # type: ignore[assignment]  # the import system's "not here"
        if quiet is not None:
            # For good, not inside catch_warnings: that saves and puts back the filters of the
            # whole process, and another thread leaving its own (paramiko's import, side by
            # side) put back filters without this one while the import was still running.
            warnings.filterwarnings("ignore", message=quiet)
        try:
            return importlib.import_module(name)
        finally:
            for h in mine:
                if h in sys.modules and sys.modules[h] is None:
                    del sys.modules[h]
