"""The worker processes of the long reference solves: :func:`run_workers`, the one pool of every long solve
(the cylinder's reference pushes, the sphere and path tables, the scenes' references) on dask.distributed (a
local cluster, or a lab's with ``--scheduler``); and :func:`prefetch`, which solves the :class:`Solve` jobs a
run reads and the cache lacks (:func:`missing_solves`) in such workers before the run reads them from the
cache."""

from __future__ import annotations

import logging
import os
import time
from dataclasses import dataclass

import numpy as np

from flexsheet.fem.cache import ArrayCache
from flexsheet.fem.material import Material
from flexsheet.fem.reference.capsule_contact import PENALTY_SCALE
from flexsheet.fem.reference.mesh import RefSpec
from flexsheet.fem.reference.paths import (
    load_step,
    push_depths,
    reference_key,
    reference_path,
    stable_key,
    stable_path,
)
from flexsheet.runtime.background import lower_priority
from flexsheet.runtime.console import LIBRARY, show_lines

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Solve:
    """One :func:`reference_path` a run reads: mesh, azimuth (deg), output depth spacing (m; depths
    ``push_depths(step)``) and contact penalty scale; ``stable``: its :func:`stable_path` (the snapshot tables
    and the held-out pushes)."""

    spec: RefSpec
    angle_deg: float
    step: float
    penalty_scale: float = PENALTY_SCALE
    stable: bool = False

    def cost(self) -> float:
        """Relative CPU estimate for ordering (largest first): ∝ h_fine⁻³ (× (h_fine/skin)² with a skin), × 2
        for a half model, × the load steps."""
        c = self.spec.h_fine ** -3 * (self.spec.h_fine / self.spec.skin_h) ** 2 if self.spec.skin_h else \
            self.spec.h_fine ** -3
        c *= self.spec.h_fine / self.spec.tip_h if self.spec.tip_h else 1.0      # a rough share for the tip
        half = self.angle_deg != 0.0 or not self.spec.half_z
        return c * (2.0 if half else 1.0) / load_step(push_depths(self.step))


def missing_solves(jobs: list[Solve], mat: Material, cache: ArrayCache, probes: np.ndarray, contact: str
                   ) -> list[Solve]:
    """The ``jobs`` :func:`reference_path` (or, ``stable``, :func:`stable_path`) would solve, not read, from
    ``cache``, each loading path once (its ``stable`` job where there is one)."""
    todo: dict[str, Solve] = {}  # by the loading path's key: one worker per path, its sweep included
    for j in jobs:
        key = reference_key(j.spec, j.angle_deg, push_depths(j.step), mat, probes, contact, j.penalty_scale)
        missing = not os.path.exists(cache.path("reference", key))
        if j.stable and contact == "frictionless":     # its unloading sweep too (stable_path)
            sk = stable_key(j.spec, j.angle_deg, push_depths(j.step), mat, probes, contact, j.penalty_scale)
            missing = missing or not os.path.exists(cache.path("stable", sk))
        if missing and (key not in todo or j.stable):
            todo[key] = j
    return list(todo.values())


def prefetch(jobs: list[Solve], n_workers: int, mat: Material, cache: ArrayCache, probes: np.ndarray,
             contact: str, scheduler: str | None = None) -> None:
    """Solve the ``jobs`` the cache lacks on dask (:func:`run_workers`: ``n_workers`` local processes, or the
    cluster at ``scheduler``; log lines prefixed "[solver N]"), into ``cache``; the run then reads them from
    it, and a run interrupted and started again solves only what the cache still lacks. Does nothing with one
    local worker, a disabled cache or fewer than two solves missing. A failed solve is logged and left to the
    run, which solves it again and raises with the cause."""

    if not (parallel(n_workers) or scheduler) or not cache.cache_dir:
        return
    todo = missing_solves(jobs, mat, cache, probes, contact)
    if len(todo) < 2:
        return
    n = min(n_workers, len(todo))
    log.info(f"prefetch: {len(todo)} reference solves the cache lacks, in {n} worker processes (--jobs)")
    t0 = time.perf_counter()
    work = [(i, j, mat, cache.cache_dir, probes, contact) for i, j in enumerate(todo)]
    for i, sec, err in run_workers(_solve_one, work, n, scheduler):
        j = todo[i]
        what = f"{j.spec.key()} at {j.angle_deg:g} deg, penalty {j.penalty_scale:g} E/h"
        log.info(f"prefetch: {what} done in {sec:.0f} s" if err is None else
                 f"prefetch: {what} failed ({err}); the run solves it itself")
    log.info(f"prefetch: done in {time.perf_counter() - t0:.0f} s")


