"""A node's heavy call (a drawing, a frame), run at most ``rate`` times a second after a request, on either
clock.

On the wall clock the call runs in a thread of its own (its context, e.g. an OpenGL one, lives there), the
loop free; the loop waits for a request, keeps to the rate, awaits ``before`` and runs the call in that
thread. On a simulated clock no host thread may run beside simulated time: the call runs on the loop thread at
the request (or at the next tick of ``rate`` when the rate held it back; ``before`` is awaited there), and
each call is charged ``cost`` s of simulated time (:meth:`flexsheet.runtime.node.Node.charge`), so what it
publishes leaves when the lab's machine would have finished it. The node's code is the same on both clocks.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Awaitable, Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

__all__ = ["PacedCall"]


class PacedCall:
    """``call()`` at most ``rate`` Hz after :meth:`request` (see module docstring). ``done(result)`` runs on
    the loop thread with what the call returned; a ``ValueError`` it raises goes to ``failed(exc)`` instead.
    ``cost`` s: the lab's time for one call (charged on a simulated clock); ``name``: the thread's name;
    ``before``: an async hook awaited before a call from the tick or the wall clock's loop (not from a request
    on a simulated clock, which runs inside the requesting handler). Raises ``ValueError`` for a rate that is
    not > 0."""

    def __init__(self, node, rate: float, call: Callable[[], Any], done: Callable[[Any], None],
                 failed: Callable[[ValueError], None], cost: float, name: str,
                 before: Callable[[], Awaitable[None]] | None = None) -> None:
        if not rate > 0:
            raise ValueError(f"rate must be > 0 Hz, got {rate!r}")
        self.node, self.period, self.call, self.done, self.failed = node, 1.0 / rate, call, done, failed
        self.cost, self.name, self.before = cost, name, before
        self.simulated = node.clock.simulated
        self.last = 0.0                        # the last call's start, s (the node's monotonic time)
        self._wanted = False
        self._pool: ThreadPoolExecutor | None = None
        self._event: asyncio.Event | None = None
        self._task: asyncio.Task | None = None

    async def start(self, init: Callable[[], None] | None = None) -> None:
        """Run ``init()`` where the calls will run (the call's thread, or the loop thread on a simulated
        clock), then start serving requests."""
        if self.simulated:
            if init is not None:
                init()
            self.node.timer(self.period, self._tick)
            return
        loop = asyncio.get_running_loop()
        self._pool = ThreadPoolExecutor(1, thread_name_prefix=self.name)
        if init is not None:
            await loop.run_in_executor(self._pool, init)
        self._event = asyncio.Event()
        self._task = loop.create_task(self._serve())

    def request(self) -> None:
        """Ask for a call (thread-safe on the wall clock; on a simulated clock it runs now if the rate
        allows)."""
        self._wanted = True
        if self.simulated:
            self._run_here()
        elif self._event is not None:
            self.node._loop.call_soon_threadsafe(self._event.set)

    def elapsed(self, t0: float) -> float:
        """The call's time so far, s, from ``t0 = time.perf_counter()`` at its start: the host's on the wall
        clock, ``cost`` on a simulated clock (a message must not depend on the host)."""
        return self.cost if self.simulated else time.perf_counter() - t0

    async def close(self, release: Callable[[], None] | None = None) -> None:
        """Stop serving and run ``release()`` where the calls ran."""
        if self._task is not None:
            self._task.cancel()
        if self._pool is None:
            if release is not None:
                release()
            return
        if release is not None:
            await asyncio.get_running_loop().run_in_executor(self._pool, release)
        self._pool.shutdown(wait=True)

    # ------------------------------------------------------------------ simulated clock: the loop thread
    async def _tick(self) -> None:
        if self.before is not None:
            await self.before()
        self._run_here()

    def _run_here(self) -> None:
        now = self.node.monotonic()
        if not self._wanted or now - self.last < self.period - 1e-9:
            return
        self._wanted = False
        self.last = now
        self.node.charge(self.cost)
        try:
            result = self.call()
        except ValueError as exc:
            self.failed(exc)
            return
        self.done(result)

    # ------------------------------------------------------------------ wall clock: the call's own thread
    async def _serve(self) -> None:
        loop = asyncio.get_running_loop()
        while True:
            await self._event.wait()
            self._event.clear()
            wait = self.last + self.period - self.node.monotonic()
            if wait > 0:
                await asyncio.sleep(wait)
            self._wanted = False
            self.last = self.node.monotonic()
            if self.before is not None:
                await self.before()
            try:
                result = await loop.run_in_executor(self._pool, self.call)
            except ValueError as exc:
                self.failed(exc)
                continue
            self.done(result)
