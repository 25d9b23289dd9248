"""The stereo renderer (flexsheet.rendering.stereo_renderer): GLSL correction vs numpy (transform feedback),
the gripped sheet's depth table sampled by the fine shader (its light lands on the identified model's sheet,
the uniform-tension model's does not), deterministic headless render, the left image for the user's left
eye."""

import numpy as np
import pytest

from flexsheet.model import geometry
from flexsheet.model.projector import Projector
from flexsheet.model.sheet import Membrane, SheetSurface
from flexsheet.rendering.correction import correct_vertices, correct_vertices_fine, correct_vertices_pushed
from flexsheet.rendering.stereo_renderer import StereoRenderer, cylinder_draw_mesh, sampled

COM = dict(projector=geometry.PROJECTOR, screen_point=geometry.SCREEN_POINT,
           screen_normal=geometry.SCREEN_NORMAL)
R = geometry.CYLINDER_RADIUS


@pytest.fixture(scope="module")
def gl():
    import moderngl

    ctx = moderngl.create_standalone_context(backend="egl")
    r = StereoRenderer(Projector.default(256, 192, pixel=0.0028), ctx=ctx, shading=False)
    v, f = cylinder_draw_mesh(n_around=48, n_along=16)
    # add points that exercise the stability paths: a grazing/off-sheet vertex far to the side
    extra = np.array([[-0.01, 0.4, 0.35], [-0.2, 0.0, 0.0]], dtype=np.float32)
    r.set_mesh(np.vstack([v, extra]), f)
    yield r, np.vstack([v, extra]).astype(np.float64)
    ctx.release()


def sheets():
    th = np.radians(40)
    tilt = SheetSurface([-R + R * np.cos(th), 0, -R * np.sin(th)], [np.cos(th), 0, -np.sin(th)], [0, 1, 0])
    # any shape reaches the shader as a depth table; numpy corrects for that same sampled shape
    push = SheetSurface(np.zeros(3), [1, 0, 0], [0, 1, 0],
                        membrane=sampled(Membrane(0.12, 0.12, 0.01, -0.02, 0.04, modes=16)))
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
        want, ok = correct_vertices(v, eye=eye, sheet_point=tilt.origin, sheet_normal=tilt.normal,
                                    return_valid=True, **COM)
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


def test_left_image_is_drawn_for_the_users_left_eye():
    """The user faces −x with +z up, so the left eye is at −y (right-handed frame); a small object 0.3 m
    behind the screen must show uncrossed disparity: its left-eye image lies toward the user's left."""
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
    # where each eye sees the object's centroid on the screen (x = 0), and the projector column that
    # lights it: projector image right is the projector's own right, which faces the user: the user's left
    c = tri.mean(axis=0)
    hit = [e + (c - e) * (e[0] / (e[0] - c[0])) for e in (left_eye, right_eye)]
    want = float((hit[0] - hit[1]) @ -users_right) / px
    assert want > 8.0                                       # ~9.8 px of uncrossed disparity
    assert abs((col[0] - col[1]) - want) < 1.0


def _landing_error(r, sheet_drawn, sheet_true, v):
    """Max distance (m) on the imaginary screen, seen from V, between where the light the shader aims for each
    vertex lands on ``sheet_true`` and where the eye expects the vertex."""
    from flexsheet.rendering.correction import land_projector_rays, project_vertices

    scr = dict(screen_point=geometry.SCREEN_POINT, screen_normal=geometry.SCREEN_NORMAL)
    r.set_model("fine", sheet_drawn)
    got, ok = r.transform(geometry.EYE)
    assert ok.all()
    b = project_vertices(got.astype(float), eye=geometry.EYE, **scr)
    c = land_projector_rays(b, geometry.PROJECTOR, sheet_true)
    return np.linalg.norm(project_vertices(c, eye=geometry.EYE, **scr)
                          - project_vertices(v, eye=geometry.EYE, **scr),
                          axis=1).max()


def test_shader_samples_the_gripped_sheet_depth_table(tmp_path):
    """The fine shader draws the identified, gripped sheet model from its depth table: the GLSL correction
    equals numpy's on the same table (2e-6 m), the table's samples are the FEM table's, and the light it aims
    lands on the FEM table's own sheet within 0.1 mm on the screen from 10 to 50 mm; drawn with the
    uniform-tension model (T_v = T_u, what the renderer drew before) it lands > 0.5 mm off at 30 mm and
    more."""
    from flexsheet.model.sheet import SheetSurface
    from flexsheet.model.sheet_model import NominalSheetModel
    from flexsheet.rendering.correction import correct_vertices_fine
    from flexsheet.rendering.state import silhouette_probes

    mesh = {"h_fine": 0.006, "h_coarse": 0.012}
    m = NominalSheetModel(positions=(0.0,), mesh=mesh, cache_dir=str(tmp_path))
    uniform = NominalSheetModel(positions=(0.0,), mesh=mesh, cache_dir=str(tmp_path), tension_ratio=1.0)
    a = 0.12 * 1.04
    r = StereoRenderer(Projector.default(256, 192, pixel=0.0028), shading=False)
    v, f = cylinder_draw_mesh(n_around=48, n_along=16)
    probes = silhouette_probes(v, step=1).astype(np.float32)
    r.set_mesh(probes, np.array([[0, 1, 2]], np.int32))
    try:
        for S, pu, pv in ((0.01, 0.0, 0.0), (0.03, 0.002, -0.001), (0.05, 0.0, 0.0)):
            shp = m.shape(a, S, pu, pv)
            true = SheetSurface(np.zeros(3), [1, 0, 0], [0, 1, 0], a,
                                membrane=m.table(0.04).shape(S, pu, pv, a))
            sheet = SheetSurface(np.zeros(3), [1, 0, 0], [0, 1, 0], a, membrane=shp)
            r.set_model("fine", sheet)
            got, got_ok = r.transform(geometry.EYE)
            want, ok = correct_vertices_fine(probes.astype(float), eye=geometry.EYE,
                                             projector=geometry.PROJECTOR,
                                             screen_point=geometry.SCREEN_POINT,
                                             screen_normal=geometry.SCREEN_NORMAL,
                                             sheet=sheet, return_valid=True)
            assert ok.all()
            np.testing.assert_array_equal(got_ok, ok)
            assert np.abs(got - want).max() < 2e-6
            e_table = _landing_error(r, sheet, true, probes.astype(float))
            assert e_table < 1e-4, (S, e_table)
            old = SheetSurface(np.zeros(3), [1, 0, 0], [0, 1, 0], a, membrane=uniform.shape(a, S, pu, pv))
            e_old = _landing_error(r, old, true, probes.astype(float))
            assert e_old > 5 * e_table and (S < 0.03 or e_old > 5e-4), (S, e_old)
    finally:
        r.release()
