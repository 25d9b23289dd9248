"""Eye tracking (flexsheet.calibration.eye): the glasses' pose from their markers, the eyes follow them."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flexsheet.calibration.eye import glasses_eye_offset, glasses_pose
from flexsheet.model import geometry
from flexsheet.vision.glasses import tracked_eyes


def test_tracked_eyes_follow_the_glasses():
    rng = np.random.default_rng(3)
    model = np.array([[0.07, 0.0, 0.0], [-0.07, 0.0, 0.0], [0.0, 0.03, 0.01], [0.02, -0.01, 0.02]])
    R = np.column_stack([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])      # glasses x = display +y
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = geometry.EYE + np.array([0.0, 0.0, 0.03])
    seen = model @ R.T + T[:3, 3] + rng.normal(0, 2e-5, model.shape)
    T_est = glasses_pose(seen, model)
    assert np.linalg.norm(T_est[:3, 3] - T[:3, 3]) < 1e-4
    off = glasses_eye_offset(T, geometry.EYE)
    assert np.allclose(off, [0.0, -0.03, 0.0], atol=1e-12)
    # the head turns 20 deg about z and moves 5 cm to the side: the eyes go with it
    turn = np.array([[math.cos(0.35), -math.sin(0.35), 0], [math.sin(0.35), math.cos(0.35), 0], [0, 0, 1.0]])
    T2 = T.copy()
    T2[:3, :3] = turn @ R
    T2[:3, 3] += [0.0, 0.05, 0.0]
    left, right, V = tracked_eyes(T2, off, 0.064)
    assert np.linalg.norm(left - right) == pytest.approx(0.064)
    assert np.allclose((left - right) / 0.064, turn @ [0.0, 1.0, 0.0])
    assert np.allclose(V, T2[:3, :3] @ off + T2[:3, 3])
    with pytest.raises(ValueError, match="collinear"):
        glasses_pose(np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0.0]]),
                     np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0.0]]))
    with pytest.raises(ValueError, match="ipd"):
        tracked_eyes(T2, off, 0.5)
