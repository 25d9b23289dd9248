"""Structured light (flexsheet.calibration.projector): the Gray-code decoder against OpenCV's, the grid
correspondences against the twin's true projector; poses and patterns that cannot be used are refused."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from flexsheet.calibration import arms as arms_mod
from flexsheet.calibration import projector as pj
from flexsheet.calibration.display_calib import nominal_display_calib


def test_decoder_matches_opencv_getprojpixel(home_patterns):
    truth, _, pats, frames = home_patterns
    W, H = truth.projector_size
    left = [f[0] for f in frames]
    col, row, valid = pj.decode(left, W, H)
    assert valid.sum() > 20000
    g = cv2.structured_light.GrayCodePattern.create(W, H)
    ys, xs = np.nonzero(valid)
    pick = np.random.default_rng(1).choice(len(xs), 300, replace=False)
    agree = 0
    for k in pick:
        err, p = g.getProjPixel(left[:-2], int(xs[k]), int(ys[k]))
        agree += (not err) and p == (col[ys[k], xs[k]], row[ys[k], xs[k]])
    assert agree == len(pick)            # same bits, same Gray->binary, same per-bit threshold (5 DN)


def test_grid_correspondences_hit_the_true_projector(home_patterns):
    truth, twin, _, frames = home_patterns
    W, H = truth.projector_size
    col, row, valid = pj.decode([f[0] for f in frames], W, H)
    proj, cam = pj.grid_correspondences(col, row, valid, 8)
    assert len(proj) > 1000
    # where does each camera point's ray meet the home sheet
    # (x = 0), and where does the true projector put it?
    c = twin.cams[0]
    X = []
    for u, v in cam:
        n = cv2.undistortPoints(np.array([[[u, v]]]), c.K, c.D).ravel()
        d = c.T[:3, :3] @ np.array([n[0], n[1], 1.0])
        X.append(c.T[:3, 3] - c.T[0, 3] / d[0] * d)
    Tp = truth.T_display_projector
    uv = cv2.projectPoints(np.array(X), cv2.Rodrigues(Tp[:3, :3].T)[0], -Tp[:3, :3].T @ Tp[:3, 3],
                           truth.projector_K, truth.projector_D)[0].reshape(-1, 2)
    err = np.linalg.norm(uv - proj, axis=1)
    assert np.median(err) < 0.1 and np.percentile(err, 95) < 0.3     # projector px


def test_too_few_poses_are_refused(twin_and_camera):
    truth, twin, _, cam = twin_and_camera
    W, H = truth.projector_size
    pats = pj.gray_code_patterns(W, H)
    pose = pj.triangulate_pose(twin.pattern_frames(pats, np.eye(4), frames=1), W, H, cam.stereo,
                               cam.T_display_camera)
    assert len(pose.X) > 500
    with pytest.raises(ValueError, match="needs at least 3 sheet poses"):
        pj.estimate_projector([pose, pose], nominal_display_calib().projector.K, (W, H))
    q = [arms_mod.home_joints("left")] * 5
    with pytest.raises(ValueError, match="only 5 usable marker configurations, need at least 8"):
        arms_mod.estimate_arm_base("left", q, np.zeros((5, 3)), np.eye(4), np.zeros(3))


def test_undecodable_patterns_are_refused(twin_and_camera):
    truth, twin, _, cam = twin_and_camera
    W, H = truth.projector_size
    pats = pj.gray_code_patterns(W, H)
    dark = twin.pattern_frames(pats, np.eye(4), white_dn=6.0, frames=1)     # a dark, thick sheet
    with pytest.raises(ValueError, match=r"patterns did not decode in the left camera.*sheet too dark"):
        pj.triangulate_pose(dark, W, H, cam.stereo, cam.T_display_camera)
    with pytest.raises(ValueError, match="need 42 images"):
        pj.decode([f[0] for f in dark[:-1]], W, H)
