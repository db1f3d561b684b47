"""What every record store offers (folder, DNS): the protocol, its results and errors.

Picking one from the settings is :func:`rosnet_tui.core.sync.choose_store.make_store`.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

from rosnet_tui.core.printable import printable
from rosnet_tui.core.saved.sync_records import Candidate, Record, choose_best


class StoreError(Exception):
    """The store cannot be used right now (unreachable, refused, misconfigured): says why."""


class StoreConfigError(StoreError):
    """The settings do not describe a usable store (retrying will not help)."""


@dataclass(frozen=True)
class Refusal:
    """A copy that was not used, and why (malformed, foreign, a garbage peer record)."""

    source: str
    name: str | None
    why: str

    def __post_init__(self) -> None:   # a file name or a record's text: shown and logged
        object.__setattr__(self, "source", printable(self.source))
        object.__setattr__(self, "why", printable(self.why))
        if self.name is not None:
            object.__setattr__(self, "name", printable(self.name))


@dataclass
class FetchResult:
    """The best valid copy of each name that has one, and what was refused or noted."""

    records: dict[str, Candidate] = field(default_factory=dict)
    refused: list[Refusal] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    # Every valid copy seen for our own name (to continue its seq, and to tidy up).
    own_copies: list[Candidate] = field(default_factory=list)
    # Name (lower case) to the public key its records must be signed by (signing.pinned_keys);
    # a name without one has no record that counts.
    keys: Mapping[str, Any] = field(default_factory=dict)

    def add_copies(self, name: str, copies: list[Candidate], own_name: str) -> None:
        """Keep the best of *name*'s copies signed by its owner (all of them for our own name);
        the others are refused before they compete, so a forged copy never wins."""
        from .signing import verify_each  # start-up cost: cryptography

        copies, bad = verify_each(copies, self.keys)
        self.refused += [Refusal(c.source, name, why) for c, why in bad]
        if name == own_name:
            self.own_copies = copies
            return
        best, notes = choose_best(copies)
        self.notes += notes
        if best is not None:
            self.records[name] = best


class RecordStore(Protocol):
    kind: str

    def describe(self) -> str:
        """Where the records live, in a few words (for logs and status)."""
        ...

    def publish(self, record: Record) -> None:
        """Make *record* this component's current record (atomic). Raises StoreError."""
        ...

    def fetch(self, names: Iterable[str], own_name: str, keys: Mapping[str, Any]) -> FetchResult:
        """The best valid record of each of *names* signed by the key *keys* pins for it.
        Raises StoreError when unreachable."""
        ...
