"""The fingertip predictor (flexsheet.vision.predict): the constant-velocity Kalman filter."""

import numpy as np
import pytest

from flexsheet.vision.predict import ConstantVelocityKF


def test_kalman_predicts_constant_velocity():
    kf = ConstantVelocityKF(q=0.01)   # small q: the motion really is constant-velocity
    rng = np.random.default_rng(0)
    v = np.array([0.2, -0.1, 0.05])
    R = np.eye(3) * (0.3e-3) ** 2
    for k in range(60):
        t = k / 48
        kf.update(v * t + rng.normal(0, 0.3e-3, 3), R, t)
    # the estimate is consistent with the filter's own covariance (3σ), which is a few cm/s at 48 Hz
    sd_v = np.sqrt(np.diag(kf.P)[3:])
    assert np.all(np.abs(kf.velocity - v) < 3 * sd_v) and np.all(sd_v < 0.03)
    t_last = 59 / 48
    x_pred, P_pred = kf.predicted(t_last + 0.05)
    assert np.all(np.abs(x_pred[:3] - v * (t_last + 0.05)) < 3 * np.sqrt(np.diag(P_pred)[:3]))
    assert np.linalg.norm(x_pred[:3] - v * (t_last + 0.05)) < 3e-3
    # a 5 cm jump is far outside the gate; a 0.3 mm step is inside
    assert kf.mahalanobis2(v * (t_last + 1 / 48) + [0.05, 0, 0], R, t_last + 1 / 48) > 100
    assert kf.mahalanobis2(v * (t_last + 1 / 48), R, t_last + 1 / 48) < 16.27
    with pytest.raises(ValueError, match="z must be"):
        kf.update(np.array([np.nan, 0, 0]), R, 2.0)
