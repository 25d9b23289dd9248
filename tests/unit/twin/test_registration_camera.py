"""The calibration twin's image formation (flexsheet.twin.registration_camera): exact rays, and image noise at
the level measured on the real XIMEA images."""

from __future__ import annotations

import math

import cv2
import numpy as np

from flexsheet.twin.registration_camera import XIMEA_NOISE, TrueCamera
from flexsheet.twin.truth import TwinTruth


def test_twin_rays_reproject_exactly():
    t = TwinTruth.draw(2)
    c = t.camera_calib
    cam = TrueCamera(c["K1"], c["D1"], c["image_size"], np.eye(4))
    r = cam.rays(2)
    rng = np.random.default_rng(0)
    idx = rng.integers(0, [r.shape[0], r.shape[1]], (500, 2))
    uv = cv2.projectPoints(r[idx[:, 0], idx[:, 1]].astype(np.float64), np.zeros(3), np.zeros(3), c["K1"],
                           c["D1"])[0]
    expect = np.column_stack([(idx[:, 1] + 0.5) / 2 - 0.5, (idx[:, 0] + 0.5) / 2 - 0.5])
    assert np.abs(uv.reshape(-1, 2) - expect).max() < 1e-3


def test_twin_noise_is_the_measured_ximea_level(home_patterns):
    _, twin, _, frames = home_patterns
    white = frames[-2][0].astype(float)
    # a flat lit patch: noise from adjacent-pixel differences (shading cancels), robust sigma
    ys, xs = np.nonzero(white > 120)
    cy, cx = int(np.median(ys)), int(np.median(xs))
    patch = white[cy - 15:cy + 15, cx - 15:cx + 15]
    d = np.diff(patch, axis=1).ravel()
    sigma = 1.4826 * np.median(np.abs(d - np.median(d))) / math.sqrt(2)
    level = patch.mean()
    expect = math.sqrt(XIMEA_NOISE.read_dn ** 2 + XIMEA_NOISE.shot_gain * level)
    # the optical blur (σ 0.54 px) is applied before the sensor noise, so the noise is white
    assert 0.8 * expect < sigma < 1.2 * expect
