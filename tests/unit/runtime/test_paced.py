"""A node's heavy call at a bounded rate (flexsheet.runtime.paced): on the wall clock in a thread of its own,
the loop free; on a simulated clock on the loop thread at the request, charged its cost; never faster than its
rate."""

from __future__ import annotations

import asyncio
import threading
import time
from types import SimpleNamespace

import pytest

from flexsheet.runtime.paced import PacedCall


class _SimNode:
    """What PacedCall uses of a node on a simulated clock: the time, charge and timer."""

    def __init__(self) -> None:
        self.clock = SimpleNamespace(simulated=True)
        self.t = 0.0
        self.charged: list[float] = []
        self.timers: list = []

    def monotonic(self) -> float:
        return self.t

    def charge(self, seconds: float) -> None:
        self.charged.append(seconds)

    def timer(self, period, callback) -> None:
        self.timers.append((period, callback))


def test_on_a_simulated_clock_a_request_runs_at_once_within_the_rate_and_is_charged():
    node, calls, done, failed = _SimNode(), [], [], []

    def call():
        calls.append(node.t)
        if node.t == 0.3:
            raise ValueError("bad input")
        return node.t

    paced = PacedCall(node, 10.0, call, done.append, failed.append, cost=0.008, name="t")
    asyncio.run(paced.start(init=lambda: calls.append("init")))
    assert calls == ["init"] and node.timers[0][0] == pytest.approx(0.1)
    for t in (0.1, 0.15, 0.3):                # 0.15: the rate holds it back, and it stays wanted
        node.t = t
        paced.request()
    assert calls[1:] == [0.1, 0.3] and done == [0.1] and str(failed[0]) == "bad input"
    assert node.charged == [0.008, 0.008]
    node.t = 0.45
    asyncio.run(node.timers[0][1]())          # the tick: nothing wanted, nothing runs
    assert calls[1:] == [0.1, 0.3]
    paced.request()
    assert calls[-1] == 0.45 and paced.elapsed(time.perf_counter() - 5.0) == 0.008


def test_on_the_wall_clock_the_call_runs_in_its_own_thread_at_most_at_its_rate():
    threads, starts = set(), []

    async def main():
        node = SimpleNamespace(clock=SimpleNamespace(simulated=False), monotonic=time.monotonic,
                               _loop=asyncio.get_running_loop())
        done = asyncio.Queue()

        def call():
            threads.add(threading.current_thread().name)
            starts.append(paced.last)  # the loop's start of this call (its thread runs it just after)
            return len(starts)

        paced = PacedCall(node, 20.0, call, done.put_nowait, lambda exc: None, cost=0.0, name="paced-test")
        await paced.start(init=lambda: threads.add(threading.current_thread().name))
        for _ in range(4):                    # bursts of requests are coalesced, 50 ms apart at most 20 Hz
            for _ in range(5):
                paced.request()
            await asyncio.wait_for(done.get(), 2.0)
        await paced.close(release=lambda: threads.add(threading.current_thread().name))

    asyncio.run(main())
    assert len(starts) == 4 and all(n.startswith("paced-test") for n in threads) and len(threads) == 1
    assert min(b - a for a, b in zip(starts, starts[1:], strict=False)) >= 0.05 - 1e-3


def test_a_rate_that_is_not_positive_is_refused():
    with pytest.raises(ValueError, match="rate must be > 0 Hz, got 0"):
        PacedCall(_SimNode(), 0.0, lambda: None, print, print, cost=0.0, name="t")
