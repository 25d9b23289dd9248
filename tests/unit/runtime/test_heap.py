"""Freed heap back to the OS (flexsheet/runtime/heap.py)."""

from __future__ import annotations

import sys

import pytest

from flexsheet.runtime import heap


def _rss_mb() -> float:
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("VmRSS")) / 1024.0


@pytest.mark.skipif(not sys.platform.startswith("linux") or heap._malloc_trim() is None, reason="glibc only")
def test_a_fragmented_heap_shrinks_by_what_was_freed_in_it():
    """128 MB in 16 KiB blocks (below glibc's mmap threshold: on the heap), every block but each 64th freed:
    the pinned blocks keep the heap's top, so the free pages stay resident until the trim, which returns ≥ 60
    MB."""
    blocks = [bytearray(16384) for _ in range(8192)]
    for b in blocks:
        b[::4096] = b"\x01" * len(b[::4096])            # touch every page
    kept = blocks[::64]
    del blocks
    before = _rss_mb()
    assert heap.release_free_memory() is True
    after = _rss_mb()
    assert before - after >= 60.0, (before, after)
    assert len(kept) == 128


def test_the_trimmer_trims_once_per_period():
    """With period 10 s on an injected clock: not at 5 s, once at 10 s, not again at 15 s, again at 20 s; a
    bad period is named."""
    now, calls = [100.0], []
    t = heap.Trimmer(10.0, clock=lambda: now[0], release=lambda: calls.append(now[0]) or True)
    got = []
    for s in (105.0, 110.0, 115.0, 120.0):
        now[0] = s
        got.append(t.maybe())
    assert got == [False, True, False, True] and calls == [110.0, 120.0]
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="period"):
            heap.Trimmer(bad)
