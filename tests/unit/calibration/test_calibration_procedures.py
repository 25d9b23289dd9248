"""Display registration in the twin (flexsheet.calibration): every procedure within its target for three truth
seeds (quick preset), refusals of corrupted input with clear errors, the lab's captured-images path, the eye."""

from __future__ import annotations

import json
import math
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from flexsheet.calibration import arms as arms_mod
from flexsheet.calibration import camera_pose as cp
from flexsheet.calibration import projector as pj
from flexsheet.calibration.display_calib import ENTRIES, nominal_display_calib
from flexsheet.calibration.display_calib_file import load_display_calib
from flexsheet.calibration.eye import glasses_eye_offset, glasses_pose, tracked_eyes
from flexsheet.calibration.procedures import QUICK
from flexsheet.calibration.sources import ImageDirSource, save_frames
from flexsheet.display.calibrate import camera_pose_main, display_main, eye_main
from flexsheet.model import geometry
from flexsheet.twin.registration import run_display_sim
from flexsheet.twin.registration_camera import CalibrationTwin
from flexsheet.twin.truth import TwinTruth

#: the truth seeds of the twin's quick registration that tests/nodes/test_camera_realism.py and
#: tests/unit/rendering/test_correction_twin.py load (sim_display_calib(seed, quick=True)): run here fresh, then shared
SEEDS = (0, 1, 2)


def _share_with_the_cache(seed: int, out: Path) -> None:
    """Put this fresh run's files where :func:`flexsheet.twin.registration.sim_display_calib` caches the
    realistic quick registration of ``seed`` (when that entry is absent), so the tests that load it do not run
    the same procedures again: the same call (seed, realism, QUICK) whose summary key run_display_sim checks."""
    root = os.environ.get("FLEXSHEET_CACHE") or os.path.join(os.path.expanduser("~"), ".cache", "flexsheet")
    dst = Path(root) / "display" / f"realistic-{int(seed)}-quick"
    if (dst / "summary.json").is_file() and (dst / "display.yaml").is_file():
        return
    dst.mkdir(parents=True, exist_ok=True)
    for name in ("display.yaml", "summary.json"):       # summary last: it is what marks the entry complete
        tmp = dst / f".{name}.{os.getpid()}"
        shutil.copyfile(out / name, tmp)
        os.replace(tmp, dst / name)


@pytest.fixture(scope="module", params=SEEDS)
def sim(request, tmp_path_factory):
    out = tmp_path_factory.mktemp(f"display{request.param}")
    s = run_display_sim(request.param, str(out), QUICK)     # always run here, never cached
    _share_with_the_cache(request.param, out)
    return request.param, out, s


def test_every_procedure_within_target(sim):
    seed, out, s = sim
    assert s["camera"]["translation_error_mm"] <= 0.5, s["camera"]
    assert s["camera"]["rotation_error_deg"] <= 0.1, s["camera"]
    assert s["projector"]["translation_error_mm"] <= 2.0, s["projector"]
    assert s["projector"]["rotation_error_deg"] <= 0.2, s["projector"]
    assert s["projector"]["reprojection_px"] <= 0.5, s["projector"]
    for side in ("left", "right"):
        assert s["arms"][side]["translation_error_mm"] <= 1.0, (side, s["arms"][side])
    # residuals a lab would see are reported and plausible (corner jitter of the twin vs 0.127 px real RMS)
    assert 0.02 < s["camera"]["rms_px"] < 0.2
    assert s["camera"]["views"] == QUICK.views and s["projector"]["poses"] == QUICK.projector_poses
    # the file the display runs on
    d = load_display_calib(str(out / "display.yaml"), require=ENTRIES)
    assert d.camera.provenance.source == f"twin seed {seed} (realistic)"
    assert d.projector.provenance.residuals["reprojection_px"] == pytest.approx(s["projector"]["reprojection_px"])
    # estimates moved away from the nominal toward the truth (they were not handed the nominal back)
    truth = TwinTruth.draw(seed)
    nom = nominal_display_calib()
    assert (truth.camera_pose_error(nom.camera.T_display_camera)[0] * 1e3
            > 5 * s["camera"]["translation_error_mm"])
    assert truth.base_error("left", nom.arms["left"].T_display_base)[0] * 1e3 > s["arms"]["left"]["translation_error_mm"]


