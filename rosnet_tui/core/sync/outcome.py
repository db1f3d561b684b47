"""What the sync service answers: a round's result, or the refusal to start."""

from __future__ import annotations

from dataclasses import dataclass


class SyncError(Exception):
    """The service cannot start (settings, store configuration, another instance)."""


@dataclass
class RoundResult:
    ok: bool
    applied: bool
    errors: dict[str, str]
