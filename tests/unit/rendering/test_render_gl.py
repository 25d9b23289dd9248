"""GLSL correction vs numpy (transform feedback), deterministic headless render, measurement camera."""

import numpy as np
import pytest

from flexsheet.experiments.measurement import MeasurementCamera, measure_sizes
from flexsheet.model import geometry
from flexsheet.model.projector import Projector
from flexsheet.model.sheet import Membrane, SheetSurface
from flexsheet.rendering.correction import correct_vertices, correct_vertices_fine, correct_vertices_pushed
from flexsheet.rendering.stereo_renderer import StereoRenderer, cylinder_mesh

COM = dict(projector=geometry.PROJECTOR, screen_point=geometry.SCREEN_POINT, screen_normal=geometry.SCREEN_NORMAL)
R = geometry.CYLINDER_RADIUS


@pytest.fixture(scope="module")
def gl():
    import moderngl

    ctx = moderngl.create_standalone_context(backend="egl")
    r = StereoRenderer(Projector.default(256, 192, pixel=0.0028), ctx=ctx, shading=False)
    v, f = cylinder_mesh(n_around=48, n_along=16)
    # add points that exercise the stability paths: a grazing/off-sheet vertex far to the side
    extra = np.array([[-0.01, 0.4, 0.35], [-0.2, 0.0, 0.0]], dtype=np.float32)
    r.set_mesh(np.vstack([v, extra]), f)
    yield r, np.vstack([v, extra]).astype(np.float64)
    ctx.release()


def sheets():
    th = np.radians(40)
    tilt = SheetSurface([-R + R * np.cos(th), 0, -R * np.sin(th)], [np.cos(th), 0, -np.sin(th)], [0, 1, 0])
    push = SheetSurface(np.zeros(3), [1, 0, 0], [0, 1, 0], membrane=Membrane(0.12, 0.12, 0.01, -0.02, 0.04, modes=16))
    return tilt, push


@pytest.mark.parametrize("model", ["none", "flat", "four_triangle", "fine"])
@pytest.mark.parametrize("eye_dy", [0.0, 0.032])
def test_shader_matches_numpy(gl, model, eye_dy):
    r, v = gl
    tilt, push = sheets()
    eye = geometry.EYE + [0.0, eye_dy, 0.0]
    sheet = tilt if model == "flat" else push
    r.set_model(model, sheet if model != "none" else None)
    got, got_ok = r.transform(eye)
    if model == "none":
        want, ok = v, np.ones(len(v), bool)
    elif model == "flat":
        want, ok = correct_vertices(v, eye=eye, sheet_point=tilt.origin, sheet_normal=tilt.normal, return_valid=True, **COM)
    elif model == "four_triangle":
        want, ok = correct_vertices_pushed(v, eye=eye, pushed_point=push.pushed_point, corners=push.corners,
                                           return_valid=True, **COM)
    else:
        want, ok = correct_vertices_fine(v, eye=eye, sheet=push, return_valid=True, **COM)
    assert np.abs(got - want).max() < 1e-6
    np.testing.assert_array_equal(got_ok, ok)
    if model == "four_triangle":
        assert not ok[-2]                      # the off-sheet vertex is flagged in both


def test_headless_render_is_deterministic_and_sized(gl):
    r, _ = gl
    tilt, _ = sheets()
    r.set_model("flat", tilt)
    r.render_pair()
    a = r.read_pair()
    r.render_pair()
    b = r.read_pair()
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    r.set_model("none")
    img = r.render_single(geometry.EYE)
    # proper image: 120 mm x 65.2 mm cylinder (silhouette from the eye) at 2.8 mm / px -> ~998 px
    h_mm = 2 * 0.4 * R / np.sqrt((0.4 + R) ** 2 - R**2) * 1e3
    area = img.sum() * 2.8**2
    assert abs(area - 120.0 * h_mm) / (120.0 * h_mm) < 0.05
    left, right = r.read_pair()
    assert left.shape == (192, 256, 3) and not np.array_equal(left, right)   # stereo: the eyes differ


