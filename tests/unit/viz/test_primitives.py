"""The scene's geometry helpers (flexsheet.viz.primitives): frustum corners, the sheet mesh's depression,
quaternions."""

from __future__ import annotations

import numpy as np
import pytest

from flexsheet.model import geometry
from flexsheet.model.projector import Projector
from flexsheet.model.sheet import SheetSurface, clamp_poses
from flexsheet.viz.primitives import frustum_points, quaternions, sheet_mesh


def test_frustum_corners_reproject_to_the_image_corners():
    P = Projector.default()
    Tp = np.eye(4)
    Tp[:3, :3], Tp[:3, 3] = P.R, P.position
    pts = frustum_points(P.K, P.width, P.height, Tp, depth=1.0)
    assert np.allclose(pts[0], geometry.PROJECTOR)
    assert np.allclose(pts[1:, 0], 0.0, atol=1e-12)      # optical axis +x: depth 1 m reaches the screen x = 0
    xc = (pts[1:] - P.position) @ P.R                     # back into the projector frame, then project
    uv = (P.K @ xc.T).T
    assert np.allclose(uv[:, :2] / uv[:, 2:], [[0, 0], [P.width, 0], [P.width, P.height], [0, P.height]])
    # one projector pixel is 0.7 mm on the screen
    assert abs(np.linalg.norm(pts[2] - pts[1]) / P.width - geometry.PIXEL_ON_SCREEN) < 1e-9
    with pytest.raises(ValueError, match="depth"):
        frustum_points(P.K, 10, 10, Tp, depth=0.0)


def test_sheet_mesh_carries_the_membrane_depression():
    clamps = clamp_poses(np.zeros(3), geometry.SCREEN_NORMAL, np.array([0.0, 1.0, 0.0]), 0.0)
    sheet = SheetSurface.from_clamps(*clamps, pushed_point=np.array([-0.01, 0.0, 0.0]),
                                     membrane_kwargs={"modes": 64})
    v, f = sheet_mesh(sheet, 21)
    assert v.shape == (441, 3) and f.shape == (800, 3) and f.max() == 440
    centre = v[10 * 21 + 10]
    assert np.allclose(centre, [-0.01, 0.0, 0.0], atol=2e-4)          # the deepest point is under the finger
    edges = v.reshape(21, 21, 3)[[0, -1], :, 0]
    assert np.allclose(edges, 0.0, atol=1e-12)                         # clamped edges stay on the plane
    with pytest.raises(ValueError, match="n must be"):
        sheet_mesh(sheet, 1)


def test_quaternions_match_known_rotations_and_reject_bad_input():
    Rz = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # 90° about z
    assert np.allclose(quaternions(Rz), [0, 0, np.sqrt(0.5), np.sqrt(0.5)])
    assert quaternions(np.stack([np.eye(3)] * 3)).shape == (3, 4)
    with pytest.raises(ValueError, match="rotations"):
        quaternions(np.full((3, 3), np.nan))
