"""The hidden truth (flexsheet.twin.truth) and the calibration twin's image formation
(flexsheet.twin.registration_camera): determinism, documented spreads, exact rays, the decoder against OpenCV's,
and image noise at the level measured on the real XIMEA images."""

from __future__ import annotations

import ast
import math
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from flexsheet.arm.kinematics import ArmKinematics, home_joints
from flexsheet.calibration import projector as pj
from flexsheet.calibration.display_calib import nominal_display_calib
from flexsheet.twin.registration_camera import XIMEA_NOISE, CalibrationTwin, TrueCamera
from flexsheet.twin.sensor_noise import measure_ximea_noise
from flexsheet.twin.truth import Spreads, TwinTruth

ROOT = Path(__file__).resolve().parents[3]


def test_truth_is_deterministic_and_ideal_is_nominal():
    a, b, c = TwinTruth.draw(4), TwinTruth.draw(4), TwinTruth.draw(5)
    assert np.array_equal(a.T_display_camera, b.T_display_camera) and np.array_equal(a.projector_K, b.projector_K)
    assert not np.allclose(a.T_display_camera, c.T_display_camera)
    nom = nominal_display_calib()
    i = TwinTruth.draw(4, "ideal")
    assert np.array_equal(i.T_display_camera, nom.camera.T_display_camera)
    assert np.allclose(i.camera_calib["K1"], nom.camera.stereo["K1"], atol=1e-9)
    assert np.array_equal(i.projector_K, nom.projector.K) and not i.projector_D.any()
    q = home_joints("left") + 0.1
    assert np.allclose(i.clamp_pose("left", q), ArmKinematics("left", nom.arms["left"].T_display_base).fk(q), atol=1e-12)
    # realistic: the as-built arm differs from the nominal by mm, not cm
    d = np.linalg.norm(a.clamp_pose("left", q)[:3, 3] - ArmKinematics("left", nom.arms["left"].T_display_base).fk(q)[:3, 3])
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


def test_twin_rays_reproject_exactly():
    t = TwinTruth.draw(2)
    c = t.camera_calib
    cam = TrueCamera(c["K1"], c["D1"], c["image_size"], np.eye(4))
    r = cam.rays(2)
    rng = np.random.default_rng(0)
    idx = rng.integers(0, [r.shape[0], r.shape[1]], (500, 2))
    uv = cv2.projectPoints(r[idx[:, 0], idx[:, 1]].astype(np.float64), np.zeros(3), np.zeros(3), c["K1"], c["D1"])[0]
    expect = np.column_stack([(idx[:, 1] + 0.5) / 2 - 0.5, (idx[:, 0] + 0.5) / 2 - 0.5])
    assert np.abs(uv.reshape(-1, 2) - expect).max() < 1e-3


@pytest.fixture(scope="module")
def home_patterns():
    truth = TwinTruth.draw(3)
    twin = CalibrationTwin(truth, seed=1)
    W, H = truth.projector_size
    pats = pj.gray_code_patterns(W, H)
    return truth, twin, pats, twin.pattern_frames(pats, np.eye(4), home_exact=True, frames=1)


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
    # where does each camera point's ray meet the home sheet (x = 0), and where does the true projector put it?
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


def test_measured_noise_model_on_real_pairs(tmp_path):
    src = ROOT / "tests" / "data" / "stereo_xi"
    for n in ("left01.jpg", "left05.jpg", "right01.jpg", "right05.jpg"):
        shutil.copy(src / n, tmp_path / n)
    r = measure_ximea_noise(str(tmp_path))
    m = r["model"]
    # four images against the 34-image medians behind XIMEA_NOISE: same camera, same order of magnitude
    assert 0.2 <= m["blur_px"] <= 1.0
    assert 2.0 < r["median"]["sigma_black_dn"] < 7.0 and 4.0 < r["median"]["sigma_white_dn"] < 12.0
    assert r["median"]["sigma_white_dn"] > r["median"]["sigma_black_dn"]          # shot noise
    assert 20 < m["black_dn"] < 60 and 110 < m["white_dn"] < 230
    assert 0.08 < m["corner_rms_px"] < 0.25


def test_estimators_never_import_the_truth_or_the_twin():
    bad = []
    for name in ("camera_pose", "projector", "arms", "eye"):
        path = ROOT / "flexsheet" / "calibration" / f"{name}.py"
        for node in ast.walk(ast.parse(path.read_text())):
            mods = []
            if isinstance(node, ast.Import):
                mods = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                mods = [node.module or ""]
            bad += [f"{name}: {m}" for m in mods if m.startswith("flexsheet.twin") or m.endswith("sources")]
    assert bad == []
