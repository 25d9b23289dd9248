"""The hidden truth (flexsheet.twin.truth): deterministic draws, the ideal one nominal, the documented
spreads."""

from __future__ import annotations

import numpy as np
import pytest

from flexsheet.arm.kinematics import ArmKinematics, home_joints
from flexsheet.calibration.display_calib import nominal_display_calib
from flexsheet.twin.truth import Spreads, TwinTruth


def test_truth_is_deterministic_and_ideal_is_nominal():
    a, b, c = TwinTruth.draw(4), TwinTruth.draw(4), TwinTruth.draw(5)
    assert (np.array_equal(a.T_display_camera, b.T_display_camera)
            and np.array_equal(a.projector_K, b.projector_K))
    assert not np.allclose(a.T_display_camera, c.T_display_camera)
    nom = nominal_display_calib()
    i = TwinTruth.draw(4, "ideal")
    assert np.array_equal(i.T_display_camera, nom.camera.T_display_camera)
    assert np.allclose(i.camera_calib["K1"], nom.camera.stereo["K1"], atol=1e-9)
    assert np.array_equal(i.projector_K, nom.projector.K) and not i.projector_D.any()
    q = home_joints("left") + 0.1
    assert np.allclose(i.clamp_pose("left", q), ArmKinematics("left", nom.arms["left"].T_display_base).fk(q),
                       atol=1e-12)
    # realistic: the as-built arm differs from the nominal by mm, not cm
    d = np.linalg.norm(a.clamp_pose("left", q)[:3, 3]
                       - ArmKinematics("left", nom.arms["left"].T_display_base).fk(q)[:3, 3])
    assert 1e-4 < d < 0.03
    with pytest.raises(ValueError, match="realism"):
        TwinTruth.draw(1, "perfect")
    with pytest.raises(ValueError, match="spread base_mm"):
        TwinTruth.draw(1, spreads=Spreads(base_mm=-1.0))


def test_truth_spreads_match_their_documented_sigmas():
    nom = nominal_display_calib()
    draws = [TwinTruth.draw(s) for s in range(60)]
    cam = np.array([t.T_display_camera[:3, 3] - nom.camera.T_display_camera[:3, 3] for t in draws]) * 1e3
    base = np.array([t.bases["right"][:3, 3] - nom.arms["right"].T_display_base[:3, 3] for t in draws]) * 1e3
    f = np.array([t.projector_K[0, 0] / nom.projector.K[0, 0] - 1.0 for t in draws])
    fx = np.array([t.camera_calib["K1"][0, 0] - nom.camera.stereo["K1"][0, 0] for t in draws])
    sp = Spreads()
    assert 0.7 * sp.camera_mount_mm < cam.std() < 1.3 * sp.camera_mount_mm
    assert 0.7 * sp.base_mm < base.std() < 1.3 * sp.base_mm
    assert 0.6 * sp.projector_focal_rel < f.std() < 1.4 * sp.projector_focal_rel
    assert 1.0 < fx.std() < 3.0          # the XIMEA calibration's bootstrap: sigma_fx = 2.0 px
