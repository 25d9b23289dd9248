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


#: :func:`timed`'s ``first`` when the coroutine has not been stepped yet
_NOT_STARTED: Any = object()


class _Timed:
    """Awaitable that steps ``coro`` (send / throw) and adds each step's thread CPU time to ``counter``; with
    ``first``, ``coro`` already ran its first step, which yielded ``first``."""

    __slots__ = ("coro", "counter", "first")

    def __init__(self, coro: Coroutine, counter: CpuCounter, first: Any = _NOT_STARTED) -> None:
        self.coro, self.counter, self.first = coro, counter, first

    def __await__(self):
        coro, counter = self.coro, self.counter
        value: Any = None
        error: BaseException | None = None
        if self.first is not _NOT_STARTED:
            value, error = yield from _pass(self.first)
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
            value, error = yield from _pass(yielded)


def _pass(yielded: Any):
    """Yield ``yielded`` to the task driving us; (the value sent back, None) or (None, what was thrown in:
    a cancellation, passed on to the coroutine)."""
    try:
        return (yield yielded), None
    except BaseException as exc:
        return None, exc


def timed(coro: Coroutine, counter: CpuCounter, first: Any = _NOT_STARTED) -> _Timed:
    """``await timed(coro, counter)`` is ``await coro``, and adds the CPU time of ``coro``'s own steps to
    ``counter.s`` (s): not what other tasks ran while it waited. ``first``: ``coro`` already ran its first
    step (timed by the caller), which yielded ``first``. Raises what ``coro`` raises."""
    return _Timed(coro, counter, first)
