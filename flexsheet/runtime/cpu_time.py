"""The thread CPU time of a coroutine's own steps (pure: the standard library).

An async handler runs in steps between its awaits; timing it across ``await handler(msg)`` would also count
everything the event loop ran meanwhile (other nodes' handlers, the bus). :func:`timed` drives the coroutine
one step at a time and adds only the CPU time of its own steps (``time.thread_time``, s) to a counter, so
``flexsheet bench sim`` books an async handler's work under its node, as it books a sync one's.
"""

from __future__ import annotations

import time
from collections.abc import Coroutine
from typing import Any

__all__ = ["CpuCounter", "timed"]

_thread_time = time.thread_time


class CpuCounter:
    """Accumulated thread CPU time ``s`` (seconds) of the steps :func:`timed` ran."""

    __slots__ = ("s",)

    def __init__(self) -> None:
        self.s = 0.0


class _Timed:
    """Awaitable that steps ``coro`` (send / throw) and adds each step's thread CPU time to ``counter``."""

    __slots__ = ("coro", "counter")

    def __init__(self, coro: Coroutine, counter: CpuCounter) -> None:
        self.coro, self.counter = coro, counter

    def __await__(self):
        coro, counter = self.coro, self.counter
        value: Any = None
        error: BaseException | None = None
        while True:
            t0 = _thread_time()
            try:
                yielded = coro.send(value) if error is None else coro.throw(error)
            except StopIteration as stop:
                counter.s += _thread_time() - t0
                return stop.value
            except BaseException:
                counter.s += _thread_time() - t0
                raise
            counter.s += _thread_time() - t0
            try:
                value, error = (yield yielded), None
            except BaseException as exc:      # cancellation or a throw into the awaiting task: pass it on
                value, error = None, exc


def timed(coro: Coroutine, counter: CpuCounter) -> _Timed:
    """``await timed(coro, counter)`` is ``await coro``, and adds the CPU time of ``coro``'s own steps to
    ``counter.s`` (s): not what other tasks ran while it waited. Raises what ``coro`` raises."""
    return _Timed(coro, counter)
