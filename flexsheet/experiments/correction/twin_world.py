"""The twin side (truth only): :class:`TwinWorld`, the hidden truth's display, for the measurement only."""

from __future__ import annotations

import numpy as np

from flexsheet.experiments.correction.settings import FEM_DEPTHS, FEM_POSITIONS, STRETCH
from flexsheet.model import geometry
from flexsheet.model.projector import Projector
from flexsheet.model.sheet import SheetSurface, frame_from_clamps
from flexsheet.model.sheet_fem import SheetPhysics
from flexsheet.model.sheet_table import IndentTable, default_cache_dir
from flexsheet.twin.truth import TwinTruth


class TwinWorld:
    """The hidden truth's display, for the measurement only: the true projector (K, distortion, pose), the
    true clamp poses of commanded joints, the true sheet (flat, or pushed: the FEM table of
    :class:`flexsheet.model.sheet_table.IndentTable` with the truth's material, cached in ``cache_dir``)."""

    def __init__(self, truth: TwinTruth, *, cache_dir: str | None = None, fem_mesh: dict | None = None,
                 depths=FEM_DEPTHS, positions=FEM_POSITIONS, stretch: float = STRETCH) -> None:
        self.truth = truth
        T = np.asarray(truth.T_display_projector, float)
        w, h = truth.projector_size
        self.projector = Projector(np.asarray(truth.projector_K, float), T[:3, :3].copy(), T[:3, 3].copy(),
                                   int(w), int(h))
        self.distortion = np.asarray(truth.projector_D, float).ravel().copy()
        self.cache_dir = cache_dir or default_cache_dir()
        self.fem_mesh = dict(fem_mesh or {})
        self.depths, self.positions, self.stretch = tuple(depths), tuple(positions), float(stretch)
        self._table = None

    def table(self):
        """The true sheet's FEM table at the commanded stretch (built once, ~3 s per table, cached on
        disk)."""
        if self._table is None:
            self._table = IndentTable(SheetPhysics.from_truth(self.truth, self.stretch), self.depths,
                                      self.positions,
                                      mesh=self.fem_mesh, cache_dir=self.cache_dir)
        return self._table

    def clamps(self, q: dict) -> tuple[np.ndarray, np.ndarray]:
        """True clamp poses (left, right) (4, 4) of the commanded joints."""
        return self.truth.clamp_pose("left", q["left"]), self.truth.clamp_pose("right", q["right"])

    def sheet(self, q: dict, finger=None) -> tuple[SheetSurface, dict]:
        """The true sheet held by the true clamps, pushed by the finger at ``finger`` (3,) m when it is behind
        the true sheet plane; returns (surface, info: true depth and contact, m)."""
        origin, n, eu, a = frame_from_clamps(*self.clamps(q))
        b = geometry.SHEET_SIZE / 2
        info = {"origin": origin, "normal": n}
        mem = None
        if finger is not None:
            d = np.asarray(finger, float) - origin
            depth = -float(d @ n)
            pu, pv = float(d @ eu), float(d @ np.cross(n, eu))
            info.update(depth=depth, push_u=pu, push_v=pv)
            if depth > 0.0:
                mem = self.table().shape(depth, pu, pv, a)
        return SheetSurface(origin, n, eu, a, b, mem), info