def _solver_init(name=None) -> None:
    """Worker setup, once per worker process (:func:`_setup_plugin`): the progress lines printed with the
    prefix "[solver N] " (:func:`flexsheet.runtime.console.show_lines` of the library's loggers; N the
    worker's name); one BLAS and OpenMP thread (the nanny starts workers with ``OMP_NUM_THREADS=1``; CHOLMOD's
    libraries load under that limit); SIGINT ignored and tied to its parent, dying with it even on ``kill -9``
    (:func:`flexsheet.runtime.background.lower_priority`, niceness unchanged)."""
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = "1"
    try:
        import sksparse.cholmod  # noqa: F401 - loads the BLAS/OpenMP CHOLMOD uses under the thread limit
    except ImportError:
        pass
    lower_priority(0, idle=False)
    name = os.getpid() if name is None else name
    name = name + 1 if isinstance(name, int) and name < 1000 else name       # a local cluster's are 0 .. n-1
    show_lines(LIBRARY, prefix=f"[solver {name}] ")


def _solve_one(args: tuple) -> tuple[int, float, str | None]:
    """Worker: one :func:`reference_path` (or :func:`stable_path`) into the cache; (job index, seconds, None
    or the error)."""
    i, job, mat, cache_dir, probes, contact = args
    t = time.perf_counter()
    try:
        solve = stable_path if job.stable else reference_path
        solve(job.spec, job.angle_deg, push_depths(job.step), mat, ArrayCache(cache_dir), probes, contact,
              job.penalty_scale)
    except Exception as exc:                    # noqa: BLE001 - reported; the run solves it again and raises
        return i, time.perf_counter() - t, f"{type(exc).__name__}: {exc}"
    return i, time.perf_counter() - t, None


def _setup_plugin():
    """A dask ``WorkerPlugin`` that runs :func:`_solver_init` on every worker (its ``name`` makes it one per
    cluster); built here so that importing this module does not import distributed."""
    from distributed import WorkerPlugin

    class _Setup(WorkerPlugin):
        name = "flexsheet-solver"

        def setup(self, worker) -> None:
            _solver_init(worker.name)

    return _Setup()


#: the dask scheduler every :func:`run_workers` uses ("tcp://HOST:PORT"), or None for
#: a local cluster; set once by a command's ``--scheduler`` (:func:`set_scheduler`)
SCHEDULER: str | None = None


def set_scheduler(address: str | None) -> None:
    """Run every later :func:`run_workers` on the dask cluster whose scheduler listens at ``address``
    ("tcp://HOST:PORT"; None: a local cluster). Raises ``ValueError`` naming a malformed address."""
    global SCHEDULER
    if address is not None:
        host, _, port = address.removeprefix("tcp://").rpartition(":")
        if not address.startswith("tcp://") or not host or not port.isdigit() or not 0 < int(port) < 65536:
            raise ValueError(f"--scheduler must be tcp://HOST:PORT, got {address!r}")
    SCHEDULER = address


def parallel(n: int) -> bool:
    """Whether work should go to :func:`run_workers`: more than one local worker, or a cluster set."""
    return n > 1 or SCHEDULER is not None


def run_workers(fn, work: list, n: int, scheduler: str | None = None, key=None):
    """Yield ``fn(w)`` for every ``w`` of ``work``, in the order they finish, computed on dask.distributed: a
    :class:`distributed.LocalCluster` of ``n`` worker processes, one thread each (the default), or the cluster
    whose scheduler listens at ``scheduler`` (default :data:`SCHEDULER`) ("tcp://HOST:8786", a lab's cluster:
    its workers need flexsheet installed and the same cache folder, a shared disk). Every local worker runs
    :func:`_solver_init` first (a lab's workers are not changed: no plugin is left on its scheduler). Logs
    "k/N done" as results arrive. ``key(w)`` names a task (default: its index), so a result the cluster still
    holds is not computed twice. Ctrl-C, an error or leaving the loop early cancels what is left and closes a
    local cluster at once. ``fn`` must be importable (module level) and catch its own errors. Raises
    ``ValueError`` for ``n`` < 1 and ``OSError`` when ``scheduler`` cannot be reached."""
    from distributed import Client, LocalCluster, as_completed

    if n < 1:
        raise ValueError(f"n (worker processes) must be >= 1, got {n}")
    scheduler = scheduler or SCHEDULER
    cluster = None
    if scheduler is None:
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                               silence_logs=50)
    try:
        client = Client(cluster if cluster is not None else scheduler, timeout=10)
    except (OSError, TimeoutError) as exc:
        if cluster is not None:
            cluster.close()
        raise OSError(f"cannot reach the dask scheduler at {scheduler!r}: {exc}") from exc
    import uuid

    run = uuid.uuid4().hex[:12]             # task keys unique per run: a shared scheduler holds others' too
    try:
        if cluster is not None:  # our own workers only; a lab's cluster's workers are left as they are
            client.register_plugin(_setup_plugin())
        futures = [client.submit(fn, w, pure=False, key=f"flexsheet-{run}-{key(w) if key else i}")
                   for i, w in enumerate(work)]
        for k, fut in enumerate(as_completed(futures), 1):
            result = fut.result()
            log.info(f"workers: {k}/{len(futures)} done")
            yield result
    finally:
        for fut in locals().get("futures", []):
            fut.cancel()
        client.close()
        if cluster is not None:
            cluster.close()


def default_jobs() -> int:
    """Worker processes for :func:`prefetch`: the cores this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
