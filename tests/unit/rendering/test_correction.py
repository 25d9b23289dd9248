"""The correction (flexsheet.rendering.correction): Eqs (1)-(6), the 4-triangle and fine corrections, their
stability cases, the model choice and its predicted errors (also against the nominal FEM sheet model)."""

import numpy as np
import pytest

from flexsheet.model import geometry
from flexsheet.model.sheet import Membrane, SheetSurface
from flexsheet.rendering.correction import (
    choose_sheet_model,
    correct_vertices,
    correct_vertices_fine,
    correct_vertices_pushed,
    fan_triangles,
    land_on_triangles,
    land_projector_rays,
    predict_model_errors,
    project_vertices,
)

COM = dict(eye=geometry.EYE, projector=geometry.PROJECTOR, screen_point=geometry.SCREEN_POINT,
           screen_normal=geometry.SCREEN_NORMAL)
R = geometry.CYLINDER_RADIUS


def cylinder_points(n=9):
    a = np.linspace(-1.4, 1.4, n)
    return np.array([[-R + R * np.cos(t), y, R * np.sin(t)] for t in a for y in (-0.06, -0.02, 0.03, 0.06)])


def tilted(theta_deg):
    th = np.radians(theta_deg)
    return SheetSurface([-R + R * np.cos(th), 0, -R * np.sin(th)], [np.cos(th), 0, -np.sin(th)], [0, 1, 0])


def dist_to_lines(x, v, a):
    d = (a - v) / np.linalg.norm(a - v, axis=1, keepdims=True)
    r = x - v
    return np.linalg.norm(r - (r * d).sum(1, keepdims=True) * d, axis=1)


def test_eqs_hand_computed_parallel_sheet():
    # sheet plane x = -0.1 parallel to the screen; V = (0.4, 0, 0), P = (-1, 0, 0), A = (-0.05, 0.02, 0):
    # C = (-0.1, 0.02*10/9, 0); C' = (0, 0.02*(10/9)^2, 0);
    # A' = (-0.05, 0.02*(10/9)^2*9/8, 0) = (-0.05, 1/36, 0)
    out = correct_vertices([[-0.05, 0.02, 0.0]], eye=[0.4, 0, 0], projector=[-1, 0, 0],
                           screen_point=[0, 0, 0],
                           screen_normal=[1, 0, 0], sheet_point=[-0.1, 0, 0], sheet_normal=[2, 0, 0])
    np.testing.assert_allclose(out[0], [-0.05, 1 / 36, 0.0], atol=1e-12)


def test_eqs_hand_computed_tilted_sheet():
    # sheet through the origin with normal (1, 0, 1)/√2, V = (1, 0, 0), P = (-1, 0, 0), A = (-0.2, 0, 0.1)
    # line V-A: (1 - 1.2 s, 0, 0.1 s) meets x + z = 0 at s = 1/1.1 -> C = (-1/11, 0, 1/11)
    # line P-C: (-1 + (10/11) u, 0, u/11) meets x = 0 at u = 1.1 -> C' = (0, 0, 0.1)
    # line V-C': (1 - w, 0, 0.1 w) meets x = -0.2 at w = 1.2 -> A' = (-0.2, 0, 0.12)
    out = correct_vertices([[-0.2, 0.0, 0.1]], eye=[1, 0, 0], projector=[-1, 0, 0], screen_point=[0, 0, 0],
                           screen_normal=[1, 0, 0], sheet_point=[0, 0, 0], sheet_normal=[1, 0, 1])
    np.testing.assert_allclose(out[0], [-0.2, 0.0, 0.12], atol=1e-12)


def test_identity_when_sheet_is_the_screen():
    a = cylinder_points()
    out = correct_vertices(a, sheet_point=[0, 0, 0], sheet_normal=[1, 0, 0], **COM)
    np.testing.assert_allclose(out, a, atol=1e-12)
    assert np.abs(out - a).max() < 1e-12


