"""A blocking call awaited from asyncio with a bound, in a daemon thread (DNS, HTTP, SSH)."""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections.abc import Callable
from typing import Any, TypeVar

T = TypeVar("T")


async def run_blocking(func: Callable[..., T], *args: Any, timeout: float | None = None) -> T:
    """Run blocking *func* in a daemon thread and await it (raises asyncio.TimeoutError).

    Unlike ``asyncio.to_thread`` a stuck call (a resolver waiting on a dead DNS server) never
    holds up the interpreter's exit: the thread is a daemon and nobody joins it.
    """
    loop = asyncio.get_running_loop()
    fut: asyncio.Future[T] = loop.create_future()

    def deliver(setter: Callable[[Any], None], value: Any) -> None:
        if not fut.done():
            setter(value)

    def target() -> None:
        try:
            value = func(*args)
        except BaseException as exc:  # noqa: BLE001 - handed to the awaiting task
            with contextlib.suppress(RuntimeError):  # loop already closed
                loop.call_soon_threadsafe(deliver, fut.set_exception, exc)
        else:
            with contextlib.suppress(RuntimeError):
                loop.call_soon_threadsafe(deliver, fut.set_result, value)

    threading.Thread(target=target, daemon=True, name=f"rosnet-{getattr(func, '__name__', 'io')}").start()
    if timeout is None:
        return await fut
    return await asyncio.wait_for(fut, max(timeout, 0.001))
