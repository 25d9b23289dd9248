"""The renderer node's pushed-sheet tables (:class:`SheetTables`, a part of
:class:`nodes.renderer.node.RendererNode`): one gripped-sheet FEM table per sheet-strain node, loaded from
disk or built in a spawned, niced worker process (~2 min per node on one core), then the models' error table
once. Builds run one at a time in the node's background (:meth:`flexsheet.runtime.node.Node.background`: on
the wall clock pushes at that stretch are drawn with the 4-triangle model meanwhile; on a simulated clock
simulated time waits for them). A stretch whose table fails is drawn with the nearest built table (logged)."""

from __future__ import annotations

import multiprocessing
import threading
import time

from flexsheet.model.sheet_model import sheet_model_for
from flexsheet.rendering.state import ErrorTable, build_table, silhouette_probes
from flexsheet.runtime.background import start_worker

__all__ = ["SheetTables"]


class SheetTables:
    """The table-building half of the renderer node; it uses the node's ``sheet_model``, ``geometry``,
    ``sheet_config``, ``eye``, ``projector``, ``log``, ``errors_total`` and ``background``."""

    def _init_tables(self) -> None:
        self.table = None                     # the models' error table, once the first FEM table is there
        self._tables_asked: set[float] = set()
        self._missing: list[float] = []  # stretches a drawing found without a table (drained before a draw)
        self._builds: set = set()
        self._failed: set[float] = set()
        self._build_lock = threading.Lock()

    async def _prepare(self, node: float) -> None:
        """Have the pushed-sheet table of stretch ``node`` loaded or built, then the error table once (in the
        background: awaited on a simulated clock). A stretch outside the sheet's range (``SheetMaterial``
        min/max stretch, as the planner) is not built: such a push stays on the 4-triangle model."""
        if node in self._tables_asked or not self._in_range(node):
            return
        self._tables_asked.add(node)
        await self.background(self._load_table, f"renderer-sheet-table-{node:g}", float(node))

    def _want_table(self, node: float) -> None:
        """A drawing found no table for stretch ``node`` (thread-safe): prepared before the next draw."""
        if self._in_range(node) and node not in self._tables_asked and node not in self._missing:
            self._missing.append(float(node))

    async def _prepare_missing(self) -> None:
        """Prepare the tables the drawings found missing (before a draw)."""
        while self._missing:
            await self._prepare(self._missing.pop(0))

    def _in_range(self, node: float) -> bool:
        mat = self.sheet_model.material
        return mat.min_stretch - 1e-9 <= node <= mat.max_stretch + 1e-9

    def _load_table(self, node: float) -> None:
        """(A background thread, one build at a time.) Load the table of stretch ``node``, building it in a
        worker process (spawned, niced) if it is not on disk, then (once) the models' error table."""
        with self._build_lock:
            if not self.sheet_model.on_disk(node) and not self._build(node):
                return
            if self.table is None:
                try:
                    self.table = self._error_table(node)
                    self.log.info("model error table ready (stretch %g)", node)
                except (ValueError, ArithmeticError, OSError) as exc:
                    self.errors_total += 1
                    self.log.error("model error table at stretch %g failed: %s", node, exc)

    def _build(self, node: float) -> bool:
        """Build the table of stretch ``node`` in a worker process; False when it failed (logged, counted, the
        nearest built table stands in) or the node stopped."""
        self.log.info("pushed-sheet FEM table for stretch %g not cached: building it (~2 min); pushes at "
                      "that stretch are drawn with the 4-triangle model meanwhile", node)
        t0 = time.monotonic()
        proc = multiprocessing.get_context("spawn").Process(
            target=build_table, args=(self.sheet_model.settings, node, 19),
            name=f"renderer-sheet-table-{node:g}",
            daemon=True)
        start_worker(proc)                       # SIGINT ignored from its first instruction
        self._builds.add(proc)
        try:
            proc.join()
        finally:
            self._builds.discard(proc)
        if self.stopping:
            return False
        if proc.exitcode != 0 or not self.sheet_model.on_disk(node):
            self.errors_total += 1
            self._failed.add(node)
            self.log.error("pushed-sheet table for stretch %g failed (exit code %s; the FEM may not converge "
                           "at that stretch)", node, proc.exitcode)
            self._substitute()
            return False
        self.log.info("pushed-sheet table for stretch %g built in %.0f s", node, time.monotonic() - t0)
        self._substitute()
        return True

    def _stop_builds(self) -> None:
        """Terminate the running builds (a partial table is never cached)."""
        for proc in list(self._builds):
            proc.terminate()

    def _substitute(self) -> None:
        """Stand the nearest built table in for each stretch whose table failed (logged)."""
        for node in sorted(self._failed):
            sub = self.sheet_model.nearest_on_disk(node)
            if sub is not None and self.sheet_model.substitute.get(node) != sub:
                self.sheet_model.substitute[node] = sub
                self.log.warning("pushes at stretch %g are drawn with the table of stretch %g", node, sub)
                if self.table is None:
                    self._want_table(sub)

    def _error_table(self, node: float) -> ErrorTable:
        """The models' predicted errors on the home sheet at stretch ``node`` (its own model instance: the
        drawing thread's is not shared)."""
        geo = self.geometry
        return ErrorTable.at_home(silhouette_probes(geo.mesh[0], center_x=float(geo.scene.center[0])),
                                  eye=self.eye,
                                  projector=self.projector.position, stretch_node=node,
                                  config=self.sheet_config,
                                  sheet_model=sheet_model_for(self.sheet_config))