@pytest.mark.parametrize("theta", [10.0, 30.0, 50.0, -40.0])
def test_flat_light_lands_on_eye_line(theta):
    a = cylinder_points()
    sheet = tilted(theta)
    ah, ok = correct_vertices(a, sheet_point=sheet.origin, sheet_normal=sheet.normal, return_valid=True,
                              **COM)
    assert ok.all()
    b = project_vertices(ah, eye=geometry.EYE, screen_point=[0, 0, 0], screen_normal=[1, 0, 0])
    c = land_projector_rays(b, geometry.PROJECTOR, sheet)
    assert np.abs((c - sheet.origin) @ sheet.normal).max() < 1e-12      # on the sheet
    assert dist_to_lines(c, geometry.EYE, a).max() < 1e-9                   # seen where A is
    assert np.abs(ah - a).max() > 1e-3                                   # and the correction did something


@pytest.mark.parametrize("depth", [0.01, 0.05])
def test_pushed_four_triangle_light_lands_on_eye_line(depth):
    a = cylinder_points()
    home = SheetSurface(np.zeros(3), [1, 0, 0], [0, 1, 0])
    q = np.array([-depth, 0.01, -0.02])
    ah, ok = correct_vertices_pushed(a, pushed_point=q, corners=home.corners, return_valid=True, **COM)
    assert ok.all()
    b = project_vertices(ah, eye=geometry.EYE, screen_point=[0, 0, 0], screen_normal=[1, 0, 0])
    qq, cs, nrm, usable, _ = fan_triangles(q, home.corners, geometry.PROJECTOR)
    c, good, on = land_on_triangles(b, geometry.PROJECTOR, qq, cs, nrm, usable, 0.02)
    assert good.all() and on.all()
    assert dist_to_lines(c, geometry.EYE, a).max() < 1e-9


@pytest.mark.parametrize("depth", [0.01, 0.05])
def test_pushed_fine_light_lands_on_eye_line(depth):
    a = cylinder_points()
    sheet = SheetSurface(np.zeros(3), [1, 0, 0], [0, 1, 0],
                         membrane=Membrane(0.12, 0.12, 0.01, -0.02, depth, modes=16))
    ah, ok = correct_vertices_fine(a, sheet=sheet, return_valid=True, **COM)
    assert ok.all()
    b = project_vertices(ah, eye=geometry.EYE, screen_point=[0, 0, 0], screen_normal=[1, 0, 0])
    c = land_projector_rays(b, geometry.PROJECTOR, sheet)
    rel = c - sheet.origin
    w = sheet.membrane.deflection(rel @ sheet.axis_u, rel @ sheet.axis_v)
    np.testing.assert_allclose(-(rel @ sheet.normal), w, atol=1e-9)     # on the membrane
    assert dist_to_lines(c, geometry.EYE, a).max() < 1e-8


def test_grazing_rays_are_left_uncorrected_and_flagged():
    # sheet normal almost perpendicular to the rays V-A: |cos| < min_cos
    a = np.array([[-0.01, 0.0, 0.0], [-0.01, 0.0, 0.3]])
    sheet_n = np.array([np.cos(np.radians(89.5)), 0, np.sin(np.radians(89.5))])
    out, ok = correct_vertices(a, eye=[0.4, 0, 0.0], projector=[-1, 0, -0.25], screen_point=[0, 0, 0],
                               screen_normal=[1, 0, 0], sheet_point=[-0.001, 0, 0], sheet_normal=sheet_n,
                               return_valid=True)
    assert np.all(np.isfinite(out))
    assert not ok[0]
    np.testing.assert_array_equal(out[0], a[0])
    # a strict min_cos = 0 corrects the same ray (huge but finite shift)
    out0, ok0 = correct_vertices(a[:1], eye=[0.4, 0, 0.0], projector=[-1, 0, -0.25], screen_point=[0, 0, 0],
                                 screen_normal=[1, 0, 0], sheet_point=[-0.001, 0, 0], sheet_normal=sheet_n,
                                 min_cos=0.0, return_valid=True)
    assert np.all(np.isfinite(out0))


