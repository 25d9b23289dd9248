"""Stereo calibration on the real XIMEA pairs (flexsheet.vision.stereo_calibration, tests/data/stereo_xi):
held-out validation, the shipped calibration, skipped pairs, the CLI and board specs."""

import glob
import os
from pathlib import Path

import cv2
import numpy as np
import pytest

from flexsheet.vision.calib_yaml import load_yaml
from flexsheet.vision.camera_model import XIMEA_CALIB
from flexsheet.vision.stereo_calibration import (
    calibrate_stereo,
    detect_board,
    main,
    parse_board,
    validate_stereo,
)

DATA = str(Path(__file__).resolve().parents[2] / "data" / "stereo_xi")


def _pairs():
    lefts = sorted(glob.glob(os.path.join(DATA, "left*.jpg")))
    rights = sorted(glob.glob(os.path.join(DATA, "right*.jpg")))
    return ([cv2.imread(f, cv2.IMREAD_GRAYSCALE) for f in lefts],
            [cv2.imread(f, cv2.IMREAD_GRAYSCALE) for f in rights], [os.path.basename(f) for f in lefts])


@pytest.fixture(scope="module")
def real_result():
    left, right, names = _pairs()
    assert len(left) == 17
    return calibrate_stereo(left, right, parse_board("chessboard:9x6", 0.024), names)


def test_real_pairs_calibrate(real_result):
    r = real_result
    assert r.image_size == (640, 512)
    assert len(r.used) == 17 and not r.skipped
    # Bound: a 9x6 chessboard with cornerSubPix reaches 0.1-0.2 px on good 640-px cameras (Learning
    # OpenCV 3, ch. 18); the target is 0.25 px. The README's reference figure is ~0.18 px.
    assert r.rms_px < 0.25
    assert r.rms_left_px < 0.25 and r.rms_right_px < 0.25
    # baseline: the source's own extrinsics give |T| ~ 92 mm with 24 mm squares
    assert 0.085 < np.linalg.norm(r.T) < 0.10
    assert abs(r.T[0]) > 0.9 * np.linalg.norm(r.T)            # side-by-side rig: T mostly along x
    assert 500 < r.K1[0, 0] < 540 and 500 < r.K2[0, 0] < 540  # README: fx ~ 519 px
    assert r.per_pair_rms_px.shape == (17, 2)
    assert np.all(r.per_pair_rms_px < 0.5)
    # the rotation is a proper rotation and F satisfies the epipolar constraint on board corners
    assert np.allclose(r.R @ r.R.T, np.eye(3), atol=1e-9) and np.linalg.det(r.R) > 0


def test_epipolar_constraint_on_real_corners(real_result):
    left, right, _ = _pairs()
    board = parse_board("chessboard:9x6", 0.024)
    _, cl = detect_board(left[0], board)
    _, cr = detect_board(right[0], board)
    ul = cv2.undistortPoints(cl.reshape(-1, 1, 2), real_result.K1, real_result.D1,
                             P=real_result.K1).reshape(-1, 2)
    ur = cv2.undistortPoints(cr.reshape(-1, 1, 2), real_result.K2, real_result.D2,
                             P=real_result.K2).reshape(-1, 2)
    from flexsheet.vision.stereo import StereoModel
    m = StereoModel.from_calib(real_result.as_dict())
    res = m.epipolar_residual(ul, ur)
    assert np.median(res) < 0.3


def test_held_out_validation_on_real_pairs():
    """Scale-free validation (the old |T| "real-scale check" was circular — the 24 mm square was
    inferred from |T|): each fold calibrated without its pairs, judged on them. Bounds from the 17-pair
    leave-one-out run (docs/vision.md: 0.16 px, 1.1 % spread): a 4-fold split trains on 12-13 pairs."""
    left, right, names = _pairs()
    v = validate_stereo(left, right, parse_board("chessboard:9x6", 0.024), folds=4, names=names)
    assert v["folds"] == 4 and v["pairs"] == 17 and len(v["per_pair"]) == 17
    assert v["epipolar_rms_px"] < 0.3                     # held-out corners on their epipolar lines
    assert v["square_std_rel"] < 0.03                     # every held-out square the same size, to 3 %
    assert v["square_pair_spread_rel"] < 0.03             # ... on every board pose
    assert abs(v["square_depth_slope_rel_per_m"]) < 0.1   # ... at every depth (wrong f or T would tilt it)
    # the mean is the --square given, by construction: not a check of the true scale
    assert abs(v["square_mean_m"] - 0.024) < 0.0005


