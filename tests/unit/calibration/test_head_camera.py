"""The head camera's registration on the chin-rest fixture and the eye's offset in the glasses, in the twin."""

import math

import cv2
import numpy as np
import pytest

from flexsheet.calibration.head_camera import (
    design_head_camera,
    eye_entry,
    fixture_poses,
    register_head_camera,
)
from flexsheet.twin.head_rig import HeadRigTwin, true_head_camera
from flexsheet.vision.glasses import GlassesTracker


@pytest.mark.parametrize("seed", [4, 11])
def test_registration_finds_the_true_camera_and_the_eye(seed):
    rig = HeadRigTwin(seed)
    K0, _, w, h = design_head_camera()
    poses = fixture_poses()
    finder = GlassesTracker(K0, None, np.eye(4), rig.board, np.zeros(3), 0.064)
    entry = register_head_camera([finder.detect(im) for im in rig.fixture_images(poses)], poses, rig.board, K0,
                                 (w, h), "twin")
    K, _, T, _, _ = true_head_camera(seed)
    assert np.linalg.norm(entry.T_display_camera[:3, 3] - T[:3, 3]) < 0.004        # mount drawn ~5 mm off
    dR = cv2.Rodrigues(entry.T_display_camera[:3, :3].T @ T[:3, :3])[0]
    assert math.degrees(np.linalg.norm(dR)) < 0.8                                  # drawn ~1 deg off
    assert entry.provenance.residuals["rms_px"] < 1.5 and entry.provenance.n_poses >= 25
    tracker = GlassesTracker(entry.K, entry.D, entry.T_display_camera, rig.board, np.zeros(3), 0.064)
    eye = eye_entry(tracker.track(rig.chin_rest_image()).T_display_glasses, rig.pupillometer_ipd(), source="twin")
    assert eye.mode == "tracked"
    assert np.linalg.norm(eye.glasses_eye_offset - rig.viewer.eye_offset) < 0.006    # chin rest: ~1 mm per axis
    assert abs(eye.ipd - rig.viewer.ipd) < 0.002


def test_too_few_views_are_refused():
    rig = HeadRigTwin(0, "ideal")
    K0, _, w, h = design_head_camera()
    poses = fixture_poses()[:3]
    finder = GlassesTracker(K0, None, np.eye(4), rig.board, np.zeros(3), 0.064)
    with pytest.raises(ValueError, match="fixture steps"):
        register_head_camera([finder.detect(im) for im in rig.fixture_images(poses)], poses, rig.board, K0, (w, h))
    with pytest.raises(ValueError, match="one detection per"):
        register_head_camera([], poses, rig.board, K0, (w, h))