def test_ray_missing_the_sheet_is_flagged_but_finite():
    home = SheetSurface(np.zeros(3), [1, 0, 0], [0, 1, 0])
    a = np.array([[-0.01, 0.0, 0.0], [-0.01, 0.5, 0.3]])              # second one far outside the sheet
    out, ok = correct_vertices_pushed(a, pushed_point=[-0.02, 0, 0], corners=home.corners, return_valid=True,
                                      **COM)
    assert ok.tolist() == [True, False]
    assert np.all(np.isfinite(out))
    sheet = SheetSurface(np.zeros(3), [1, 0, 0], [0, 1, 0],
                         membrane=Membrane(0.12, 0.12, 0, 0, 0.02, modes=16))
    out, ok = correct_vertices_fine(a, sheet=sheet, return_valid=True, **COM)
    assert ok.tolist() == [True, False]
    assert np.all(np.isfinite(out))


def test_eye_on_wrong_side_raises():
    with pytest.raises(ValueError, match="wrong side"):
        correct_vertices(cylinder_points(), sheet_point=[0.5, 0, 0], sheet_normal=[1, 0, 0], **COM)
    with pytest.raises(ValueError, match="wrong side"):
        correct_vertices(cylinder_points(), sheet_point=[0, 0, 0], sheet_normal=[-1, 0, 0], **COM)
    far = SheetSurface(np.array([0.6, 0, 0]), [1, 0, 0], [0, 1, 0])
    with pytest.raises(ValueError, match="wrong side"):
        correct_vertices_pushed(cylinder_points(), pushed_point=[0.55, 0, 0], corners=far.corners, **COM)


def test_degenerate_triangles_and_vanishing_push():
    a = cylinder_points()
    home = SheetSurface(np.zeros(3), [1, 0, 0], [0, 1, 0])
    flat = correct_vertices(a, sheet_point=[0, 0, 0], sheet_normal=[1, 0, 0], **COM)
    for S in (1e-9, 0.0):
        out = correct_vertices_pushed(a, pushed_point=[-S, 0, 0], corners=home.corners, **COM)
        np.testing.assert_allclose(out, flat, atol=1e-6)
    # pushed point on a corner: two triangles have zero area and are skipped; result stays finite
    out, ok = correct_vertices_pushed(a, pushed_point=home.corners[0], corners=home.corners,
                                      return_valid=True,
                                      **COM)
    assert np.all(np.isfinite(out)) and ok.any()
    with pytest.raises(ValueError, match="degenerate"):
        correct_vertices_pushed(a, pushed_point=[0, 0, 0], corners=np.zeros((4, 3)), **COM)
    m = Membrane(0.12, 0.12, 0, 0, 0.0)
    assert np.all(m.coef == 0)
    out = correct_vertices_fine(a, sheet=SheetSurface(np.zeros(3), [1, 0, 0], [0, 1, 0], membrane=m), **COM)
    np.testing.assert_allclose(out, flat, atol=1e-9)


@pytest.mark.parametrize("field", ["eye", "projector", "sheet_point", "sheet_normal", "vertices"])
def test_nan_pose_raises_naming_the_field(field):
    kw = dict(COM, sheet_point=np.zeros(3), sheet_normal=np.array([1.0, 0, 0]))
    a = cylinder_points()
    if field == "vertices":
        a = a.copy()
        a[3, 1] = np.nan
    else:
        kw[field] = np.array([np.nan, 0.0, 0.0])
    with pytest.raises(ValueError, match=field):
        correct_vertices(a, **kw)


def test_nan_clamp_pose_raises():
    T = np.eye(4)
    T[0, 3] = np.nan
    with pytest.raises(ValueError, match="T_left"):
        SheetSurface.from_clamps(T, np.eye(4))
    with pytest.raises(ValueError, match="pushed_point"):
        correct_vertices_pushed(cylinder_points(), pushed_point=[np.nan, 0, 0],
                                corners=SheetSurface(np.zeros(3), [1, 0, 0], [0, 1, 0]).corners, **COM)