def test_measurement_camera_flat_correction_within_a_pixel():
    r = StereoRenderer(samples=4, shading=False)
    try:
        v, f = cylinder_mesh()
        r.set_mesh(v, f)
        cam = MeasurementCamera(pixel=0.0007, extent=(0.2, 0.16))
        home = SheetSurface(np.zeros(3), [1, 0, 0], [0, 1, 0])
        r.set_model("none")
        proper = measure_sizes(cam.photograph(r.render_single(geometry.EYE), r.projector, home), cam.pixel)
        # independent geometry: width 120 mm at the middle row, silhouette height from the eye
        assert abs(proper["w"] - 0.120) < 0.0007
        h = 2 * 0.4 * R / np.sqrt((0.4 + R) ** 2 - R**2)
        assert abs(proper["h"] - h) < 0.0007
        tilt, push = sheets()
        shot = {}
        for model in ("none", "flat"):
            r.set_model(model, tilt)
            shot[model] = measure_sizes(cam.photograph(r.render_single(geometry.EYE), r.projector, tilt), cam.pixel)
        err = {m: np.mean([abs(shot[m][k] - proper[k]) for k in "hud"]) for m in shot}
        assert err["none"] > 0.005           # uncorrected: several mm off at 40°
        assert err["flat"] < 0.0007          # corrected: within one projector pixel
    finally:
        r.release()


def test_left_image_is_drawn_for_the_users_left_eye():
    """The user faces −x with +z up, so the left eye is at −y (right-handed frame); a small object 0.3 m behind
    the screen must show uncrossed disparity: its left-eye image lies toward the user's left."""
    forward, up = -np.asarray(geometry.SCREEN_NORMAL, float), np.array([0.0, 0.0, 1.0])
    users_right = np.cross(forward, up)
    left_eye, right_eye = geometry.EYE - 0.032 * users_right, geometry.EYE + 0.032 * users_right
    a = np.array([-0.3, 0.0, 0.0])
    tri = (a + np.array([[0, -0.006, -0.006], [0, 0.006, -0.006], [0, 0.0, 0.008]])).astype(np.float32)
    px = 0.0028
    r = StereoRenderer(Projector.default(256, 192, pixel=px), ipd=0.064, shading=False)
    try:
        r.set_mesh(tri, np.array([[0, 1, 2]], np.int32))
        r.set_model("none")
        r.render_pair()
        left, right = r.read_pair()
    finally:
        r.release()
    col = [np.average(np.arange(256), weights=(im.mean(axis=2) > 127).sum(axis=0)) for im in (left, right)]
    # where each eye sees the object's centroid on the screen (x = 0), and the projector column that lights it:
    # projector image right is the projector's own right, which faces the user: the user's left
    c = tri.mean(axis=0)
    hit = [e + (c - e) * (e[0] / (e[0] - c[0])) for e in (left_eye, right_eye)]
    want = float((hit[0] - hit[1]) @ -users_right) / px
    assert want > 8.0                                       # ~9.8 px of uncrossed disparity
    assert abs((col[0] - col[1]) - want) < 1.0


def test_calibrated_projector_overrides_and_refuses_a_reflection():
    d = Projector.default(320, 240)
    K = d.K.copy()
    K[0, 2] += 5.0
    p = Projector.calibrated(320, 240, K=K.tolist())
    np.testing.assert_array_equal(p.K, K)
    np.testing.assert_array_equal(p.R, d.R)
    np.testing.assert_array_equal(Projector.calibrated(320, 240).K, d.K)
    flipped = d.R @ np.diag([-1.0, 1.0, 1.0])
    with pytest.raises(ValueError, match="mirror_x"):
        Projector.calibrated(320, 240, R=flipped)
    with pytest.raises(ValueError, match="K must be a finite 3x3"):
        Projector.calibrated(320, 240, K=[[1.0, 0.0], [0.0, 1.0]])
