"""A probe on a load cell pressed into the twin's true sheet: what ``flexsheet calibrate sheet`` reads in the
twin.

The probe is a rigid sphere of the fingertip's radius on a stage that moves along the sheet's normal; the true
force is the world's own true sheet (:class:`flexsheet.twin.truth_sheet.TruthSheet` of the truth, at the
press's clamp strain: the same force ``/world/contact`` publishes), so the model identified here is judged on
the sheet the runs press; nothing is built. The reading adds the stage's depth error (σ 20 µm, a micrometre
stage; assumption) and the load cell's noise (σ = 5 mN + 0.5 % of the reading: a 10 N S-beam cell;
assumption), drawn from the probe's own seed.

Units: m, N.
"""

from __future__ import annotations

import numpy as np

from flexsheet.calibration.sheet import NOISE_N, NOISE_REL, Press
from flexsheet.twin.truth import TwinTruth
from flexsheet.twin.truth_sheet import FAMILY_DIR, TruthSheet

__all__ = ["LoadCellTwin", "DEPTH_SIGMA"]

#: the stage's depth error, m (σ)
DEPTH_SIGMA = 2e-5


class LoadCellTwin:
    """Presses on the true sheet of ``truth`` (a :class:`TwinTruth`); ``seed`` draws the noise; ``folder``:
    the true sheet's table family (default the shipped one). Raises ``FileNotFoundError`` when it lacks
    tables."""

    def __init__(self, truth: TwinTruth, seed: int = 0, folder: str = FAMILY_DIR) -> None:
        self.truth = truth
        self.sheet = TruthSheet.of(truth, folder)
        self.rng = np.random.default_rng([int(seed), 5150])

    def true_force(self, stretch: float, u: float, v: float, depth: float) -> float:
        """The true force (N) at ``depth`` m, contact (u, v) m, clamp strain ``stretch``."""
        return self.sheet.force(max(depth, 0.0), u, v, stretch)

    def press(self, stretch: float, u: float, v: float, depths) -> list[Press]:
        """One press: a reading per depth (the depth the stage reports, the force the cell reads)."""
        out = []
        for d in depths:
            true_d = float(d) + DEPTH_SIGMA * self.rng.normal()
            f = self.true_force(stretch, u, v, true_d)
            f += (NOISE_N + NOISE_REL * f) * self.rng.normal()
            out.append(Press(float(stretch), float(u), float(v), float(d), max(f, 0.0)))
        return out
