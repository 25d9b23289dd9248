"""The head camera's twin (flexsheet.twin.head_camera): the nominal mount, the board's image (levels, place,
visibility), motion blur, exposure gain, seeded noise and input checks. Tracking its frames:
tests/unit/vision/test_glasses.py."""

import cv2
import numpy as np
import pytest

from flexsheet.calibration.head_camera import design_head_camera
from flexsheet.model.geometry import EYE
from flexsheet.twin.head_camera import HeadCameraTwin
from flexsheet.vision.glasses import GlassesTracker

R_NOMINAL = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])   # glasses facing the sheet


def _glasses(offset=(0.0, 0.0, 0.0)) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R_NOMINAL
    T[:3, 3] = EYE + np.asarray(offset, float)
    return T


def _twin(**kw) -> HeadCameraTwin:
    K, T_dc, w, h = design_head_camera()
    return HeadCameraTwin(K, None, T_dc, w, h, **kw)


def _project(twin, X_display) -> np.ndarray:
    Xc = np.asarray(X_display, float) @ twin.T_camera_display[:3, :3].T + twin.T_camera_display[:3, 3]
    return (Xc @ twin.K.T)[..., :2] / Xc[..., 2:]


def test_design_camera_sees_the_eye_and_a_lean_in():
    K, T, w, h = design_head_camera()
    assert (w, h) == (512, 640)                                       # the 640 x 512 sensor in portrait
    assert K == pytest.approx(np.array([[600.0, 0, 255.5], [0, 600.0, 319.5], [0, 0, 1]]), abs=1e-12)
    assert T[:3, 3] == pytest.approx([0.0, 0.0, 0.20], abs=1e-12)
    assert np.linalg.det(T[:3, :3]) == pytest.approx(1.0, abs=1e-12)
    twin = _twin()
    assert _project(twin, np.array([0.25, 0.0, 0.0])) == pytest.approx([255.5, 319.5], abs=1e-9)
    for x, z in ((0.11, -0.03), (0.40, 0.0), (0.45, 0.07)):      # leaned in and low, at V, sat back and high
        u = _project(twin, np.array([x, 0.0, z]))
        assert 0 < u[0] < 512 and 10 < u[1] < 630
    # image +x = display −y (the viewer's left), image +y down
    assert T[:3, 0] == pytest.approx([0.0, -1.0, 0.0], abs=1e-12)
    u_left, u_up = _project(twin, EYE + [0.0, -0.01, 0.0]), _project(twin, EYE + [0.0, 0.0, 0.01])
    u_eye = _project(twin, EYE)
    assert u_left[0] > u_eye[0] + 10 and u_up[1] < u_eye[1] - 10


def test_board_drawn_where_it_projects():
    twin = _twin(noise_sigma=0.0, blur_px=0.0)
    T = _glasses()
    img = twin.render(T)
    assert img.shape == (640, 512) and img.dtype == np.uint8
    Xc = twin.board_corners_camera(T)
    uv = ((Xc @ twin.K.T)[:, :2] / Xc[:, 2:]).reshape(-1, 4, 2)
    # marker interiors' border cells are black (25), the gap between markers white (210), far away background
    for i in (0, 6, 10):
        c = uv[i]
        border = c[0] + 0.08 * (c[2] - c[0])                    # inside the black border, near corner 0
        assert img[int(round(border[1])), int(round(border[0]))] == 25
    gap = 0.5 * (uv[0, 1] + uv[1, 0])                           # between markers 0 and 1, top row
    assert img[int(round(gap[1])), int(round(gap[0]))] == 210
    assert img[20, 20] == 90 and img[620, 500] == 90
    lo, hi = uv.reshape(-1, 2).min(0), uv.reshape(-1, 2).max(0)
    assert 100 < hi[0] - lo[0] < 200 and 25 < hi[1] - lo[1] < 60       # a 0.10 × 0.03 m board at 0.44 m


def test_board_hidden_when_turned_away_behind_or_occluded():
    twin = _twin(noise_sigma=0.0)
    back = _glasses()
    back[:3, :3] = np.diag([-1.0, -1.0, 1.0]) @ R_NOMINAL           # turned 180° about z: faces the viewer
    assert np.all(twin.render(back) == 90)
    behind = _glasses((-0.8, 0.0, 0.2))                              # behind the camera
    assert np.all(twin.render(behind) == 90)
    assert np.all(twin.render(_glasses(), occluded=True) == 0)
    noisy = _twin(noise_sigma=2.0).render(_glasses(), occluded=True)
    assert noisy.mean() < 1.5 and noisy.max() < 15  # black plus the positive half of the noise


