"""Background work beside a real-time graph: a worker process that must never take CPU from the nodes.

Niceness alone is not enough on the lab's machines: a CPU-bound worker at nice 5 beside the display's ten
processes on two cores measurably slowed the loop (stroke Δθ 0.36–0.47° → 1.8–3.5° in the simulated graph,
camera frame → fingertip p99 77 → 400+ ms) while the renderer built a sheet table. :func:`lower_priority`
puts the calling process in the ``SCHED_IDLE`` class (Linux: it runs only when a CPU would otherwise idle and
is preempted at once) at niceness ``nice``, with one BLAS thread (OpenBLAS's spinning threads would otherwise
compete with each other; ``threadpoolctl``)."""

from __future__ import annotations

import os

__all__ = ["lower_priority"]


def lower_priority(nice: int = 19) -> str:
    """Make the calling process a background worker (module doc); returns what took effect, e.g.
    ``"SCHED_IDLE, nice +19, 1 BLAS thread"``. Never raises: each step that the OS refuses is skipped."""
    done = []
    try:
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
        done.append("SCHED_IDLE")
    except (AttributeError, OSError):
        pass
    if nice:
        try:
            os.nice(nice)
            done.append(f"nice +{nice}")
        except OSError:
            pass
    try:
        from threadpoolctl import threadpool_limits

        threadpool_limits(1, user_api="blas")
        done.append("1 BLAS thread")
    except ImportError:        # pragma: no cover - a dependency
        pass
    return ", ".join(done) or "unchanged"
