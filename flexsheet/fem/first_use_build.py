"""The build of a scene's first-use table (:mod:`flexsheet.fem.first_use`): :func:`build_first_use_table` (in
this process), and :class:`FirstUseBuild`, which runs it in a spawned process
(:func:`flexsheet.runtime.background.lower_priority`: ``SCHED_IDLE``, nice 19, one BLAS thread; it dies with
its owner) and watches it from a thread of the owner: a line per station (progress), then the table loaded
from the cache, or the error. It never raises into the owner's thread and never takes the owner's locks.
"""

from __future__ import annotations

import multiprocessing
import queue
import threading
import time
from collections.abc import Callable

import numpy as np

from flexsheet.fem import first_use
from flexsheet.fem.cache import ArrayCache
from flexsheet.fem.first_use import (
    FirstUseSpec,
    first_use_key,
    first_use_settings,
    load_first_use_table,
)
from flexsheet.fem.mesh import MeshSpec
from flexsheet.fem.reference.path_table import assemble_path_table
from flexsheet.fem.reference.scene_reference import scene_reference
from flexsheet.fem.scene_model import SceneModel
from flexsheet.model.scenes import load_scene
from flexsheet.runtime.background import lower_priority, start_worker

__all__ = ["build_first_use_table", "FirstUseBuild"]


def build_first_use_table(scene_file: str, mesh: tuple, order: int, cache_dir: str,
                          spec: FirstUseSpec | None = None,
                          progress: Callable[[str], None] | None = None) -> str:
    """Build the first-use table of the scene in ``scene_file`` for its real-time model (mesh sizes ``mesh``
    = (h, h_fine, refine_radius) m, element ``order``, as the FEM node built it) and save it in
    ``cache_dir`` (``spec`` None: :data:`~flexsheet.fem.first_use.FIRST_USE`); returns one line (stations,
    depth, seconds). ``progress`` takes a line per station.
    Raises ``ValueError`` when no station converged at the first depth (or for a bad scene)."""
    t0 = time.perf_counter()
    spec = spec or first_use.FIRST_USE
    sc = load_scene(scene_file)
    rt = SceneModel(sc, MeshSpec(*mesh), order, cache_dir=cache_dir)
    cache = ArrayCache(cache_dir)
    st = first_use_settings(sc, spec)
    probes = rt.rest_vertices.astype(float)
    fractions = np.linspace(0.0, 1.0, int(spec.stations))
    refs = []
    for i, f in enumerate(fractions):
        q, n = sc.stroke_at([float(f)])
        t = time.perf_counter()
        refs.append(scene_reference(sc, q[0], n[0], spec.h_fine, st, probes, cache))
        ok = int(np.sum(np.asarray(refs[-1]["converged"], bool)))
        if progress is not None:
            progress(f"station {i + 1}/{len(fractions)} (fraction {f:.2f}) in {time.perf_counter() - t:.0f} "
                     f"s: {ok}/{len(st['depths'])} depths converged, "
                     f"{float(np.asarray(refs[-1]['force'])[-1]):.2f} N at {st['depths'][-1] * 1e3:.1f} mm")
    table = assemble_path_table(sc, rt, fractions, refs)
    cache.save("pathsnap", first_use_key(sc, rt, spec), table)
    return (f"{len(fractions)} stations, depth <= {float(table['depths'][-1]) * 1e3:.1f} mm, reference "
            f"h_fine {spec.h_fine * 1e3:g} mm, built in {time.perf_counter() - t0:.0f} s")


def _worker(args: tuple, idle: bool, out) -> None:
    """The spawned process: :func:`build_first_use_table` at low priority (``idle``: ``SCHED_IDLE`` too); its
    lines on queue ``out``."""
    how = lower_priority(19, idle)
    out.put(("progress", f"worker pid {multiprocessing.current_process().pid} ({how})"))
    try:
        line = build_first_use_table(*args, progress=lambda s: out.put(("progress", s)))
    except Exception as exc:  # noqa: BLE001 - reported to the owner, which keeps serving linear
        out.put(("error", f"{type(exc).__name__}: {exc}"))
        raise SystemExit(1) from None
    out.put(("done", line))