def test_summary_is_cached_per_seed(sim):
    seed, out, s = sim
    again = run_display_sim(seed, str(out), QUICK)
    assert again == json.loads((out / "summary.json").read_text())
    assert again["timings"] == s["timings"]           # not re-run


@pytest.fixture(scope="module")
def twin_and_camera():
    truth = TwinTruth.draw(11)
    twin = CalibrationTwin(truth, seed=5, frames=8)
    board = QUICK.board_spec()
    views = twin.board_views(board, cp.plan_board_views(8))
    nom = nominal_display_calib()
    r = cp.estimate_camera_pose(views, board, nom.camera.stereo, nom.camera.T_display_camera, prior_cov=cp.load_prior())
    return truth, twin, views, r


def test_board_not_found_is_refused(twin_and_camera):
    _, _, views, _ = twin_and_camera
    nom = nominal_display_calib()
    blank = np.full_like(views[0][0], 30)
    with pytest.raises(ValueError, match=r"board not found in the home view \(view 0\).*left image"):
        cp.estimate_camera_pose([(blank, views[0][1])] + views[1:], QUICK.board_spec(), nom.camera.stereo,
                                nom.camera.T_display_camera)
    with pytest.raises(ValueError, match="board found in only 1 of 3 views, need at least 3"):
        cp.estimate_camera_pose([views[0], (blank, blank), (blank, blank)], QUICK.board_spec(), nom.camera.stereo,
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


def test_too_few_poses_are_refused(twin_and_camera):
    truth, twin, _, cam = twin_and_camera
    W, H = truth.projector_size
    pats = pj.gray_code_patterns(W, H)
    pose = pj.triangulate_pose(twin.pattern_frames(pats, np.eye(4), frames=1), W, H, cam.stereo, cam.T_display_camera)
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


def test_frames_out_of_step_with_joints_are_refused(twin_and_camera):
    truth, twin, _, cam = twin_and_camera
    nom = nominal_display_calib()
    a = nom.arms["left"]
    qs = arms_mod.plan_arm_configs("left", 10, a.T_display_base, a.marker_offset, cam.stereo, cam.T_display_camera)
    X = np.array([truth.clamp_marker_position("left", q) for q in qs])
    ok = arms_mod.estimate_arm_base("left", qs, X, a.T_display_base, a.marker_offset)
    assert ok.residual_mm < 0.5               # the as-built arm vs the nominal URDF: link and zero errors only
    # the joint list one step behind the frames (a capture that skipped a configuration): no base explains it
    with pytest.raises(ValueError, match="arm left: fit residual"):
        arms_mod.estimate_arm_base("left", qs, np.roll(X, 1, axis=0), a.T_display_base, a.marker_offset)


def test_lab_images_path_runs_the_same_estimator(twin_and_camera, tmp_path):
    _, _, views, r = twin_and_camera
    save_frames(str(tmp_path / "frames"), board_views=views)
    src = ImageDirSource(str(tmp_path / "frames"))
    again = src.board_views(QUICK.board_spec())
    assert len(again) == len(views) and np.array_equal(again[3][1], views[3][1])
    out = tmp_path / "lab"
    assert camera_pose_main(["--images", str(tmp_path / "frames"), "--out", str(out)]) == 0
    d = load_display_calib(str(out / "display.yaml"), require=("camera",))
    assert np.allclose(d.camera.T_display_camera, r.T_display_camera, atol=1e-9)
    assert d.camera.provenance.source.startswith("lab images")
    assert eye_main(["--V", "0.41,0,0.01", "--ipd", "0.062", "--out", str(out)]) == 0
    d = load_display_calib(str(out / "display.yaml"), require=("camera", "eye"))
    assert np.allclose(d.eye.V, [0.41, 0, 0.01]) and d.eye.ipd == 0.062
    with pytest.raises(ValueError, match="lacks arms.left.joints"):
        ImageDirSource(str(tmp_path / "frames")).marker_frames("left")


def test_lab_images_path_for_the_arms(twin_and_camera, tmp_path):
    from flexsheet.calibration.display_calib import CameraEntry, DisplayCalib, Provenance
    from flexsheet.calibration.procedures import run_arms
    from flexsheet.twin.registration import TwinSource

    truth, twin, _, r = twin_and_camera
    calib = DisplayCalib(camera=CameraEntry(r.T_display_camera, Provenance("test"), r.stereo))
    opts = QUICK.__class__(arm_configs=8)
    src = TwinSource(twin, marker_frames=2)
    nom = nominal_display_calib().arms["left"]
    qs = arms_mod.plan_arm_configs("left", 8, nom.T_display_base, nom.marker_offset, r.stereo, r.T_display_camera)
    frames, q = src.marker_frames("left", qs)
    save_frames(str(tmp_path), arms={"left": (frames, q)})
    lab = run_arms(ImageDirSource(str(tmp_path)), opts, calib, ("left",))["left"]
    again = run_arms(_Replay(frames, q), opts, calib, ("left",))["left"]
    # same frames, same estimator: the same base, whichever source hands them over
    assert np.allclose(lab[0].T_display_base, again[0].T_display_base, atol=1e-12)
    assert truth.base_error("left", lab[0].T_display_base)[0] < 2e-3
    assert lab[0].provenance.source.startswith("lab images") and lab[1].n_configs == 8


class _Replay:
    """A frame source that hands back given marker frames (the twin's, captured once)."""

    label = "replay"

    def __init__(self, frames, q):
        self.frames, self.q = frames, q

    def marker_frames(self, side, joints):
        return self.frames, self.q


def test_display_cli_needs_a_seed(capsys):
    with pytest.raises(SystemExit):
        display_main(["--sim", "--out", "/tmp/never-written"])
    assert "--truth-seed" in capsys.readouterr().err


def test_tracked_eyes_follow_the_glasses():
    rng = np.random.default_rng(3)
    model = np.array([[0.07, 0.0, 0.0], [-0.07, 0.0, 0.0], [0.0, 0.03, 0.01], [0.02, -0.01, 0.02]])
    R = np.column_stack([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])      # glasses x = display +y
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = geometry.EYE + np.array([0.0, 0.0, 0.03])
    seen = model @ R.T + T[:3, 3] + rng.normal(0, 2e-5, model.shape)
    T_est = glasses_pose(seen, model)
    assert np.linalg.norm(T_est[:3, 3] - T[:3, 3]) < 1e-4
    off = glasses_eye_offset(T, geometry.EYE)
    assert np.allclose(off, [0.0, -0.03, 0.0], atol=1e-12)
    # the head turns 20 deg about z and moves 5 cm to the side: the eyes go with it
    turn = np.array([[math.cos(0.35), -math.sin(0.35), 0], [math.sin(0.35), math.cos(0.35), 0], [0, 0, 1.0]])
    T2 = T.copy()
    T2[:3, :3] = turn @ R
    T2[:3, 3] += [0.0, 0.05, 0.0]
    left, right, V = tracked_eyes(T2, off, 0.064)
    assert np.linalg.norm(left - right) == pytest.approx(0.064)
    assert np.allclose((left - right) / 0.064, turn @ [0.0, 1.0, 0.0])
    assert np.allclose(V, T2[:3, :3] @ off + T2[:3, 3])
    with pytest.raises(ValueError, match="collinear"):
        glasses_pose(np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0.0]]), np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0.0]]))
    with pytest.raises(ValueError, match="ipd"):
        tracked_eyes(T2, off, 0.5)
