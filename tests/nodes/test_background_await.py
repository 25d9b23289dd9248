"""Awaiting a worker process without blocking the loop, and ending it on a stop."""

import asyncio
import multiprocessing
import time

from flexsheet.runtime.background import await_worker, start_worker


def _proc(seconds: float):
    p = multiprocessing.get_context("spawn").Process(target=time.sleep, args=(seconds,), daemon=True)
    start_worker(p)
    return p


def test_a_worker_that_ends_is_awaited_while_the_loop_runs_and_a_stop_terminates_one():
    async def ends() -> tuple[bool, int]:
        ticks = 0

        async def tick():
            nonlocal ticks
            while True:
                ticks += 1
                await asyncio.sleep(0.01)

        t = asyncio.get_running_loop().create_task(tick())
        p = _proc(0.5)
        ok = await await_worker(p, lambda: False)
        t.cancel()
        return ok and p.exitcode == 0, ticks

    ok, ticks = asyncio.run(ends())
    assert ok and ticks >= 30                      # the loop kept running (0.5 s of sleep plus the spawn)

    async def stopped() -> tuple[bool, float, bool]:
        p = _proc(30.0)
        t0 = time.monotonic()
        ok = await await_worker(p, lambda: time.monotonic() - t0 > 0.3)
        return ok, time.monotonic() - t0, p.is_alive()

    ok, took, alive = asyncio.run(stopped())
    assert not ok and not alive and took < 1.5
