"""The time a node reads: the wall clock (:class:`Clock`, :data:`WALL_CLOCK`) or simulated time
(:class:`SimClock`, driven by :mod:`flexsheet.runtime.lockstep`, with its :class:`SimTimer`), and
:func:`ticks`, a drift-free schedule on the wall clock."""

from __future__ import annotations

import asyncio
import itertools
import time
from collections.abc import Callable
from typing import Any

__all__ = ["Clock", "WALL_CLOCK", "SimClock", "SimTimer", "ticks"]


class Clock:
    """The time a node reads (:meth:`~flexsheet.runtime.node.Node.now`, header stamps, timers): here the wall
    clock, ``time.time()`` s."""

    simulated = False

    def now(self) -> float:
        return time.time()

    def stamp(self) -> float:
        """The default ``Header.stamp`` of what is published now: :meth:`now` here; on a live simulated clock
        the time the running handler's output leaves (its start plus its charged compute)."""
        return time.time()


#: the wall clock every node uses unless its container replays a bag in lockstep
WALL_CLOCK = Clock()


class SimTimer:
    """A :meth:`~flexsheet.runtime.node.Node.timer` on a :class:`SimClock`: fired by the lockstep driver when
    the replayed time passes ``due`` (s); ``cancel()`` stops it. ``node``: the
    :class:`~flexsheet.runtime.node.Node` whose timer it is."""

    __slots__ = ("period", "callback", "node", "due", "index", "cancelled", "sim_cost", "sim_delay")

    def __init__(self, period: float, callback: Callable, node: Any, due: float | None, index: int,
                 sim_cost: float = 0.0, sim_delay: float = 0.0) -> None:
        self.period, self.callback, self.node, self.due, self.index = period, callback, node, due, index
        self.cancelled = False
        self.sim_cost = float(sim_cost)
        self.sim_delay = float(sim_delay)

    def cancel(self) -> None:
        self.cancelled = True

    def done(self) -> bool:
        return self.cancelled


class SimClock(Clock):
    """Simulated time (ROS ``use_sim_time``), driven by :mod:`flexsheet.runtime.lockstep`: in a lockstep
    replay :meth:`set` to each bag message's log time before it is delivered; in a live simulated graph
    (``live=True``, launch files' ``clock: sim``) advanced from event to event by the scheduler, which charges
    each handler its declared compute (``sim_cost``). Never goes backwards. Reads 0.0 until first set.

    Timers created on it (:meth:`add_timer`) fire in due order (ties in creation order), so two runs with the
    same input run every callback at the same simulated instants.
    """

    simulated = True

    def __init__(self, live: bool = False) -> None:
        self._t: float | None = None
        self.live = bool(live)
        self.emit: float | None = None   # output time of the running handler (live: start + sim_cost)
        self.timers: list[SimTimer] = []
        self._count = itertools.count()

    def stamp(self) -> float:
        e = self.emit
        return self.now() if e is None else e

    @property
    def started(self) -> bool:
        return self._t is not None

    def now(self) -> float:
        t = self._t
        return 0.0 if t is None else t

    def set(self, t: float) -> None:
        """Move the clock to ``t`` s (a smaller ``t`` keeps the clock where it is). The first call anchors the
        timers created before it: their first tick is ``t + period``."""
        t = float(t)
        if self._t is None:
            for tm in self.timers:
                if tm.due is None:
                    tm.due = t + tm.period
            self._t = t
        elif t > self._t:
            self._t = t

    def add_timer(self, period: float, callback: Callable, node: Any, sim_cost: float = 0.0,
                  sim_delay: float = 0.0) -> SimTimer:
        tm = SimTimer(period, callback, node, None if self._t is None else self._t + period,
                      next(self._count),
                      sim_cost, sim_delay)
        self.timers.append(tm)
        return tm

    def next_due(self, t: float) -> SimTimer | None:
        """The live timer due soonest at or before ``t`` (None if none); cancelled timers are dropped."""
        self.timers = [tm for tm in self.timers if not tm.cancelled]
        due = [tm for tm in self.timers if tm.due is not None and tm.due <= t]
        return min(due, key=lambda tm: (tm.due, tm.index)) if due else None


async def ticks(period: float):
    """Async generator: yields every ``period`` s on a drift-free schedule; an overrun restarts the schedule
    rather than bursting to catch up. Used by :meth:`~flexsheet.runtime.node.Node.timer` and the device twins'
    loops."""
    nxt = time.monotonic()
    while True:
        nxt += period
        delay = nxt - time.monotonic()
        if delay > 0:
            await asyncio.sleep(delay)
        else:
            nxt = time.monotonic()  # overrun: do not burst to catch up
        yield

