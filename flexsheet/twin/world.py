"""The world twin's physics of the display, from the hidden truth only (pure; no transport).

* **Clamps**: the true clamp pose of each arm is the *true* forward kinematics of its measured joints —
  the truth's base pose, link lengths and joint zero offsets (:meth:`flexsheet.twin.truth.TwinTruth.clamp_pose`)
  — not the bridge's model (nominal URDF at the calibrated base), whose FK the bridge publishes in
  ``ArmJointState.pose``. Under the ideal truth the two agree exactly.
* **Sheet**: the pushed sheet's shape is the nonlinear membrane FEM of :mod:`flexsheet.model.sheet_fem` with
  the truth's Young's modulus, pre-strain and tension ratio, held at the measured clamp span. Its tables are
  solved per clamp-strain node (``stretch_step`` apart; the force is interpolated between the two nodes around
  the actual span, the shape is the nearer node's, mapped onto the span) and cached on disk; :meth:`TruePhysics.missing_node` names the node still to be built, which
  the node builds in a worker process (:func:`build_table`) so that the world's timers never wait on it.

Units: m, rad; frames: display (clamps), the sheet's own (u, v) for the deflection.
"""

from __future__ import annotations

import math
import os
from dataclasses import replace

import numpy as np

from flexsheet.manifest import record
from flexsheet.model import geometry
from flexsheet.model.sheet import SheetSurface, frame_from_clamps
from flexsheet.model.sheet_fem import FINGER_RADIUS, SheetPhysics
from flexsheet.model.sheet_table import FemShape, IndentTable
from flexsheet.twin.truth import TwinTruth
from flexsheet.twin.world_config import SheetFemConfig

__all__ = ["TruePhysics", "build_table"]


def build_table(truth_seed: int, realism: str, stretch: float, size: float, config: SheetFemConfig) -> str:
    """Build (or find) the cached FEM table of the truth (``truth_seed``, ``realism``) at clamp strain
    ``stretch`` over the unstretched side ``size`` m; returns its cache key. Runs in a worker process: it
    redraws the truth from the seed (nothing but the seed crosses the process boundary)."""
    truth = TwinTruth.draw(int(truth_seed), realism)
    phys = SheetPhysics.from_truth(truth, stretch, size)
    tab = IndentTable(phys, config.depths, config.positions, mesh=config.mesh(), cache_dir=config.tables_dir())
    return tab.key


class TruePhysics:
    """True clamps and true sheet of one :class:`TwinTruth` (module doc).

    ``size`` m: the unstretched sheet side between the clamps; ``half_width`` m: half the sheet's width.
    """

    def __init__(self, truth: TwinTruth, config: SheetFemConfig | None = None, size: float = geometry.SHEET_SIZE,
                 half_width: float = geometry.SHEET_SIZE / 2) -> None:
        self.truth = truth
        self.config = config or SheetFemConfig()
        if not (self.config.stretch_step > 0.0 and math.isfinite(self.config.stretch_step)):
            raise ValueError(f"stretch_step must be > 0, got {self.config.stretch_step!r}")
        self.size = float(size)
        self.half_width = float(half_width)
        self.tables: dict[float, IndentTable] = {}

    # ------------------------------------------------------------------------------------------- clamps
    def clamp_pose(self, side: str, q) -> np.ndarray:
        """True T_display_clamp (4, 4) of arm ``side`` at the measured joints ``q`` (6,) rad."""
        return self.truth.clamp_pose(side, q)

    # -------------------------------------------------------------------------------------------- sheet
    def node_of(self, stretch: float) -> float:
        """The table node (clamp strain) nearest ``stretch``, rounded to the step, ≥ 0."""
        st = self.config.stretch_step
        return round(max(0.0, round(stretch / st) * st), 6)

    def physics(self, node: float) -> SheetPhysics:
        """The true sheet physics at table node ``node`` (clamp strain)."""
        return SheetPhysics.from_truth(self.truth, node, self.size, half_width=self.half_width)

    def try_load(self, node: float) -> bool:
        """Load node ``node``'s table if it is cached (never builds); returns whether it is available."""
        if node in self.tables:
            return True
        tab = _cached_table(self.physics(node), self.config)
        if tab is not None:
            self.tables[node] = tab
        return tab is not None

    def bracket(self, stretch: float) -> tuple[float, float, float]:
        """(lower node, upper node, weight of the upper) around ``stretch``: the table nodes either side of it
        (``stretch_step`` apart; a slack sheet, below 0, takes node 0 alone: weight 0)."""
        st = self.config.stretch_step
        x = max(0.0, stretch) / st
        k = math.floor(x)
        return round(k * st, 6), round((k + 1) * st, 6), x - k

    def missing_node(self, stretch: float) -> float | None:
        """The node ``stretch`` wants when its table is neither loaded nor cached, else ``None``: the nearest
        node first, then the other one around it (the force is interpolated between the two)."""
        node = self.node_of(stretch)
        if not self.try_load(node):
            return node
        lo, hi, w = self.bracket(stretch)
        other = hi if node == lo else lo
        if w > 1e-9 and not self.try_load(other):
            return other
        return None

    def shape(self, depth: float, push_u: float, push_v: float, half_span: float) -> FemShape | None:
        """The true pushed shape at the measured span ``half_span`` (m), or ``None`` while no table is loaded.
        Its force and stiffness are interpolated linearly in clamp strain between the two table nodes around
        the span (the nearest loaded node's alone while the other is not loaded), so the true force does not
        step between tables; the deflection is the nearer node's. Raises ``ValueError`` for a contact outside
        the sheet."""
        if not self.tables:
            return None
        stretch = 2.0 * half_span / self.size - 1.0
        lo, hi, w = self.bracket(stretch)
        if lo in self.tables and hi in self.tables and w > 1e-9:
            a = self.tables[lo].shape(depth, push_u, push_v, half_span)
            b = self.tables[hi].shape(depth, push_u, push_v, half_span)
            return replace(a if w < 0.5 else b, force=(1.0 - w) * a.force + w * b.force,
                           stiffness=(1.0 - w) * a.stiffness + w * b.stiffness)
        node = min(self.tables, key=lambda n: abs(n - stretch))
        return self.tables[node].shape(depth, push_u, push_v, half_span)

    def surface(self, T_left: np.ndarray, T_right: np.ndarray, finger: np.ndarray | None
                ) -> tuple[SheetSurface, float]:
        """The true sheet held by the true clamp poses (4, 4), pushed by the fingertip ``finger`` (3,) m when
        it is behind the sheet plane and inside it. Returns (surface, clamp strain, signed: negative when slack). The surface's
        ``membrane`` is a :class:`FemShape` (or ``None``: flat, or no table yet). Raises ``ValueError`` for
        clamps that hold no sheet (see :func:`flexsheet.model.sheet.frame_from_clamps`)."""
        origin, n, eu, a = frame_from_clamps(T_left, T_right)
        stretch = 2.0 * a / self.size - 1.0
        mem = None
        if finger is not None:
            d = np.asarray(finger, float) - origin
            depth = -float(d @ n)
            pu, pv = float(d @ eu), float(d @ np.cross(n, eu))
            if depth > 0.0 and abs(pu) < a - FINGER_RADIUS and abs(pv) <= self.half_width:
                mem = self.shape(depth, pu, pv, a)
        return SheetSurface(origin, n, eu, a, self.half_width, mem, self.size), stretch


