"""What ``/camera/calibration`` carries: the stereo model with its rectification and the camera's pose, from
``display.yaml`` or, for the ideal twin only, the nominal registration."""

from __future__ import annotations

import numpy as np
import pytest

from flexsheet.calibration.display_calib import nominal_display_calib
from flexsheet.calibration.published_registration import published_registration, with_rectification
from flexsheet.vision.camera_model import camera_model


def test_the_ideal_twin_publishes_the_nominal_pose_and_a_rectified_model():
    calib = camera_model("ximea")
    stereo, T, line = published_registration(None, calib, exact_nominal=True, model="ximea")
    assert np.array_equal(T, nominal_display_calib().camera.T_display_camera) and "nominal" in line
    assert stereo["image_size"] == tuple(int(v) for v in calib["image_size"])
    assert {"R1", "R2", "P1", "P2", "Q"} <= set(stereo) and stereo["Q"].shape == (4, 4)
    assert with_rectification(stereo)["P1"].shape == (3, 4)          # already rectified: kept as it is


def test_without_display_calib_a_real_camera_is_refused_naming_the_fix():
    with pytest.raises(ValueError, match="display_calib is not set.*flexsheet calibrate camera-pose"):
        published_registration(None, camera_model("ximea"))
