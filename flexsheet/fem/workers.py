"""The worker processes of the long reference solves: :func:`run_workers`, the one pool of every long solve
(the cylinder's reference pushes, the sphere and path tables), a :class:`concurrent.futures.ProcessPoolExecutor`
of spawned workers tied to their parent; and :func:`prefetch`, which solves the :class:`Solve` jobs a run
reads and the cache lacks (:func:`missing_solves`) in such workers before the run reads them from the cache."""

from __future__ import annotations

import os
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass

import numpy as np

from flexsheet.fem import reference_paths
from flexsheet.fem.cache import ArrayCache
from flexsheet.fem.hyperelastic import PENALTY_SCALE, RefSpec
from flexsheet.fem.material import Material
from flexsheet.fem.reference_paths import (
    _depths,
    _load_step,
    _log,
    _previous_version_path,
    _reference_keys,
    _stable_key,
    reference_path,
    stable_path,
)


@dataclass(frozen=True)
class Solve:
    """One :func:`reference_path` a run reads: mesh, azimuth (deg), output depth spacing (m; depths
    ``_depths(step)``) and contact penalty scale; ``stable``: its :func:`stable_path` (the snapshot tables and
    the held-out pushes)."""

    spec: RefSpec
    angle_deg: float
    step: float
    penalty_scale: float = PENALTY_SCALE
    stable: bool = False

    def cost(self) -> float:
        """Relative CPU estimate for ordering (largest first): ∝ h_fine⁻³ (× (h_fine/skin)² with a skin), × 2 for
        a half model, × the load steps."""
        c = self.spec.h_fine ** -3 * (self.spec.h_fine / self.spec.skin_h) ** 2 if self.spec.skin_h else \
            self.spec.h_fine ** -3
        c *= self.spec.h_fine / self.spec.tip_h if self.spec.tip_h else 1.0      # a rough share for the tip
        half = self.angle_deg != 0.0 or not self.spec.half_z
        return c * (2.0 if half else 1.0) / _load_step(_depths(self.step))


def missing_solves(jobs: list[Solve], mat: Material, cache: ArrayCache, probes: np.ndarray, contact: str
                   ) -> list[Solve]:
    """The ``jobs`` :func:`reference_path` (or, ``stable``, :func:`stable_path`) would solve, not read, from
    ``cache`` (a previous version's path counts only when that version's path is this one's,
    :func:`_previous_version_path`), each loading path once (its ``stable`` job where there is one)."""
    todo: dict[str, Solve] = {}             # by the loading path's key: one worker per path, its sweep included
    for j in jobs:
        keys = _reference_keys(j.spec, j.angle_deg, _depths(j.step), mat, probes, contact, j.penalty_scale)
        missing = not os.path.exists(cache.path("reference", keys[0])) and _previous_version_path(cache, keys[1]) is None
        if j.stable and contact == "frictionless":     # its unloading sweep too (stable_path)
            sk = _stable_key(j.spec, j.angle_deg, _depths(j.step), mat, probes, contact, j.penalty_scale)
            missing = missing or not os.path.exists(cache.path("stable", sk))
        if missing and (keys[0] not in todo or j.stable):
            todo[keys[0]] = j
    return list(todo.values())


def prefetch(jobs: list[Solve], n_workers: int, mat: Material, cache: ArrayCache, probes: np.ndarray,
             contact: str) -> None:
    """Solve the ``jobs`` the cache lacks in ``n_workers`` processes (spawned, one BLAS thread each, their log
    lines prefixed "[solver N]"), into ``cache``; the run then reads them from it. Does nothing with one
    worker, a disabled cache or fewer than two solves missing. A failed solve is logged and left to the run,
    which solves it again and raises with the cause. Ctrl-C terminates the workers at once."""

    if n_workers < 2 or not cache.cache_dir:
        return
    todo = missing_solves(jobs, mat, cache, probes, contact)
    if len(todo) < 2:
        return
    n = min(n_workers, len(todo))
    _log(f"prefetch: {len(todo)} reference solves the cache lacks, in {n} worker processes (--jobs)")
    t0 = time.perf_counter()
    work = [(i, j, mat, cache.cache_dir, probes, contact) for i, j in enumerate(todo)]
    for i, sec, err in run_workers(_solve_one, work, n):
        j = todo[i]
        what = f"{j.spec.key()} at {j.angle_deg:g} deg, penalty {j.penalty_scale:g} E/h"
        _log(f"prefetch: {what} done in {sec:.0f} s" if err is None else
             f"prefetch: {what} failed ({err}); the run solves it itself")
    _log(f"prefetch: done in {time.perf_counter() - t0:.0f} s")


