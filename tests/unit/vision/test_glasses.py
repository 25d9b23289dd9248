"""The glasses tracker (flexsheet.vision.glasses) on frames of the head-camera twin
(flexsheet.twin.head_camera): board geometry, eye and pose accuracy, the visibility rules, input checks and
the constant-velocity head predictor."""

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from flexsheet.calibration.head_camera import design_head_camera
from flexsheet.model.geometry import EYE
from flexsheet.twin.head_camera import HeadCameraTwin
from flexsheet.vision.glasses import GlassesBoard, GlassesPose, GlassesTracker, HeadPredictor, tracked_eyes

EYE_OFFSET = np.array([0.0, 0.0, -0.012])          # cyclopean eye 12 mm behind the lenses (glasses frame)
IPD = 0.064
# glasses frame in the display frame for a viewer facing the sheet: x (right → left lens) = −y, y = +z,
# z (toward the sheet) = −x
R_NOMINAL = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def _pose(offset=(0.0, 0.0, 0.0), rotvec_deg=(0.0, 0.0, 0.0)) -> np.ndarray:
    """T_display_glasses: the glasses origin at V + ``offset`` m, turned by ``rotvec_deg`` (display frame)."""
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(np.radians(rotvec_deg)).as_matrix() @ R_NOMINAL
    T[:3, 3] = EYE + np.asarray(offset, float)
    return T


def _setup(dist=None, min_markers=3, **twin):
    K, T_dc, w, h = design_head_camera()
    board = GlassesBoard()
    return (HeadCameraTwin(K, dist, T_dc, w, h, board, **twin),
            GlassesTracker(K, dist, T_dc, board, EYE_OFFSET, IPD, min_markers=min_markers))


def _true_corners(twin: HeadCameraTwin, T_display_glasses) -> np.ndarray:
    """Projected board corners (N, 4, 2) px of the true pose."""
    X = twin.board_corners_camera(T_display_glasses)
    return cv2.projectPoints(X, np.zeros(3), np.zeros(3), twin.K, twin.D)[0].reshape(-1, 4, 2)


def _errors(pose: GlassesPose, T_true) -> tuple[float, float]:
    """(worst eye position error m, rotation error deg)."""
    left, right, _ = tracked_eyes(T_true, EYE_OFFSET, IPD)
    eye = max(np.linalg.norm(pose.left - left), np.linalg.norm(pose.right - right))
    dR = T_true[:3, :3].T @ pose.T_display_glasses[:3, :3]
    return float(eye), float(np.degrees(np.linalg.norm(Rotation.from_matrix(dR).as_rotvec())))


# ------------------------------------------------------------------------------------------------- board
def test_board_geometry_in_glasses_frame():
    b = GlassesBoard()
    assert b.size == pytest.approx((0.102, 0.027), abs=1e-12)
    T = b.T_glasses_board
    # board centre 30 mm above the glasses origin; printed face (−z of the OpenCV board) toward glasses +z
    assert (T[:3, :3] @ np.array([0.051, 0.0135, 0.0]) + T[:3, 3]
            == pytest.approx([0.0, 0.030, 0.0], abs=1e-12))
    assert -T[:3, 2] == pytest.approx([0.0, 0.0, 1.0], abs=1e-12)
    P = b.object_points_glasses()
    assert P.shape == (56, 3)
    assert P[:, 2] == pytest.approx(np.zeros(56), abs=1e-12)
    # marker 0's top-left corner: the printed top-left, on the right-lens side (−x) and at the top (+y)
    # (OpenCV keeps the board's points in float32: 1e-7 m)
    assert P[0] == pytest.approx([-0.051, 0.0435, 0.0], abs=1e-7)
    assert P[-2] == pytest.approx([0.051, 0.0165, 0.0], abs=1e-7)           # marker 13's bottom-right


def test_board_image_is_the_opencv_print():
    b = GlassesBoard()
    img, A = b.image(5000.0)
    assert img.shape == (165, 540) and img.dtype == np.uint8
    ref = b.cv_board().generateImage((540, 165), marginSize=15, borderBits=1)
    assert np.array_equal(img, ref)
    # pixel (u, v) = (14.5, 14.5) is the first marker's top-left corner (0, 0) in board metres
    assert A @ [14.5, 14.5, 1.0] == pytest.approx([0.0, 0.0, 1.0], abs=1e-12)
    assert A @ [539.5, 164.5, 1.0] == pytest.approx([0.105, 0.030, 1.0], abs=1e-12)
    # an off-grid scale: area-averaged edges, so the same black area (m²) as the exact print
    img2, _ = b.image(1234.0)
    black = np.sum(ref < 128) / 5000.0 ** 2
    assert np.sum(255.0 - img2) / 255.0 / 1234.0 ** 2 == pytest.approx(black, rel=1e-3)