class FirstUseBuild:
    """Build scene ``rt.scene``'s first-use table (from ``scene_file``, for the real-time model ``rt``) into
    ``cache_dir`` in a spawned worker at idle priority, watched from a daemon thread (module doc).

    Callbacks, called from that thread: ``on_progress(line)`` per step; ``on_done(table, line)`` with the
    table loaded from the cache; ``on_error(line)`` when the build failed or the worker died (never when
    :meth:`stop` ended it). ``status`` is the last line. ``idle`` False: nice 19 without ``SCHED_IDLE`` (the
    tests: beside their own workers an idle-class build may wait minutes). Raises ``ValueError`` without a
    ``cache_dir``, nothing after construction."""

    def __init__(self, rt, scene_file: str, cache_dir: str, on_progress: Callable[[str], None],
                 on_done: Callable[[dict, str], None], on_error: Callable[[str], None],
                 spec: FirstUseSpec | None = None, idle: bool = True):
        if not cache_dir:
            raise ValueError("a first-use table needs a disk cache (cache_dir)")
        self.rt, self.spec, self.cache_dir = rt, spec or first_use.FIRST_USE, cache_dir
        s = rt.spec
        self._args = (str(scene_file), (s.h, s.h_fine, s.refine_radius), int(rt.order), cache_dir, self.spec)
        self.on_progress, self.on_done, self.on_error = on_progress, on_done, on_error
        self.idle = idle
        self.status = "not started"
        self.proc = None
        self._stopped = False
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        """Spawn the worker and its watcher (returns at once)."""
        ctx = multiprocessing.get_context("spawn")
        self._queue = ctx.Queue()
        self.proc = ctx.Process(target=_worker, args=(self._args, self.idle, self._queue),
                                name="fem-first-use-table",
                                daemon=True)
        self._t0 = time.monotonic()
        start_worker(self.proc)
        self._thread = threading.Thread(target=self._watch, name="fem-first-use-watch", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """End the worker (a partial table is never cached; its finished pushes are)."""
        self._stopped = True
        if self.proc is not None and self.proc.is_alive():
            self.proc.terminate()

    def join(self, timeout: float | None = None) -> None:
        """Wait for the watcher (tests)."""
        if self._thread is not None:
            self._thread.join(timeout)

    def _say(self, what: str, line: str) -> None:
        self.status = line
        if not self._stopped:
            {"progress": self.on_progress, "error": self.on_error}[what](line)

    def _watch(self) -> None:
        """Relay the worker's lines until it ends, then load and hand over the table (or the error)."""
        done, error = None, None
        while True:
            try:
                what, line = self._queue.get(timeout=0.5)
            except queue.Empty:
                if self.proc.is_alive():
                    continue
                break
            if what == "done":
                done = line
            elif what == "error":
                error = line
            else:
                self._say("progress", line)
        if self._stopped:
            return
        try:
            self._finish(done, error)
        except Exception as exc:  # noqa: BLE001 - the owner keeps serving linear
            self._say("error", f"first-use table unusable: {type(exc).__name__}: {exc}")

    def _finish(self, done: str | None, error: str | None) -> None:
        """Hand the cached table to ``on_done``, or say why there is none."""
        self.proc.join(5.0)
        if done is None:
            why = error or f"the worker exited with code {self.proc.exitcode}"
            self._say("error", f"first-use table build failed after {time.monotonic() - self._t0:.0f} s: "
                               f"{why}")
            return
        table = load_first_use_table(self.rt, ArrayCache(self.cache_dir), self.spec)
        if table is None:
            raise ValueError("the worker finished but its table is not in the cache")
        self.status = f"first-use table ready ({done}; {time.monotonic() - self._t0:.0f} s since start)"
        self.on_done(table, self.status)
