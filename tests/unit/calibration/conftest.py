"""Fixtures shared by the calibration tests: the twin's board views and the camera pose estimated from them
(once per package)."""

from __future__ import annotations

import pytest

from flexsheet.calibration import camera_pose as cp
from flexsheet.calibration.display_calib import nominal_display_calib
from flexsheet.calibration.procedures import QUICK
from flexsheet.twin.registration_camera import CalibrationTwin
from flexsheet.twin.truth import TwinTruth


@pytest.fixture(scope="package")
def twin_and_camera():
    truth = TwinTruth.draw(11)
    twin = CalibrationTwin(truth, seed=5, frames=8)
    board = QUICK.board_spec()
    views = twin.board_views(board, cp.plan_board_views(8))
    nom = nominal_display_calib()
    r = cp.estimate_camera_pose(views, board, nom.camera.stereo, nom.camera.T_display_camera,
                                prior_cov=cp.load_prior())
    return truth, twin, views, r