@pytest.mark.parametrize("kwargs, field", [({"rows": 0}, "rows"), ({"cols": 2.5}, "cols"),
                                           ({"marker": -0.01}, "marker"), ({"gap": 0.0}, "gap"),
                                           ({"first_id": 40}, "first_id"),
                                           ({"dictionary": 9999}, "dictionary"),
                                           ({"height": float("nan")}, "height")])
def test_board_rejects_bad_fields(kwargs, field):
    with pytest.raises(ValueError, match=field):
        GlassesBoard(**kwargs)


# ---------------------------------------------------------------------------------------------- tracking
@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_tracks_eyes_within_2mm_and_1deg(seed):
    twin, tracker = _setup(seed=seed)
    rng = np.random.default_rng(100 + seed)
    for _ in range(3):
        T = _pose(rng.uniform(-0.03, 0.03, 3), rng.uniform(-4.0, 4.0, 3))
        pose = tracker.track(twin.render(T))
        assert pose is not None
        eye, ang = _errors(pose, T)
        assert eye < 2e-3 and ang < 1.0, (eye, ang)
        assert pose.markers >= 12 and pose.reprojection_px < 0.5
        assert pose.V == pytest.approx(tracked_eyes(T, EYE_OFFSET, IPD)[2], abs=2e-3)


def test_tracks_through_lens_distortion_and_motion_blur():
    dist = np.array([-0.25, 0.1, 0.001, -0.001, 0.0])
    twin, tracker = _setup(dist=dist, seed=7)
    T = _pose((0.02, -0.04, 0.03), (3.0, -5.0, 6.0))
    img = twin.render(T, velocity=(0.1, 0.3, -0.1), exposure_s=0.004)      # a 2 px streak
    eye, ang = _errors(tracker.track(img), T)
    assert eye < 2e-3 and ang < 1.0, (eye, ang)
    # the same frame read as undistorted: the tracker's lens model matters
    wrong = GlassesTracker(twin.K, None, twin.T_display_camera, twin.board, EYE_OFFSET, IPD)
    assert _errors(wrong.track(img), T)[0] > 2e-3


def test_object_points_land_on_the_detected_corners():
    twin, tracker = _setup(seed=3)
    T = _pose((0.01, 0.02, -0.01), (2.0, 3.0, -2.0))
    ids, corners = tracker.detect(twin.render(T))
    assert len(ids) >= 12 and np.all(np.diff(ids) > 0)
    err = np.linalg.norm(corners - _true_corners(twin, T)[ids], axis=-1)
    assert err.max() < 1.0 and np.median(err) < 0.3, (err.max(), np.median(err))
    # as the camera sees the board: the printed top row is above the bottom row, marker 0 left of marker 6
    uv = _true_corners(twin, T).mean(axis=1)
    assert uv[0, 0] < uv[6, 0] - 100 and uv[0, 1] < uv[7, 1] - 15


def test_occluded_or_turned_away_gives_none():
    twin, tracker = _setup(seed=4)
    T = _pose()
    assert tracker.track(twin.render(T, occluded=True)) is None
    back = _pose(rotvec_deg=(0.0, 0.0, 180.0))               # facing the sheet: the camera sees the back
    back[:3, 3] = T[:3, 3]
    assert tracker.track(twin.render(back)) is None
    assert tracker.track(twin.render(T)) is not None


def test_two_markers_are_not_enough():
    twin, tracker = _setup(seed=5, min_markers=3)
    T = _pose((0.0, 0.01, 0.0), (0.0, 2.0, 0.0))
    img = twin.render(T)
    uv = _true_corners(twin, T)
    mask = np.zeros_like(img)
    for i in (3, 4):                                         # keep markers 3 and 4 with a white surround
        c = uv[i].mean(0)
        cv2.fillConvexPoly(mask, np.round(c + 1.4 * (uv[i] - c)).astype(np.int32), 255)
    cut = np.where(mask > 0, img, np.uint8(90))
    ids, _ = tracker.detect(cut)
    assert ids.tolist() == [3, 4]
    assert tracker.track(cut) is None
    _, loose = _setup(min_markers=2)
    assert loose.track(cut) is not None and loose.track(cut).markers == 2