def _solver_init(counter) -> None:
    """Worker start: a log prefix "[solver N] " (:data:`flexsheet.fem.reference_paths._LOG_PREFIX`, which
    :func:`flexsheet.fem.reference_paths._log` reads); SIGINT ignored (the parent terminates the workers on
    Ctrl-C); one BLAS and OpenMP thread, CHOLMOD's libraries loaded first so the limit reaches them; tied to
    the parent, dies with it (:func:`flexsheet.runtime.background.lower_priority`, niceness unchanged)."""
    from flexsheet.runtime.background import lower_priority

    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = "1"
    try:
        import sksparse.cholmod  # noqa: F401 - loads the BLAS/OpenMP CHOLMOD uses before the thread limit
    except ImportError:
        pass
    lower_priority(0, idle=False)
    with counter.get_lock():
        counter.value += 1
        reference_paths._LOG_PREFIX = f"[solver {counter.value}] "


def _solve_one(args: tuple) -> tuple[int, float, str | None]:
    """Worker: one :func:`reference_path` (or :func:`stable_path`) into the cache; (job index, seconds, None or
    the error)."""
    i, job, mat, cache_dir, probes, contact = args
    t = time.perf_counter()
    try:
        solve = stable_path if job.stable else reference_path
        solve(job.spec, job.angle_deg, _depths(job.step), mat, ArrayCache(cache_dir, _log), probes, contact,
              job.penalty_scale)
    except Exception as exc:                    # noqa: BLE001 - reported; the run solves it again and raises
        return i, time.perf_counter() - t, f"{type(exc).__name__}: {exc}"
    return i, time.perf_counter() - t, None


def run_workers(fn, work: list, n: int):
    """Yield ``fn(w)`` for every ``w`` of ``work``, in the order they finish, computed in ``n`` spawned worker
    processes (a :class:`concurrent.futures.ProcessPoolExecutor`) started by :func:`_solver_init` (one BLAS
    thread, SIGINT ignored, tied to this process: killed with it, even by ``kill -9``). Ctrl-C, an error or
    leaving the loop early terminates the workers at once (a running solve is not waited for). The one pool of
    every long solve here (:func:`prefetch`, the sphere and path tables): a pool without the tie left its
    workers solving for minutes after its parent was killed. ``fn`` must be importable (module
    level) and catch its own errors."""
    import multiprocessing

    ctx = multiprocessing.get_context("spawn")
    pool = ProcessPoolExecutor(n, mp_context=ctx, initializer=_solver_init, initargs=(ctx.Value("i", 0),))
    finished = False
    try:
        for done in as_completed([pool.submit(fn, w) for w in work]):
            yield done.result()
        finished = True
    finally:
        if not finished:            # at once on Ctrl-C, an error or an early exit
            _terminate_workers(pool)
        pool.shutdown(wait=True, cancel_futures=True)


def _terminate_workers(pool: ProcessPoolExecutor) -> None:
    """Terminate ``pool``'s worker processes now, whatever they run (Python 3.14's
    ``ProcessPoolExecutor.terminate_workers``; before it, each of the executor's processes)."""
    stop = getattr(pool, "terminate_workers", None)
    if stop is not None:
        stop()
        return
    for proc in list((pool._processes or {}).values()):
        proc.terminate()


def default_jobs() -> int:
    """Worker processes for :func:`prefetch`: the cores this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
