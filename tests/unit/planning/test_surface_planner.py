"""The surface planner (flexsheet.planning.surface_planner): encountered placement, rolling without slip,
pushing, limits, the stability cases, and clamps and tension from the sheet's geometry."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from flexsheet.model import geometry
from flexsheet.model.motion_limits import MotionLimits
from flexsheet.model.shapes import make_shape, paper_cylinder
from flexsheet.model.sheet import (
    clamp_half_span,
    clamp_points,
    clamp_poses,
)
from flexsheet.model.tension import SheetMaterial, stiffness, tension
from flexsheet.model.vec import cross, dot, norm, sub
from flexsheet.planning.limits import ReachModel
from flexsheet.planning.planner_config import PlannerConfig
from flexsheet.planning.surface_planner import SurfacePlanner

R = geometry.CYLINDER_RADIUS
DT = 1.0 / 48.0


def _rest(x, n=96):
    """``x`` (N,) with its last value held ``n`` samples more: the pose filter settles on a resting finger."""
    return np.r_[x, np.full(n, x[-1])]


def _stroke(planner, shape, angles, h=None, depth=0.0005, t0=0.0):
    plans = []
    for k, a in enumerate(angles):
        p = shape.point_at(a, 0.0 if h is None else h[k], R - depth)
        plans.append(planner.update(t0 + k * DT, p))
    return plans


def test_placement_is_tangent_plane_at_centre_ray_hit():
    c = paper_cylinder()
    pl = SurfacePlanner(c)
    p = (-R + 0.08 * math.cos(0.4), 0.0, -0.08 * math.sin(0.4))   # away from the object
    plan = pl.update(0.0, p)
    A = c.point_at(0.4)
    assert not plan.touching and plan.status == "ok"
    assert norm(sub(plan.contact, A)) < 1e-12 and norm(sub(plan.origin, A)) < 1e-12
    n = plan.normal
    assert abs(dot(n, sub(A, c.c)) - R) < 1e-12              # tangent plane at A
    assert abs(dot(plan.axis_u, n)) < 1e-12 and plan.axis_u[1] > 0.99
    # clamps match flexsheet.model.sheet.clamp_poses
    Tl, Tr = plan.clamp_matrices()
    El, Er = clamp_poses(np.array(plan.origin), np.array(plan.normal), np.array(plan.axis_u), plan.stretch)
    assert np.allclose(Tl, El, atol=1e-12) and np.allclose(Tr, Er, atol=1e-12)


def test_rolling_without_slip_arc_equals_sheet_length():
    c = paper_cylinder()
    pl = SurfacePlanner(c)
    angles = np.radians(np.linspace(0, 60, 481))
    plans = _stroke(pl, c, -_rest(angles))   # point_at positive angles go down (a × e1 = −z)
    last = plans[-1]
    arc = R * math.radians(60)
    assert last.touching and last.status == "ok"
    assert math.hypot(*last.offset) == pytest.approx(arc, rel=1e-9)
    # A' (the sheet's material point that first touched A) is at distance arc from B along the sheet
    Ap = sub(last.origin, (0.0, 0.0, 0.0))
    B = last.contact
    assert norm(sub(B, Ap)) == pytest.approx(arc, rel=1e-9)
    assert abs(dot(sub(B, Ap), last.normal)) < 1e-12          # A'B lies in the sheet plane
    assert dot(last.normal, sub(B, c.c)) == pytest.approx(R)  # tangent at B


def test_two_d_stroking_around_and_along_is_path_independent_on_cylinder():
    c = paper_cylinder()
    n = 200
    a1 = np.r_[np.linspace(0, 0.5, n), np.full(n, 0.5)]
    h1 = np.r_[np.zeros(n), np.linspace(0, 0.03, n)]
    a2 = np.r_[np.zeros(n), np.linspace(0, 0.5, n)]
    h2 = np.r_[np.linspace(0, 0.03, n), np.full(n, 0.03)]
    p1 = _stroke(SurfacePlanner(c), c, _rest(a1), _rest(h1))[-1]
    p2 = _stroke(SurfacePlanner(c), c, _rest(a2), _rest(h2))[-1]
    assert norm(sub(p1.origin, p2.origin)) < 1e-9            # cylinder is developable: no holonomy
    assert p1.offset == pytest.approx(p2.offset, abs=1e-9)
    assert abs(p1.offset[0]) == pytest.approx(0.03, abs=1e-9)


def test_stroking_on_sphere_keeps_tangent_and_rolls_geodesic():
    s = make_shape("sphere", {"center": (-0.04, 0.0, 0.0), "radius": 0.04})
    pl = SurfacePlanner(s)
    for k, a in enumerate(_rest(np.linspace(0, 0.6, 300))):
        p = (-0.04 + 0.0395 * math.cos(a), 0.0395 * math.sin(a), 0.0)
        plan = pl.update(k * DT, p)
    assert plan.touching
    assert math.hypot(*plan.offset) == pytest.approx(0.04 * 0.6, rel=1e-6)
    assert dot(plan.normal, sub(plan.contact, s.c)) == pytest.approx(0.04)


def test_pushing_keeps_tangent_pose_and_reports_depth():
    c = paper_cylinder()
    pl = SurfacePlanner(c)
    pl.update(0.0, c.point_at(0.3, 0.0, R + 0.0005))
    base = pl.update(DT, c.point_at(0.3, 0.0, R - 0.0005))
    for k, d in enumerate(np.linspace(0.0005, 0.01, 40)):
        plan = pl.update((k + 2) * DT, c.point_at(0.3, 0.0, R - d))
    assert plan.touching and plan.depth == pytest.approx(0.01)
    assert norm(sub(plan.contact, c.point_at(0.3))) < 1e-12
    assert norm(sub(plan.origin, base.origin)) < 1e-12 and norm(sub(plan.normal, base.normal)) < 1e-12


def test_stroke_and_push_combined():
    c = paper_cylinder()
    pl = SurfacePlanner(c)
    angles = _rest(np.linspace(0, 0.5, 300))
    depth = _rest(0.004 * np.sin(np.linspace(0, math.pi, 300)) + 0.0005)
    for k, (a, d) in enumerate(zip(angles, depth, strict=False)):
        plan = pl.update(k * DT, c.point_at(a, 0.0, R - d))
    assert plan.touching and math.hypot(*plan.offset) == pytest.approx(R * 0.5, rel=1e-9)


def test_axis_singularity_holds_last_normal():
    c = paper_cylinder()
    pl = SurfacePlanner(c)
    pl.update(0.0, c.point_at(0.2, 0.0, R - 0.001))
    n0 = pl.last.normal
    plan = pl.update(DT, (-R, 0.0, 0.0))       # finger pushed onto the axis
    assert "hold:singular" in plan.status
    assert norm(sub(plan.normal, n0)) < 1e-9 or "rate_limited" in plan.status
    assert all(math.isfinite(x) for x in plan.origin + plan.normal)


def test_inside_object_projects_and_touches():
    c = paper_cylinder()
    pl = SurfacePlanner(c)
    plan = pl.update(0.0, (-R + 0.5 * R * math.cos(0.2), 0.0, -0.5 * R * math.sin(0.2)))
    assert plan.touching and plan.depth == pytest.approx(0.5 * R)
    assert norm(sub(plan.contact, c.point_at(0.2))) < 1e-12


def test_past_end_cap_rolls_over_rim_within_limits():
    c = paper_cylinder()
    lim = MotionLimits()
    pl = SurfacePlanner(c, PlannerConfig(limits=lim))
    ys = np.r_[np.linspace(0.0, 0.09, 400), np.full(200, 0.09)]
    plans = [pl.update(k * DT, (0.0005, y, 0.0)) for k, y in enumerate(ys)]
    contacts = [norm(sub(a.contact, b.contact)) for a, b in zip(plans, plans[1:], strict=False)]
    speeds = [norm(sub(a.origin, b.origin)) / DT for a, b in zip(plans, plans[1:], strict=False)]
    assert max(contacts) < 0.002                 # the contact wraps over the rim continuously
    assert max(speeds) <= lim.v_max + 1e-9      # the sheet swinging about the rim is rate-limited
    assert all("hold" not in p.status for p in plans)
    # with the default arm bases the sheet cannot face the end cap: reported, arms held inside reach
    assert "unreachable" in plans[-1].status and ReachModel().reachable(plans[-1].left, plans[-1].right)[0]
    # with a larger workspace it settles tangent to the cap
    pl = SurfacePlanner(c, PlannerConfig(reach=ReachModel(reach_max=0.8, reach_min=0.0)))
    plans = [pl.update(k * DT, (0.0005, y, 0.0)) for k, y in enumerate(ys)]
    assert plans[-1].normal[1] > 0.99 and plans[-1].status == "ok"


def test_box_edge_sharp_is_rate_limited_rounded_is_not():
    for radius, expect_limited in ((0.0, True), (0.01, False)):
        b = make_shape("box", {"center": (-0.03, 0, 0), "half_extents": (0.03, 0.03, 0.03), "radius": radius})
        pl = SurfacePlanner(b)
        statuses = []
        for k, z in enumerate(np.linspace(0.0, 0.06, 600)):
            statuses.append(pl.update(k * DT, (0.01, 0.0, z)).status)
        assert any("rate_limited" in s for s in statuses) == expect_limited, radius


def test_sudden_jump_is_reacquired_and_ramped():
    c = paper_cylinder()
    lim = MotionLimits()
    pl = SurfacePlanner(c, PlannerConfig(limits=lim))
    for k in range(10):
        pl.update(k * DT, c.point_at(0.0, 0.0, R - 0.0005))
    o_prev = pl.last.origin
    plan = pl.update(10 * DT, c.point_at(-1.0, 0.03, R + 0.01))     # marker re-acquired far away
    assert "reacquired" in plan.status and "rate_limited" in plan.status
    assert norm(sub(plan.origin, o_prev)) <= lim.a_max * DT * DT + 1e-12
    speeds = []
    for k in range(11, 200):
        p = pl.update(k * DT, c.point_at(-1.0, 0.03, R + 0.01))
        speeds.append(norm(sub(p.origin, o_prev)) / DT)
        o_prev = p.origin
    assert max(speeds) <= lim.v_max + 1e-9
    assert norm(sub(p.contact, c.point_at(-1.0, 0.03))) < 1e-9 and p.status == "ok"


@pytest.mark.parametrize("bad", [(float("nan"), 0.0, 0.0), (0.0, float("inf"), 0.0), (1.0, 2.0), "xyz", None])
def test_invalid_input_holds_last_safe_pose(bad):
    c = paper_cylinder()
    pl = SurfacePlanner(c)
    assert pl.update(0.0, bad) is None                      # nothing to hold yet, no exception
    good = pl.update(0.0, (0.01, 0.0, 0.0))
    plan = pl.update(DT, bad)
    assert plan.status == "hold:invalid_fingertip"
    assert plan.origin == good.origin and plan.left == good.left and plan.normal == good.normal
    assert pl.counts["hold:invalid_fingertip"] == 2
    stale = pl.update(0.0, (0.01, 0.0, 0.0))
    assert stale.status == "hold:stale_fingertip"


def test_unreachable_is_reported_and_not_clipped():
    c = make_shape("plane")
    reach = ReachModel(reach_max=0.45)
    pl = SurfacePlanner(c, PlannerConfig(reach=reach, jump_distance=1.0))
    ok = pl.update(0.0, (0.01, 0.0, 0.0))
    assert ok.status == "ok" and ok.reach_margin > 0
    o = ok.origin
    for k in range(1, 300):                                   # finger walks up, sheet follows until the limit
        plan = pl.update(k * DT, (0.01, 0.0, 0.0005 * k))
        if "unreachable" in plan.status:
            break
        o = plan.origin
    assert "unreachable" in plan.status and plan.reach_margin < 0
    assert plan.origin == o                                   # held the last reachable pose, exactly
    assert reach.reachable(plan.left, plan.right)[0]
    assert plan.contact[2] == pytest.approx(0.0005 * k)      # the requested contact is still reported


def test_object_stiffer_than_sheet_is_reported():
    pl = SurfacePlanner(paper_cylinder())
    plan = pl.update(0.0, (0.01, 0.0, 0.0), object_stiffness=5000.0)
    assert "object_stiffer_than_sheet" in plan.status
    assert plan.stiffness < 5000.0 and plan.stretch <= pl.cfg.material.max_stretch
    for k in range(1, 40):                       # stretch is rate-limited back down
        plan = pl.update(k * DT, (0.01, 0.0, 0.0), object_stiffness=20.0)
    assert plan.status == "ok"
    assert plan.stiffness == pytest.approx(20.0, rel=1e-6)


def test_sheet_edge_slip_is_reported():
    c = make_shape("plane")
    pl = SurfacePlanner(c)
    for k, y in enumerate(np.linspace(0.0, 0.2, 400)):
        plan = pl.update(k * DT, (-0.0005, y, 0.0))
    assert "slip:sheet_edge" in plan.status
    assert abs(plan.offset[0]) <= 0.5 * 0.24 * (1 + plan.stretch) - pl.cfg.sheet_margin + 1e-12


def test_cross_product_convention_axis_v():
    plan = SurfacePlanner(paper_cylinder()).update(0.0, (0.01, 0.0, 0.0))
    assert (plan.axis_v == pytest.approx(cross(plan.normal, plan.axis_u))
            and plan.axis_v[2] == pytest.approx(1.0))


def test_planner_clamps_and_tension_use_the_sheet_geometry():
    pl = SurfacePlanner(paper_cylinder())
    plan = pl.update(0.0, (0.01, 0.0, 0.0), object_stiffness=20.0)
    a = clamp_half_span(plan.stretch)
    assert plan.left == pytest.approx(tuple(np.add(plan.origin, np.multiply(a, plan.axis_u))), abs=1e-15)
    assert (plan.left, plan.right) == clamp_points(plan.origin, plan.axis_u, plan.stretch)
    Tl, Tr = plan.clamp_matrices()
    assert (Tl[:3, 3] == pytest.approx(plan.left, abs=1e-15)
            and Tr[:3, 3] == pytest.approx(plan.right, abs=1e-15))
    # string model at the centre: k = T·w·2/a with a the clamp half span
    mat = SheetMaterial()
    assert (stiffness(plan.stretch, mat)
            == pytest.approx(tension(plan.stretch, mat) * mat.contact_width * 2 / a))
    assert plan.stiffness == pytest.approx(20.0, rel=1e-6)


def test_a_given_object_press_is_matched_in_force_along_the_press():
    """With the object's press (force at a depth) given, the planned stretch makes the identified sheet's
    force at the finger's depth the object's, extrapolated by its stiffness; shallower than FORCE_DEPTH, and
    without a press, the stiffness is matched instead."""
    from flexsheet.model.tension import press_force
    from flexsheet.planning.surface_planner import FORCE_DEPTH

    rng = np.random.default_rng(8)
    mat = SheetMaterial(contact_width=0.023, contact_growth=2.7, stretching=1.7e4, strain_offset=0.02,
                        max_force=60.0)
    c = paper_cylinder()
    for d in (0.004, 0.008, 0.012):
        k = float(rng.uniform(60.0, 140.0))
        f_obj, d_obj = float(k * d * rng.uniform(0.6, 0.9)), d - 0.0005      # the FEM's solve, 0.5 mm earlier
        pl = SurfacePlanner(c, PlannerConfig(material=mat))
        pl.update(0.0, c.point_at(0.3, 0.0, R + 0.0005), k)
        plan = None
        for i, dd in enumerate(np.linspace(0.0, d, 30)):
            plan = pl.update((i + 1) * DT, c.point_at(0.3, 0.0, R - dd), k, object_press=(f_obj, d_obj))
        assert (plan.depth == pytest.approx(d) and plan.depth >= FORCE_DEPTH
                and plan.status == "ok"), plan.status
        want = f_obj + k * (d - d_obj)
        assert press_force(plan.stretch, mat, pl.s[0], d) == pytest.approx(want, rel=1e-6)
        # the same push matched in stiffness presents the slope, and a different force
        ps = SurfacePlanner(c, PlannerConfig(material=mat))
        ps.update(0.0, c.point_at(0.3, 0.0, R + 0.0005), k)
        for i, dd in enumerate(np.linspace(0.0, d, 30)):
            q = ps.update((i + 1) * DT, c.point_at(0.3, 0.0, R - dd), k)
        assert q.stiffness == pytest.approx(k, rel=1e-6)
        assert abs(press_force(q.stretch, mat, ps.s[0], d) / want - 1.0) > 0.02
    # a malformed press is ignored (stiffness matched), never raised
    pl = SurfacePlanner(c, PlannerConfig(material=mat))
    pl.update(0.0, c.point_at(0.3, 0.0, R - 0.005), 90.0)
    plan = pl.update(DT, c.point_at(0.3, 0.0, R - 0.005), 90.0, object_press=(float("nan"), 0.005))
    assert plan.stiffness == pytest.approx(90.0, rel=1e-6)


def test_the_arms_pull_limit_caps_the_clamp_force():
    from flexsheet.model.tension import clamp_force

    c = paper_cylinder()
    pl = SurfacePlanner(c)
    pl.set_pull_limit(25.0)
    plan = None
    for i in range(20):
        plan = pl.update(i * DT, c.point_at(0.3, 0.0, R - 0.004), 400.0)        # stiffer than any sheet
    assert clamp_force(plan.stretch, pl.cfg.material) == pytest.approx(25.0, rel=1e-6)
    assert "object_stiffer_than_sheet" in plan.status
    pl.set_pull_limit(None)                                                    # lifted: the material's 40 N
    for i in range(20, 400):
        plan = pl.update(i * DT, c.point_at(0.3, 0.0, R - 0.004), 400.0)
    assert clamp_force(plan.stretch, pl.cfg.material) == pytest.approx(pl.cfg.material.max_force, rel=1e-6)
    with pytest.raises(ValueError, match="pull limit"):
        pl.set_pull_limit(float("nan"))


def test_with_the_objects_force_depth_table_its_mapped_force_is_matched_at_every_depth():
    """With the object's table set, the stretch makes the identified sheet's force at the finger's depth (at
    least TABLE_MIN_DEPTH) the table's force there, mapped by stiffness_scale and contrast_gain; the given
    stiffness and press are not used."""
    from flexsheet.model.force_depth import ForceDepth
    from flexsheet.model.tension import press_force
    from flexsheet.planning.surface_planner import TABLE_MIN_DEPTH

    c = paper_cylinder()
    ang = np.linspace(-0.2, 1.2, 8)
    pts = np.array([c.point_at(a, 0.0) for a in ang])
    nrm = np.array([[math.cos(a), 0.0, math.sin(a)] for a in ang])
    depths = np.linspace(0.0, 0.03, 61)
    force = np.array([(900.0 + 300.0 * (i == 4)) * depths ** 1.5 for i in range(8)])
    table = ForceDepth(pts, nrm, tuple(f"p{i}" for i in range(8)), depths, force)
    mat = SheetMaterial(contact_width=0.033, contact_growth=2.0, own_stiffness=0.5, own_growth=290.0)
    checked = 0
    for gain in (1.0, 2.5):
        pl = SurfacePlanner(c, PlannerConfig(material=mat, stiffness_scale=0.8, contrast_gain=gain))
        pl.set_force_depth(table)
        pl.update(0.0, c.point_at(0.3, 0.0, R + 0.0005), 55.0)
        for i, dd in enumerate(np.linspace(0.0, 0.008, 40)):
            plan = pl.update((i + 1) * DT, c.point_at(0.3, 0.0, R - dd), 55.0, object_press=(5.0, 0.001))
            d = max(plan.depth, TABLE_MIN_DEPTH)
            want, k = table.mapped(plan.contact, d, 0.8, gain)
            assert plan.k_source == "table" and plan.object_stiffness == pytest.approx(k)
            if not plan.status.startswith("object_"):
                assert (press_force(plan.stretch, mat, pl.s[0], d)
                        == pytest.approx(want, rel=1e-6)), (dd, plan.status)
                checked += 1
    assert checked >= 20
    pl.set_force_depth(None)                                      # back to the stiffness given
    plan = pl.update(50 * DT, c.point_at(0.3, 0.0, R - 0.001), 55.0)
    assert plan.k_source == "given" and plan.object_stiffness == pytest.approx(0.8 * 55.0)


def test_a_held_pose_keeps_the_sheet_still_while_its_stretch_follows_the_push_within_the_clamp_speed():
    """A lost head (hold_pose): the sheet's pose stays the last plan's, the stretch moves toward what update
    would ask at the new depth, no faster than the clamps' 0.25 m/s near a head; a refused sample is held
    whole. The object stiffens with depth (given press and slope), so the request changes along the push."""
    from flexsheet.model.tension import press_force

    k0 = float(np.random.default_rng(31).uniform(10.0, 18.0))

    def push(planner, i, d, hold):
        p = c.point_at(0.3, 0.0, R - d)
        k, press = k0 * (1.0 + d / 0.004), (k0 * (d + d * d / 0.008), d)
        if hold:
            return planner.hold_pose("hold:head_lost", i * DT, p, k, object_press=press)
        return planner.update(i * DT, p, k, object_press=press)

    c = paper_cylinder()
    mat = SheetMaterial()
    pl, ref = SurfacePlanner(c), SurfacePlanner(c)
    for p_ in (pl, ref):
        push(p_, 0, 0.0, False)
        base = push(p_, 1, 0.001, False)
    rate = pl.hold_stretch_rate()
    assert rate * 0.5 * mat.size == pytest.approx(min(pl.cfg.limits.stretch_rate * 0.5 * mat.size, 0.25))
    prev, steps = base, 0
    for i in range(2, 40):                       # the finger pushes to 12 mm at once and stays
        plan, want = push(pl, i, 0.012, True), push(ref, i, 0.012, False)
        assert plan.status == "hold:head_lost" and plan.depth == pytest.approx(0.012)
        assert plan.origin == base.origin and plan.normal == base.normal and plan.axis_u == base.axis_u
        assert abs(plan.stretch - prev.stretch) <= rate * DT + 1e-12          # each clamp ≤ 0.25 m/s
        clamp_speed = max(norm(sub(plan.left, prev.left)), norm(sub(plan.right, prev.right))) / DT
        assert clamp_speed <= 0.25 + 1e-9
        steps += plan.stretch != prev.stretch
        prev = plan
    assert steps >= 2                                 # the jump needed more than one step at that rate
    # the stretch reached what tracking asks at 12 mm: the same force there
    assert plan.stretch > base.stretch + rate * DT and want.status == "ok"
    assert press_force(plan.stretch, mat, base.offset[0], 0.012) == pytest.approx(
        press_force(want.stretch, mat, want.offset[0], 0.012), rel=0.01)
    assert pl.counts["hold:head_lost"] == 38
    # a request the sheet cannot meet says so, as tracking does
    stiff = pl.hold_pose("hold:head_lost", 41 * DT, c.point_at(0.3, 0.0, R - 0.012), 5000.0)
    assert stiff.status == "hold:head_lost;object_stiffer_than_sheet"
    plan = stiff
    # a refused sample (NaN) holds the whole last plan
    held = pl.hold_pose("hold:head_lost", 100.0, (math.nan, 0.0, 0.0), k0)
    assert held.stretch == plan.stretch and held.origin == plan.origin and held.status == "hold:head_lost"


def test_the_stretch_meets_the_force_where_on_the_sheet_the_finger_presses():
    """With the sheet's position terms identified, the stretch asked for a press 40 mm along the clamp line
    and about 25 mm across (rolled there by a diagonal stroke) meets the object's force with the model at that
    contact, and differs from the stretch the band alone would ask there."""
    from flexsheet.model.tension import press_force

    rng = np.random.default_rng(12)
    mat = SheetMaterial(contact_width=0.023, contact_growth=2.7, stretching=1.7e4, strain_offset=0.02,
                        position_u=float(rng.uniform(0.2, 0.4)), position_v=float(rng.uniform(-0.6, -0.4)))
    c = paper_cylinder()
    k, d = 80.0, 0.006
    f_obj = k * d

    def stroke(m):
        pl = SurfacePlanner(c, PlannerConfig(material=m))
        pl.update(0.0, c.point_at(0.3, 0.0, R + 0.0005), k)
        for i, (a, h) in enumerate(zip(np.linspace(0.3, 1.0, 60), np.linspace(0.0, 0.04, 60), strict=True)):
            plan = pl.update((i + 1) * DT, c.point_at(a, h, R - d), k, object_press=(f_obj, d))
        return pl, plan

    pl, plan = stroke(mat)
    su, sv = pl.s
    assert (abs(su) > 0.03 and abs(sv) > 0.02 and plan.touching
            and "object" not in plan.status), (pl.s, plan.status)
    assert press_force(plan.stretch, mat, su, d, sv) == pytest.approx(f_obj, rel=1e-6)
    band = replace(mat, position_u=0.0, position_v=0.0)
    _, plan0 = stroke(band)
    assert abs(plan.stretch / plan0.stretch - 1.0) > 0.01