def test_tracker_rejects_bad_inputs():
    K, T_dc, _, _ = design_head_camera()
    b = GlassesBoard()
    good = dict(camera_matrix=K, dist=None, T_display_camera=T_dc, board=b, eye_offset=EYE_OFFSET, ipd=IPD)
    bad = [("camera_matrix", np.eye(2)), ("camera_matrix", np.diag([-700.0, 700.0, 1.0])),
           ("dist", [0.1, 0.2, 0.3]), ("dist", [np.nan] * 5), ("T_display_camera", np.eye(3)),
           ("T_display_camera", np.diag([1.0, 1.0, -1.0, 1.0])), ("board", "DICT_4X4_50"),
           ("eye_offset", [0.0, 0.0]), ("eye_offset", [0.0, np.inf, 0.0]), ("ipd", 0.2), ("ipd", -0.01),
           ("ipd", float("nan"))]
    for field, value in bad:
        with pytest.raises(ValueError, match=field):
            GlassesTracker(**{**good, field: value})
    for n in (0, 15, 2.5):
        with pytest.raises(ValueError, match="min_markers"):
            GlassesTracker(**good, min_markers=n)
    tracker = GlassesTracker(**good)
    with pytest.raises(ValueError, match="image"):
        tracker.track(np.zeros((512, 640), np.float32))


# --------------------------------------------------------------------------------------------- predictor
def _eyes_pose(V) -> GlassesPose:
    V = np.asarray(V, float)
    off = np.array([0.0, IPD / 2, 0.0])
    return GlassesPose(np.eye(4), V - off, V + off, V, 14, 0.1)


def test_predictor_extrapolates_constant_velocity_and_caps():
    pr = HeadPredictor(smoothing=0.5, max_extrapolation=0.1)
    assert pr.predict(0.0) is None
    V0, v = np.array([0.40, 0.01, -0.02]), np.array([0.05, -0.12, 0.08])
    for k in range(6):
        t = 10.0 + k / 120
        assert pr.update(t, _eyes_pose(V0 + v * (t - 10.0)))
    t_last = 10.0 + 5 / 120
    left, right, V = pr.predict(t_last + 0.03)
    assert np.linalg.norm(V - (V0 + v * (t_last + 0.03 - 10.0))) < 1e-4
    assert np.linalg.norm(right - left - [0.0, IPD, 0.0]) < 1e-4
    # capped at 0.1 s ahead; never extrapolated backwards
    assert np.linalg.norm(pr.predict(t_last + 1.0)[2] - (V0 + v * (t_last + 0.1 - 10.0))) < 1e-4
    assert np.linalg.norm(pr.predict(t_last - 0.5)[2] - (V0 + v * (t_last - 10.0))) < 1e-9


def test_predictor_ignores_stale_poses_and_restarts_after_a_gap():
    pr = HeadPredictor(max_gap=0.25)
    pr.update(1.0, _eyes_pose([0.40, 0.0, 0.0]))
    pr.update(1.01, _eyes_pose([0.401, 0.0, 0.0]))                     # 0.1 m/s along x
    assert pr.predict(1.05)[2][0] == pytest.approx(0.405, abs=1e-9)
    assert not pr.update(1.005, _eyes_pose([0.5, 0.0, 0.0]))            # older than the last: ignored
    assert pr.predict(1.05)[2][0] == pytest.approx(0.405, abs=1e-9)
    pr.update(2.0, _eyes_pose([0.42, 0.0, 0.0]))                        # after a 1 s gap: at rest
    assert pr.predict(2.05)[2][0] == pytest.approx(0.42, abs=1e-12)
    for kwargs, field in (({"smoothing": 0.0}, "smoothing"), ({"smoothing": 1.5}, "smoothing"),
                          ({"max_extrapolation": -0.1}, "max_extrapolation"), ({"max_gap": 0.0}, "max_gap")):
        with pytest.raises(ValueError, match=field):
            HeadPredictor(**kwargs)
    with pytest.raises(ValueError, match="stamp"):
        pr.update(float("nan"), _eyes_pose([0.4, 0.0, 0.0]))
