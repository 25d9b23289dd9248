"""The world twin's physics (flexsheet/twin/world.py): the pushed sheet it makes of the true clamps is the
truth's sheet (:class:`flexsheet.twin.truth_sheet.TruthSheet`) at the measured span, and a sheet of another
size than the table family's is refused."""

from __future__ import annotations

import numpy as np
import pytest

from flexsheet.model.sheet import clamp_poses
from flexsheet.model.sheet_table import FemShape
from flexsheet.twin.truth import TwinTruth
from flexsheet.twin.world import TruePhysics


def _surface(phys: TruePhysics, stretch: float, finger):
    Tl, Tr = clamp_poses(np.zeros(3), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]), stretch)
    return phys.surface(Tl, Tr, None if finger is None else np.asarray(finger, float))


@pytest.mark.parametrize("seed", [2, 5821])
def test_the_pushed_sheet_is_the_truths_sheet_at_the_measured_span(seed):
    truth = TwinTruth.draw(seed, "realistic")
    phys = TruePhysics(truth)
    finger = [-0.012, 0.01, -0.02]                                  # 12 mm behind the sheet
    surf, stretch = _surface(phys, 0.043, finger)
    assert stretch == pytest.approx(0.043, abs=1e-12)
    mem = surf.membrane
    assert isinstance(mem, FemShape) and mem.depth == pytest.approx(0.012)
    assert mem.force == pytest.approx(phys.sheet.force(0.012, mem.push_u, mem.push_v, 0.043), rel=1e-12)
    assert 0.3 < mem.force < 3.0 and mem.stiffness > mem.force / 0.012      # N; stiffening with depth
    assert surf.pushed_point == pytest.approx(finger, abs=1e-12)
    assert mem.deflection(mem.push_u, mem.push_v) == pytest.approx(0.012, rel=0.05)
    ideal = TruePhysics(TwinTruth.draw(seed, "ideal"))
    f_ideal = _surface(ideal, 0.043, finger)[0].membrane.force
    assert abs(mem.force / f_ideal - 1.0) > 0.005                     # the drawn sheet is not the nominal one
    flat, _ = _surface(phys, 0.043, [0.01, 0.0, 0.0])                 # in front of the sheet: not pushed
    assert flat.membrane is None


def test_a_sheet_of_another_size_than_the_family_is_refused():
    with pytest.raises(ValueError, match="0.24 m sheet"):
        TruePhysics(TwinTruth.draw(0, "ideal"), size=0.30)
