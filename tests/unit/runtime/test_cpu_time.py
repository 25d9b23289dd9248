"""flexsheet.runtime.cpu_time: an async handler's CPU is its own steps', not what the loop ran while it
waited."""

from __future__ import annotations

import asyncio
import time

import pytest

from flexsheet.runtime.cpu_time import CpuCounter, timed


def _burn(s: float) -> None:
    t0 = time.thread_time()
    while time.thread_time() - t0 < s:
        pass


def test_only_the_coroutines_own_steps_are_counted():
    async def handler(ev: asyncio.Event) -> str:
        _burn(0.03)
        await ev.wait()             # meanwhile another task burns 0.12 s on this thread
        _burn(0.02)
        return "done"

    async def other(ev: asyncio.Event) -> None:
        _burn(0.12)
        ev.set()

    async def main():
        ev, cpu = asyncio.Event(), CpuCounter()
        t0 = time.thread_time()
        res, _ = await asyncio.gather(timed(handler(ev), cpu), other(ev))
        return res, cpu.s, time.thread_time() - t0

    res, own, whole = asyncio.run(main())
    assert res == "done" and whole >= 0.17
    assert own == pytest.approx(0.05, abs=0.015)        # 0.03 + 0.02, not the 0.17 the await spanned


def test_errors_and_cancellation_pass_through_and_are_counted():
    async def bad():
        _burn(0.02)
        await asyncio.sleep(0)
        raise ValueError("bad input: x=3")

    async def slow():
        await asyncio.sleep(10)

    async def main():
        cpu = CpuCounter()
        with pytest.raises(ValueError, match="x=3"):
            await timed(bad(), cpu)
        assert cpu.s >= 0.019
        task = asyncio.ensure_future(timed(slow(), CpuCounter()))
        await asyncio.sleep(0.01)
        task.cancel()
        with pytest.raises(asyncio.CancelledError):
            await task

    asyncio.run(main())
