"""The peers a check runs its other side on, and working with them concurrently."""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable, Sequence
from typing import TypeVar

from rosnet_tui.core.config.settings_model import Peer, Settings

T = TypeVar("T")


def ssh_peers(s: Settings) -> list[Peer]:
    """The peers we can run commands on (those with an SSH user), in the settings' order."""
    return [p for p in s.peers if p.ssh_user]


NO_SSH_USER = ("no peer has an SSH user in the settings (peer.ssh_user), so the peer's side cannot "
               "be run from here")

PEER_CONCURRENCY = 8  # peers one check works with at once (the largest fleet: 8 members)


async def each_peer(peers: Sequence[Peer], work: Callable[[Peer], Awaitable[T]], *,
                    limit: int = PEER_CONCURRENCY, return_exceptions: bool = False
                    ) -> list[T | BaseException]:
    """``await work(peer)`` for every peer, concurrently, at most *limit* at once (each peer's
    SSH sessions share its one connection of the round); results in *peers*' order. With
    *return_exceptions*, an exception is that peer's result, as with ``asyncio.gather``."""
    gate = asyncio.Semaphore(max(1, limit))

    async def one(peer: Peer) -> T:
        async with gate:
            return await work(peer)

    return await asyncio.gather(*(one(p) for p in peers), return_exceptions=return_exceptions)
