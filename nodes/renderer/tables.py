"""The renderer node's pushed-sheet tables (:class:`SheetTables`, a part of
:class:`nodes.renderer.node.RendererNode`): one gripped-sheet FEM table per sheet-strain node, loaded from disk or
built in a spawned, niced worker process (~2 min per node on one core), then the models' error table once. On
the wall clock the builds run one at a time while pushes at that stretch are drawn with the 4-triangle model;
on a simulated clock they are awaited while simulated time waits. A stretch whose table fails is drawn with
the nearest built table (logged)."""

from __future__ import annotations

import asyncio
import multiprocessing
import time

from flexsheet.model.sheet_model import sheet_model_for
from flexsheet.rendering.state import ErrorTable, build_table, silhouette_probes
from flexsheet.runtime.background import await_worker, start_worker

__all__ = ["SheetTables"]


class SheetTables:
    """The table-building half of the renderer node; it uses the node's ``sheet_model``, ``geometry``,
    ``sheet_config``, ``eye``, ``projector``, ``log``, ``errors_total``, ``stopping`` and ``_request``."""

    async def _sim_table(self, node: float) -> None:
        """Load or build (in a spawned worker process, awaited: the loop stays free for heartbeats and signals)
        the pushed-sheet table of stretch ``node``, then the error table once: on a simulated clock, before
        simulated time goes on (the lockstep scheduler awaits the handler). A stop terminates the build."""
        if node in self._tables_asked:
            return
        self._tables_asked.add(node)
        if not self.sheet_model.on_disk(node):
            self.log.info("pushed-sheet FEM table for stretch %g not cached: building it (~2 min) while simulated "
                          "time waits", node)
            proc = multiprocessing.get_context("spawn").Process(
                target=build_table, args=(self.sheet_model.settings, node, 19), name=f"renderer-sheet-table-{node:g}",
                daemon=True)
            start_worker(proc)
            if not await await_worker(proc, lambda: self.stopping):
                return
            if proc.exitcode != 0 or not self.sheet_model.on_disk(node):
                self.errors_total += 1
                self._failed.add(node)
                self.log.error("pushed-sheet table for stretch %g failed (exit code %s)", node, proc.exitcode)
                self._substitute()
                return
        if self.table is None:
            try:
                self.table = self._error_table(node)
            except (ValueError, ArithmeticError, OSError) as exc:
                self.errors_total += 1
                self.log.error("model error table at stretch %g failed: %s", node, exc)

    def _want_table(self, node: float) -> None:
        """Ask for the pushed-sheet table of stretch ``node`` (thread-safe; from the drawing thread too). A
        stretch outside the sheet's range (``SheetMaterial`` min/max stretch, as the planner) is not built: such
        a push stays on the 4-triangle model."""
        if not self._in_range(node):
            return
        if self.sim:   # drawn meanwhile with what there is; the next render tick builds it, simulated time waiting
            if node not in self._tables_asked and node not in self._sim_missing:
                self._sim_missing.append(float(node))
        else:
            self._loop.call_soon_threadsafe(self._queue_table, float(node))

    async def _sim_tick(self) -> None:
        """Simulated clock: build the tables a drawing found missing (awaited), then redraw if wanted."""
        while self._sim_missing:
            await self._sim_table(self._sim_missing.pop(0))
        self._sim_render()

    def _in_range(self, node: float) -> bool:
        mat = self.sheet_model.material
        return mat.min_stretch - 1e-9 <= node <= mat.max_stretch + 1e-9

    def _queue_table(self, node: float) -> None:
        if node not in self._tables_asked:
            self._tables_asked.add(node)
            self._tables_wanted.append(node)
            self._tables_event.set()

    async def _build_tables(self) -> None:
        """One table at a time: load it if it is on disk, else build it in a worker process (spawned, niced),
        then (once) the models' error table at that stretch."""
        loop = asyncio.get_running_loop()
        ctx = multiprocessing.get_context("spawn")
        while True:
            await self._tables_event.wait()
            self._tables_event.clear()
            while self._tables_wanted:
                node = self._tables_wanted.pop(0)
                if not self.sheet_model.on_disk(node):
                    self.log.info("pushed-sheet FEM table for stretch %g not cached: building it (~2 min); pushes "
                                  "at that stretch are drawn with the 4-triangle model meanwhile", node)
                    t0 = time.monotonic()
                    proc = ctx.Process(target=build_table, args=(self.sheet_model.settings, node, 19),
                                       name=f"renderer-sheet-table-{node:g}", daemon=True)
                    start_worker(proc)             # SIGINT ignored from its first instruction
                    self._builds.add(proc)
                    try:
                        await loop.run_in_executor(None, proc.join)
                    finally:
                        self._builds.discard(proc)
                    if proc.exitcode != 0 or not self.sheet_model.on_disk(node):
                        self.errors_total += 1
                        self._failed.add(node)
                        self.log.error("pushed-sheet table for stretch %g failed (exit code %s; the FEM may not "
                                       "converge at that stretch)", node, proc.exitcode)
                        self._substitute()
                        continue
                    self.log.info("pushed-sheet table for stretch %g built in %.0f s", node, time.monotonic() - t0)
                    self._substitute()
                if self.table is None:
                    try:
                        self.table = await loop.run_in_executor(None, self._error_table, node)
                        self.log.info("model error table ready (stretch %g)", node)
                    except (ValueError, ArithmeticError, OSError) as exc:
                        self.errors_total += 1
                        self.log.error("model error table at stretch %g failed: %s", node, exc)
                self._request()

    def _substitute(self) -> None:
        """Stand the nearest built table in for each stretch whose table failed (logged)."""
        for node in sorted(self._failed):
            sub = self.sheet_model.nearest_on_disk(node)
            if sub is not None and self.sheet_model.substitute.get(node) != sub:
                self.sheet_model.substitute[node] = sub
                self.log.warning("pushes at stretch %g are drawn with the table of stretch %g", node, sub)
                if self.table is None:
                    self._queue_table(sub)

    def _error_table(self, node: float) -> ErrorTable:
        """The models' predicted errors on the home sheet at stretch ``node`` (its own model instance: the
        drawing thread's is not shared)."""
        geo = self.geometry
        return ErrorTable.at_home(silhouette_probes(geo.mesh[0], center_x=float(geo.scene.center[0])), eye=self.eye,
                                  projector=self.projector.position, stretch_node=node, config=self.sheet_config,
                                  sheet_model=sheet_model_for(self.sheet_config))

