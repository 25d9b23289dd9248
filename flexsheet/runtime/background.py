"""Background work beside a real-time graph: a worker process that must never take CPU from the nodes.

Niceness alone is not enough on the lab's machines: a CPU-bound worker at nice 5 beside the display's ten
processes on two cores measurably slowed the loop (stroke Δθ 0.36–0.47° → 1.8–3.5° in the simulated graph,
camera frame → fingertip p99 77 → 400+ ms) while the renderer built a sheet table. :func:`lower_priority`
puts the calling process in the ``SCHED_IDLE`` class (Linux: it runs only when a CPU would otherwise idle and
is preempted at once) at niceness ``nice``, with one BLAS thread (OpenBLAS's spinning threads would otherwise
compete with each other; ``threadpoolctl``), and ties it to its parent: when the node that started it dies
(even ``kill -9``) the worker gets SIGKILL (``PR_SET_PDEATHSIG``). Without that an orphaned worker kept the
dead node's stdout open, so the launcher never saw the node exit and never respawned it. The worker ignores
SIGINT: its owner ends it (the node's teardown terminates it; the experiment's pool on Ctrl-C), or it dies
with its owner. The launcher stops a node with SIGINT to its whole process group, and a worker that took it
printed a ``KeyboardInterrupt`` traceback at every shutdown during a table build."""

from __future__ import annotations

import ctypes
import multiprocessing
import os
import signal
import threading

__all__ = ["lower_priority", "start_worker"]


def lower_priority(nice: int = 19, idle: bool = True) -> str:
    """Make the calling process a background worker (module doc); call it first thing in the worker. Returns
    what took effect, e.g. ``"SIGINT ignored, dies with its parent, SCHED_IDLE, nice +19, 1 BLAS
    thread"``. Never raises: a step the OS refuses is skipped. Exits the process at once if its parent is
    already gone (the parent :func:`multiprocessing.parent_process` names, so also one killed while this
    worker still imported). ``idle`` False: niceness only, no ``SCHED_IDLE`` — for work the graph needs soon
    (the world's true sheet: in the idle class a table could take minutes beside a running graph and, killed
    with its node, never reach the cache)."""
    done = []
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        done.append("SIGINT ignored")
    except ValueError:             # not the main thread: the caller is not a worker process of its own
        pass
    # the parent as multiprocessing recorded it when it started this worker: a parent killed while the worker
    # still imported (before the tie below) has already been replaced by init or a subreaper in getppid()
    mp_parent = multiprocessing.parent_process()
    parent = mp_parent.pid if mp_parent is not None and mp_parent.pid else os.getppid()
    try:
        if ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL) == 0:    # PR_SET_PDEATHSIG
            done.append("dies with its parent")
    except (AttributeError, OSError):
        pass
    if os.getppid() != parent:           # the parent died before the tie was made
        os._exit(1)
    if idle:
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


def start_worker(proc) -> None:
    """``proc.start()`` (a :class:`multiprocessing.Process`) with SIGINT ignored in the child from its first
    instruction: an ignored disposition survives the spawn's fork + exec, and Python keeps it. The worker then
    ignores the launcher's SIGINT to the node's process group even while it still imports, before its
    :func:`lower_priority` (a stop 1 s after a build started printed a ``KeyboardInterrupt`` traceback from
    the worker's numpy import). The caller's own handler is restored at once. Off the main thread (where
    Python may not touch signal handlers) it is a plain ``proc.start()``."""
    if threading.current_thread() is not threading.main_thread():
        proc.start()
        return
    old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        proc.start()
    finally:
        signal.signal(signal.SIGINT, old)