def test_noise_is_seeded_and_has_its_sigma():
    T = _glasses()
    a, b, c = _twin(seed=3).render(T), _twin(seed=3).render(T), _twin(seed=4).render(T)
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    patch = a[:100, :200].astype(float)                               # background only
    assert patch.std() == pytest.approx(2.0, abs=0.15) and patch.mean() == pytest.approx(90.0, abs=0.2)
    bright = _twin(noise_sigma=0.0, exposure_gain=1.5).render(T)
    assert bright[20, 20] == 135 and bright.max() == 255                  # white 210·1.5 clips


def test_motion_blur_streaks_along_the_image_velocity():
    twin = _twin(noise_sigma=0.0)
    T = _glasses()
    still = twin.render(T).astype(float)
    # 0.5 m/s along display −y moves the board along image +x: a 0.5·0.004·700/0.435 ≈ 3.2 px streak
    moving = twin.render(T, velocity=(0.0, -0.5, 0.0), exposure_s=0.004).astype(float)

    def sharpness(img, axis):
        return np.abs(np.diff(img, axis=axis)).max()
    assert sharpness(moving, 1) < 0.6 * sharpness(still, 1)
    assert sharpness(moving, 0) > 0.8 * sharpness(still, 0)
    assert abs(moving.sum() - still.sum()) < 1e-3 * still.sum()           # blur keeps the light
    # a streak under 0.3 px is not drawn
    assert np.array_equal(twin.render(T, velocity=(0.0, 0.01, 0.0)), twin.render(T))


def test_distortion_moves_the_board_as_the_lens_model_does():
    K, T_dc, w, h = design_head_camera()
    dist = np.array([0.3, 0.0, 0.0, 0.0, 0.0])                    # pincushion: off-centre points move outward
    T = _glasses((0.0, -0.08, 0.06))                              # up and to the image right
    twin = HeadCameraTwin(K, dist, T_dc, noise_sigma=0.0)
    ids, corners = GlassesTracker(K, dist, T_dc, twin.board, (0.0, 0.0, 0.0), 0.0).detect(twin.render(T))
    X = twin.board_corners_camera(T)
    raw = cv2.projectPoints(X, np.zeros(3), np.zeros(3), K, dist)[0].reshape(-1, 4, 2)[ids]
    ideal = cv2.projectPoints(X, np.zeros(3), np.zeros(3), K, None)[0].reshape(-1, 4, 2)[ids]
    assert len(ids) >= 12
    assert np.linalg.norm(corners - raw, axis=-1).max() < 0.5
    assert np.linalg.norm(corners - ideal, axis=-1).mean() > 3.0                 # the lens moved them


@pytest.mark.parametrize("kwargs, field", [({"width": 8}, "width"), ({"height": 100.5}, "height"),
                                           ({"noise_sigma": -1.0}, "noise_sigma"),
                                           ({"blur_px": np.nan}, "blur_px"),
                                           ({"exposure_gain": 0.0}, "exposure_gain"), ({"board": 3}, "board"),
                                           ({"white": 300.0}, "white"),
                                           ({"camera_matrix": np.eye(4)}, "camera_matrix"),
                                           ({"dist": [1.0, 2.0]}, "dist"),
                                           ({"T_display_camera": np.ones((4, 4))}, "T_display_camera")])
def test_twin_rejects_bad_inputs(kwargs, field):
    K, T_dc, _, _ = design_head_camera()
    args = {"camera_matrix": K, "dist": None, "T_display_camera": T_dc, **kwargs}
    with pytest.raises(ValueError, match=field):
        HeadCameraTwin(**args)


def test_render_rejects_bad_inputs():
    twin = _twin()
    for kwargs, field in (({"T_display_glasses": np.eye(3)}, "T_display_glasses"),
                          ({"velocity": [0.0, np.inf, 0.0]}, "velocity"),
                          ({"exposure_s": -0.001}, "exposure_s")):
        with pytest.raises(ValueError, match=field):
            twin.render(**{"T_display_glasses": _glasses(), **kwargs})
