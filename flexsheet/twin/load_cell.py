"""A probe on a load cell pressed into the twin's true sheet: what ``flexsheet calibrate sheet`` reads in the twin.

The probe is a rigid sphere of the fingertip's radius on a stage that moves along the sheet's normal; the true
force is the world's own true-sheet table (:class:`flexsheet.twin.world.TruePhysics`: the sheet FEM of the
truth at that clamp strain, the same force ``/world/contact`` publishes), so the model identified here is judged
on the sheet the runs press. The reading adds the stage's depth error (σ 20 µm, a micrometre stage; assumption)
and the load cell's noise (σ = 5 mN + 0.5 % of the reading: a 10 N S-beam cell; assumption), drawn from the
probe's own seed. Tables missing from the cache are built first, two at a time (~40 s each).

Units: m, N.
"""

from __future__ import annotations

import logging

import numpy as np

from flexsheet.calibration.sheet import NOISE_N, NOISE_REL, Press
from flexsheet.model import geometry
from flexsheet.twin.truth import TwinTruth
from flexsheet.twin.world import TruePhysics, build_table
from flexsheet.twin.world_config import SheetFemConfig

log = logging.getLogger(__name__)

__all__ = ["LoadCellTwin", "DEPTH_SIGMA"]

#: the stage's depth error, m (σ)
DEPTH_SIGMA = 2e-5


class LoadCellTwin:
    """Presses on the true sheet of ``truth`` (a :class:`TwinTruth`); ``seed`` draws the noise; ``config``: the
    world's true-sheet tables (default :class:`SheetFemConfig`)."""

    def __init__(self, truth: TwinTruth, seed: int = 0, config: SheetFemConfig | None = None) -> None:
        self.truth = truth
        self.phys = TruePhysics(truth, config or SheetFemConfig())
        self.rng = np.random.default_rng([int(seed), 5150])

    def prepare(self, stretches) -> None:
        """Load (or build, two at a time) the true tables at ``stretches``' nodes."""
        from concurrent.futures import ProcessPoolExecutor

        nodes = sorted({self.phys.node_of(s) for s in stretches})
        missing = [n for n in nodes if not self.phys.try_load(n)]
        if missing:
            log.info(f"sheet: building the true sheet's tables at clamp strain {missing} (~40 s each, two at a time)")
            t = self.truth
            with ProcessPoolExecutor(max_workers=min(2, len(missing))) as ex:
                list(ex.map(build_table, [t.seed] * len(missing), [t.realism] * len(missing), missing,
                            [geometry.SHEET_SIZE] * len(missing), [self.phys.config] * len(missing)))
            for n in missing:
                if not self.phys.try_load(n):
                    raise RuntimeError(f"the true sheet's table at clamp strain {n} was not built")

    def true_force(self, stretch: float, u: float, v: float, depth: float) -> float:
        """The true force (N) at ``depth`` m, contact (u, v) m, clamp strain ``stretch`` (its table node)."""
        node = self.phys.node_of(stretch)
        if not self.phys.try_load(node):
            self.prepare([stretch])
        return float(self.phys.tables[node].shape(max(depth, 0.0), u, v).force)

    def press(self, stretch: float, u: float, v: float, depths) -> list[Press]:
        """One press: a reading per depth (the depth the stage reports, the force the cell reads)."""
        out = []
        for d in depths:
            true_d = float(d) + DEPTH_SIGMA * self.rng.normal()
            f = self.true_force(stretch, u, v, true_d)
            f += (NOISE_N + NOISE_REL * f) * self.rng.normal()
            out.append(Press(float(stretch), float(u), float(v), float(d), max(f, 0.0)))
        return out