def test_choose_model_picks_cheapest_meeting_target():
    table = {"none": [(0.0, 0.0), (0.05, 0.01)], "flat": [(0.0, 0.0), (0.05, 0.01)],
             "four_triangle": [(0.0, 0.0), (0.05, 0.002)], "fine": [(0.0, 0.0), (0.05, 0.0001)]}
    assert choose_sheet_model(0.0, table) == "none"
    assert choose_sheet_model(0.0, table, models=("flat", "four_triangle", "fine")) == "flat"
    assert choose_sheet_model(0.0125, table, target=0.001) == "four_triangle"   # 4-tri 0.0005 there
    assert choose_sheet_model(0.05, table, target=0.0007) == "fine"
    assert choose_sheet_model(0.05, table, target=1e-6) == "fine"               # none meets: least error
    with pytest.raises(ValueError, match="depth"):
        choose_sheet_model(float("nan"), table)


def test_predicted_errors_grow_with_depth_and_fine_is_reference():
    home = SheetSurface(np.zeros(3), [1, 0, 0], [0, 1, 0])

    def ref(s, depth):                     # any membrane-like shape pushed at the centre
        return Membrane(s.half_span, s.half_width, 0.0, 0.0, depth, modes=16)

    p1 = predict_model_errors(0.01, probes=cylinder_points(), sheet=home, reference=ref, **COM)
    p5 = predict_model_errors(0.05, probes=cylinder_points(), sheet=home, reference=ref, **COM)
    assert p1["fine"] < 1e-9 and p5["fine"] < 1e-9
    assert p5["none"] > p1["none"] > 0.0
    assert p5["four_triangle"] < p5["none"]
    p0 = predict_model_errors(0.0, probes=cylinder_points(), sheet=home, reference=None, **COM)
    assert max(p0.values()) < 1e-9                       # unpushed: every model is the flat correction


# ------------------------------------------------------------- the nominal FEM sheet model (fine shader form)
@pytest.fixture(scope="module")
def nominal_model(tmp_path_factory):
    from flexsheet.model.sheet_model import NominalSheetModel

    # centre-contact table on a coarse mesh (~2 s); the experiment and the node use the default mesh
    return NominalSheetModel(positions=(0.0,), mesh={"h_fine": 0.006, "h_coarse": 0.012},
                             cache_dir=str(tmp_path_factory.mktemp("fem")))


def test_fine_correction_on_the_fitted_shape_lands_on_eye_line(nominal_model):
    a = 0.12 * 1.04
    sheet = SheetSurface(np.zeros(3), [1, 0, 0], [0, 1, 0], a,
                         membrane=nominal_model.shape(a, 0.05, 0.0, 0.0))
    pts = cylinder_points()
    ah, ok = correct_vertices_fine(pts, sheet=sheet, return_valid=True, **COM)
    assert ok.all()
    b = project_vertices(ah, eye=geometry.EYE, screen_point=[0, 0, 0], screen_normal=[1, 0, 0])
    c = land_projector_rays(b, geometry.PROJECTOR, sheet)
    assert dist_to_lines(c, geometry.EYE, pts).max() < 1e-7


def test_predicted_errors_against_the_nominal_model(nominal_model):
    home = SheetSurface(np.zeros(3), [1, 0, 0], [0, 1, 0], 0.12 * 1.04)

    def ref(s, depth):
        return nominal_model.shape(s.half_span, depth, 0.0, 0.0, s.half_width)

    p_series = predict_model_errors(0.05, probes=cylinder_points(), sheet=home, **COM,
                                    reference=lambda s,
                                    d: Membrane(s.half_span, s.half_width, 0.0, 0.0, d, modes=16))
    p_fem = predict_model_errors(0.05, probes=cylinder_points(), sheet=home, reference=ref, **COM)
    assert p_fem["fine"] < 1e-9                        # the fine model now carries the reference shape
    # the conical FEM dent is closer to the 4-triangle pyramid than the series membrane is
    assert p_fem["four_triangle"] < p_series["four_triangle"]
    assert p_fem["none"] > p_series["none"] * 0.5
