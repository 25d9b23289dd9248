"""The camera-pose estimator (flexsheet.calibration.camera_pose) on the twin's board views: a board not found,
a bowed board fitted or refused; no estimator imports the truth or the twin."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from flexsheet.calibration import camera_pose as cp
from flexsheet.calibration.display_calib import nominal_display_calib
from flexsheet.calibration.procedures import QUICK

ROOT = Path(__file__).resolve().parents[3]


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


def test_board_not_found_is_refused(twin_and_camera):
    _, _, views, _ = twin_and_camera
    nom = nominal_display_calib()
    blank = np.full_like(views[0][0], 30)
    with pytest.raises(ValueError, match=r"board not found in the home view \(view 0\).*left image"):
        cp.estimate_camera_pose([(blank, views[0][1])] + views[1:], QUICK.board_spec(), nom.camera.stereo,
                                nom.camera.T_display_camera)
    with pytest.raises(ValueError, match="board found in only 1 of 3 views, need at least 3"):
        cp.estimate_camera_pose([views[0], (blank, blank), (blank, blank)], QUICK.board_spec(),
                                nom.camera.stereo,
                                nom.camera.T_display_camera)


def test_a_bowed_board_is_fitted_or_refused(twin_and_camera):
    truth, twin, _, _ = twin_and_camera
    board = QUICK.board_spec()
    views = twin.board_views(board, cp.plan_board_views(12), bow_mm=0.6)       # sag at the sheet corners
    nom = nominal_display_calib()
    args = (views, board, nom.camera.stereo, nom.camera.T_display_camera)
    r = cp.estimate_camera_pose(*args, prior_cov=cp.load_prior())
    # reported at the board's farthest inner corner: 0.47 x the sheet-corner sag for the 9x8 board
    assert r.bow_mm == pytest.approx(0.6 * 0.47, abs=0.08)
    assert truth.camera_pose_error(r.T_display_camera)[0] < 0.5e-3
    flat = cp.estimate_camera_pose(*args, prior_cov=cp.load_prior(), fit_bow=False)
    assert truth.camera_pose_error(flat.T_display_camera)[0] > 1e-3        # why the bow is fitted
    with pytest.raises(ValueError, match=r"board is bowed by 0\.[23]\d mm at its farthest corner"):
        cp.estimate_camera_pose(*args, prior_cov=cp.load_prior(), max_bow_mm=0.1)
