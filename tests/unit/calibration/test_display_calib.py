"""The display calibration's entries (flexsheet.calibration.display_calib): stale and nominal entries refused
when asked, a base pose as x, y, z, yaw."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from test_display_calib_file import _measured

from flexsheet.calibration.display_calib import DisplayCalib, xyzyaw_from_pose
from flexsheet.calibration.display_calib_file import load_display_calib, write_display_calib
from flexsheet.model import geometry


def test_stale_and_nominal_entries_are_refused_when_asked(tmp_path):
    c = _measured()
    path = str(tmp_path / "display.yaml")
    write_display_calib(path, c)
    d = load_display_calib(path)
    # camera measured 2025-01-02 (old), projector nominal: both stale for a 30-day limit
    assert set(d.stale(30 * 86400.0)) >= {"camera", "projector"}
    with pytest.raises(ValueError, match="stale entries"):
        d.require("camera", max_age_s=30 * 86400.0)
    fresh = DisplayCalib(arms={"left": c.arms["left"]})
    assert fresh.stale(3600.0, names=("arms.left",)) == []


def test_base_pose_to_xyzyaw():
    T = geometry.pose_matrix(-0.05, 0.55, -0.4, -math.pi / 2)
    assert np.allclose(xyzyaw_from_pose(T), (-0.05, 0.55, -0.4, -math.pi / 2))
    Tt = T.copy()
    Tt[:3, :3] = cv2.Rodrigues(np.array([0.05, 0.0, 0.0]))[0] @ T[:3, :3]
    with pytest.raises(ValueError, match="tilted"):
        xyzyaw_from_pose(Tt)