def test_held_out_validation_flags_a_broken_pair():
    """The check can fail: right images shifted 3 px vertically (a sensor ROI moved between captures) in the
    pairs of one fold give held-out epipolar errors of about 3/sqrt(2) px there; the other folds, trained with
    those pairs, are disturbed too but far less."""
    left, right, names = _pairs()
    right = [np.roll(r, 3, axis=0) if i % 4 == 0 else r for i, r in enumerate(right)]
    v = validate_stereo(left, right, parse_board("chessboard:9x6", 0.024), folds=4, names=names)
    bad = [v["per_pair"][n]["epipolar_rms_px"] for i, n in enumerate(names) if i % 4 == 0]
    good = [v["per_pair"][n]["epipolar_rms_px"] for i, n in enumerate(names) if i % 4 != 0]
    assert min(bad) > 1.5 and np.median(good) < 0.8 and min(bad) > 2.5 * np.median(good), (bad, good)
    assert v["epipolar_rms_px"] > 0.8                     # the summary flags it too


def test_validate_stereo_refuses_bad_folds():
    left, right, _ = _pairs()
    board = parse_board("chessboard:9x6", 0.024)
    with pytest.raises(ValueError, match="folds must be"):
        validate_stereo(left[:5], right[:5], board, folds=1)
    with pytest.raises(ValueError, match="only 0 pairs"):
        validate_stereo([np.full_like(left[0], 128)] * 4, right[:4], board)


def test_shipped_ximea_calibration_matches(real_result):
    shipped = load_yaml(XIMEA_CALIB)                     # flexsheet/vision/ximea_calib.yaml
    assert np.allclose(shipped["K1"], real_result.K1, rtol=1e-6)
    assert np.allclose(shipped["T"], real_result.T, atol=1e-7)


def test_skipped_pair_reported():
    left, right, names = _pairs()
    left, right, names = left[:4], right[:4], names[:4]
    right[2] = np.full_like(right[2], 128)                     # board missing in one image
    r = calibrate_stereo(left, right, parse_board("chessboard:9x6", 0.024), names)
    assert r.skipped == [names[2]] and "right" in r.skipped_reason[names[2]]
    assert len(r.used) == 3


def test_cli_writes_yaml(tmp_path, capsys):
    out = str(tmp_path / "cal.yaml")
    rc = main(["--left", os.path.join(DATA, "left0[1-5].jpg"), "--right",
               os.path.join(DATA, "right0[1-5].jpg"),
               "--board", "chessboard:9x6", "--square", "0.024", "-o", out])
    assert rc == 0
    assert "stereo RMS" in capsys.readouterr().out
    assert 0.08 < np.linalg.norm(load_yaml(out)["T"]) < 0.105


@pytest.mark.parametrize("spec,square",
                         [("chessboard:9", 0.024), ("chessboard:9x6", None), ("chessboard:1x6", 0.02),
                          ("charuco:5x7:0.04:0.05:DICT_4X4_50", None),
                          ("charuco:5x7:0.04:0.03:DICT_NOPE", None), ("grid:3x3", 0.01)])
def test_bad_board_specs(spec, square):
    with pytest.raises(ValueError):
        parse_board(spec, square)


def test_charuco_synthetic_stereo():
    """ChArUco path (opencv-contrib 5 CharucoDetector.detectBoard): a board seen by a known synthetic rig
    at 8 poses is detected and the rig's 0.1 m baseline is recovered."""
    board = parse_board("charuco:7x5:0.03:0.022:DICT_4X4_50")
    cb = board.charuco_board()
    px_per_m = 4000.0
    bw, bh = int(7 * 0.03 * px_per_m), int(5 * 0.03 * px_per_m)
    tex = cb.generateImage((bw, bh), marginSize=0)
    K = np.array([[600.0, 0, 319.5], [0, 600.0, 239.5], [0, 0, 1]])
    R_lr, T_lr = cv2.Rodrigues(np.array([0.0, 0.02, 0.0]))[0], np.array([-0.1, 0.0, 0.0])
    rng = np.random.default_rng(3)
    left, right = [], []
    S = np.array([[1 / px_per_m, 0, 0], [0, 1 / px_per_m, 0], [0, 0, 1]])   # texture px -> board m
    for _ in range(8):
        rv = rng.uniform(-0.35, 0.35, 3)
        R_b = cv2.Rodrigues(rv)[0]
        t_b = np.array([rng.uniform(-0.08, 0.0), rng.uniform(-0.06, 0.0), rng.uniform(0.45, 0.6)])
        for Rc, Tc, out in ((np.eye(3), np.zeros(3), left), (R_lr, T_lr, right)):
            Rw, tw = Rc @ R_b, Rc @ t_b + Tc
            H = K @ np.column_stack([Rw[:, 0], Rw[:, 1], tw]) @ S
            img = cv2.warpPerspective(tex, H, (640, 480), flags=cv2.INTER_AREA, borderValue=255)
            out.append(cv2.GaussianBlur(img, (0, 0), 0.6))
    r = calibrate_stereo(left, right, board)
    assert len(r.used) >= 6
    assert r.rms_px < 0.5
    assert np.linalg.norm(r.T) == pytest.approx(0.1, abs=0.005)