#: the true sheet's tables shipped for the default twin (realistic, truth seed 0) at the clamp strains a
#: default run reaches, so a fresh machine's simulated run does not wait for them (≈ 30–80 s each); searched
#: after the cache. Regenerate: ``python -m flexsheet.twin.world --ship``.
SHIPPED_TRUTH_TABLES = os.path.join(os.path.dirname(os.path.abspath(__file__)), "sheet_tables")
#: (realism, truth seed, clamp strains) shipped
SHIPPED_TRUTHS = (("realistic", 0, tuple(round(0.01 * k, 6) for k in range(0, 13))),)


def _cached_table(phys: SheetPhysics, cfg: SheetFemConfig) -> IndentTable | None:
    """The cached (or shipped) table of ``phys`` or ``None`` (nothing is built)."""
    for folder in (cfg.tables_dir(), SHIPPED_TRUTH_TABLES):
        tab = IndentTable.cached(phys, cfg.depths, cfg.positions, mesh=cfg.mesh(), cache_dir=folder)
        if tab is not None:
            return tab
    return None


def ship(size: float = geometry.SHEET_SIZE) -> list[str]:
    """Build (or take from the cache) the tables of :data:`SHIPPED_TRUTHS` and copy them into
    :data:`SHIPPED_TRUTH_TABLES`, entered in its manifest. Returns the paths."""
    import shutil

    os.makedirs(SHIPPED_TRUTH_TABLES, exist_ok=True)
    out = []
    for realism, seed, nodes in SHIPPED_TRUTHS:
        cfg = SheetFemConfig()
        phys = TruePhysics(TwinTruth.draw(seed, realism), cfg, size=size)
        for node in nodes:
            build_table(seed, realism, node, size, cfg)
            key = IndentTable.key_of(phys.physics(node), cfg.depths, cfg.positions, cfg.mesh())
            src = os.path.join(cfg.tables_dir(), f"indent_{key}.npz")
            dst = os.path.join(SHIPPED_TRUTH_TABLES, os.path.basename(src))
            if os.path.abspath(src) != os.path.abspath(dst):
                shutil.copyfile(src, dst)
            record(dst, "python -m flexsheet.twin.world --ship")
            out.append(dst)
    return out


if __name__ == "__main__":
    import sys

    if sys.argv[1:] == ["--ship"]:
        for path in ship():
            print(path)
    else:
        print("usage: python -m flexsheet.twin.world --ship", file=sys.stderr)
        sys.exit(2)
