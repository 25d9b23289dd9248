"""The projector model (flexsheet.model.projector): a calibrated projector overrides the default and refuses a
reflection."""

import numpy as np
import pytest

from flexsheet.model.projector import Projector


def test_calibrated_projector_overrides_and_refuses_a_reflection():
    d = Projector.default(320, 240)
    K = d.K.copy()
    K[0, 2] += 5.0
    p = Projector.calibrated(320, 240, K=K.tolist())
    np.testing.assert_array_equal(p.K, K)
    np.testing.assert_array_equal(p.R, d.R)
    np.testing.assert_array_equal(Projector.calibrated(320, 240).K, d.K)
    flipped = d.R @ np.diag([-1.0, 1.0, 1.0])
    with pytest.raises(ValueError, match="mirror_x"):
        Projector.calibrated(320, 240, R=flipped)
    with pytest.raises(ValueError, match="K must be a finite 3x3"):
        Projector.calibrated(320, 240, K=[[1.0, 0.0], [0.0, 1.0]])
