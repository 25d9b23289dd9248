"""The landing the application's mark predicts (flexsheet.planning.landing) and the planner's sheet waiting
there: tangent at the mark, offset outside, blended to the fingertip near the surface, turned around the
object and never through it, and unchanged without a mark."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from flexsheet.model.shapes import make_shape, paper_cylinder
from flexsheet.model.vec import dot, norm, sub
from flexsheet.planning.landing import Landing, clearance, smoothstep
from flexsheet.planning.planner_config import PlannerConfig
from flexsheet.planning.surface_planner import SurfacePlanner

DT = 1.0 / 48.0
CFG = PlannerConfig(use_mark=True)
CYL = paper_cylinder()
R = CYL.R


def _on(phi: float, out: float = 0.0) -> tuple:
    """The cylinder's point at angle ``phi`` rad (0: facing the user, + toward +z), ``out`` m outside."""
    c = CYL.c
    return (c[0] + (R + out) * math.cos(phi), 0.0, c[2] + (R + out) * math.sin(phi))


def _normal(phi: float) -> tuple:
    return (math.cos(phi), 0.0, math.sin(phi))


def _deg(a, b) -> float:
    return math.degrees(math.acos(max(-1.0, min(1.0, dot(a, b)))))


# ------------------------------------------------------------------------------------------------ Landing
def test_the_marks_weight_and_the_lifts_share_rise_from_0_to_1_over_their_bands():
    ld = Landing(CYL, CFG)
    t, b = CFG.touch_distance, CFG.preposition_blend
    assert ld.weight(-0.001) == 0.0 and ld.weight(0.0) == 0.0 and ld.weight(t) == 1.0
    assert ld.weight(0.5 * t) == pytest.approx(0.5)
    assert ld.lift_share(t) == 0.0 and ld.lift_share(t + b) == 1.0 and ld.lift_share(0.03) == 1.0
    assert ld.lift_share(t + 0.5 * b) == pytest.approx(0.5)
    for f in (ld.weight, ld.lift_share):
        ws = [f(0.0005 * k) for k in range(25)]
        assert all(w1 >= w0 for w0, w1 in zip(ws, ws[1:], strict=False))
    assert smoothstep(0.25) == pytest.approx(0.15625)


def test_a_malformed_mark_is_refused_and_a_hidden_one_forgets_the_mark():
    ld = Landing(CYL, CFG)
    with pytest.raises(ValueError, match="finite"):
        ld.set_mark(0.0, (math.nan, 0.0, 0.0), (1.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="non-zero"):
        ld.set_mark(0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    ld.set_mark(1.0, _on(0.0), (2.0, 0.0, 0.0))
    assert ld.mark is not None and norm(ld.mark.normal) == pytest.approx(1.0)
    ld.set_mark(1.1, _on(0.0), (1.0, 0.0, 0.0), visible=False)
    assert ld.mark is None


def test_without_a_fresh_mark_on_the_surface_or_after_the_arrival_the_fingertips_projection_is_kept():
    ld = Landing(CYL, CFG)
    q, n = _on(0.5), _normal(0.5)
    assert ld.place(0.0, DT, 0.02, q, n, None) == (q, n, 0.0)            # no mark
    ld.set_mark(0.0, _on(0.0), _normal(0.0))
    assert ld.place(CFG.mark_timeout + 0.01, DT, 0.02, q, n, None) == (q, n, 0.0)   # stale
    assert ld.place(0.1, DT, 0.0, q, n, None, touching=True) == (q, n, 0.0)          # arrived
    assert ld.place(0.1, DT, 0.001, q, n, None, touching=True) == (q, n, 0.0)        # lifted while touching
    assert ld.place(0.1, None, 0.001, q, n, None, touching=False)[0] != q            # released: landing again


def test_far_from_the_surface_the_target_is_the_mark_offset_outside():
    ld = Landing(CYL, CFG)
    ld.set_mark(0.0, _on(0.2), _normal(0.2))
    q, n, lift = ld.place(0.0, None, 0.03, _on(1.0), _normal(1.0), None)
    assert norm(sub(q, _on(0.2))) < 1e-12 and _deg(n, _normal(0.2)) < 1e-9
    assert lift == pytest.approx(CFG.preposition_offset)


def test_within_touch_distance_the_target_blends_from_the_mark_to_the_finger_on_the_surface():
    ld = Landing(CYL, CFG)
    ld.set_mark(0.0, _on(0.0), _normal(0.0))
    d = 0.5 * CFG.touch_distance
    q, n, lift = ld.place(0.0, None, d, _on(0.2), _normal(0.2), None, touching=True)
    assert math.degrees(math.atan2(n[2], n[0])) == pytest.approx(math.degrees(0.1), abs=1e-6)
    assert abs(CYL.signed_distance(q)) < 1e-9 and _deg(CYL.normal_at(q), n) < 1e-6
    assert lift == 0.0
    q, n, lift = ld.place(0.0, None, CFG.touch_distance + 0.5 * CFG.preposition_blend, _on(0.2), _normal(0.2),
                          None)
    assert norm(sub(q, _on(0.0))) < 1e-12 and lift == pytest.approx(0.5 * CFG.preposition_offset)


def test_a_far_turn_steps_by_w_max_dt_through_support_planes():
    ld = Landing(CYL, CFG)
    ld.set_mark(0.0, _on(0.0), _normal(0.0))
    q, n, lift = ld.place(0.0, DT, 0.03, _on(1.0), _normal(1.0), (_on(1.0), _normal(1.0)))
    assert _deg(n, _normal(1.0)) == pytest.approx(math.degrees(CFG.limits.w_max * DT), rel=1e-9)
    assert abs(CYL.signed_distance(q)) < 1e-9 and clearance(CYL, q, n, q) == pytest.approx(0.0, abs=1e-12)


# --------------------------------------------------------------------------------------- the planner
def _lift_and_land(planner: SurfacePlanner, start: float, end: float, mark: bool, n_move: int = 48,
                   t0: float = 0.0) -> list:
    """The finger touching at ``start`` rad, lifted 30 mm and carried to ``end`` rad over ``n_move`` samples,
    then landing there (0.5 mm in) and resting; the mark at ``end`` throughout when ``mark``."""
    plans, t = [], t0
    path = [_on(start, -0.0005)] * 24
    for k in range(1, n_move + 1):
        f = k / n_move
        path.append(_on(start + (end - start) * smoothstep(f), 0.03 * smoothstep(4.0 * f)))
    path += [_on(end, 0.03 * (1.0 - k / 24.0)) for k in range(24)] + [_on(end, -0.0005)] * 48
    for p in path:
        if mark:
            planner.set_mark(t, _on(end), _normal(end))
        plans.append(planner.update(t, p))
        t += DT
    return plans


def test_with_a_mark_the_away_sheet_waits_tangent_at_the_mark_offset_outside():
    p = SurfacePlanner(CYL, CFG)
    p.update(0.0, _on(0.8, 0.03))
    t = 0.0
    for _ in range(96):                           # the finger hovers 30 mm out over 0.8 rad, the mark at 0
        t += DT
        p.set_mark(t, _on(0.0), _normal(0.0))
        plan = p.update(t, _on(0.8, 0.03))
    assert not plan.touching and plan.status == "ok"
    assert _deg(plan.normal, _normal(0.0)) < 1e-6
    want = tuple(a + CFG.preposition_offset * b for a, b in zip(_on(0.0), _normal(0.0), strict=True))
    assert norm(sub(plan.origin, want)) < 1e-6                      # 3 mm outside, at the mark
    assert clearance(CYL, plan.origin, plan.normal, plan.contact) == pytest.approx(CFG.preposition_offset,
                                                                                   abs=1e-6)


def test_without_a_mark_or_with_a_hidden_one_the_plans_are_unchanged():
    a = _lift_and_land(SurfacePlanner(CYL, CFG), math.radians(60), 0.0, mark=False)
    assert _lift_and_land(SurfacePlanner(CYL), math.radians(60), 0.0, mark=True) == a     # use_mark off
    hidden = SurfacePlanner(CYL, CFG)
    hidden.set_mark(0.0, _on(0.0), _normal(0.0), visible=False)
    b = _lift_and_land(hidden, math.radians(60), 0.0, mark=False)
    assert a == b
    off = SurfacePlanner(CYL, replace(CFG, mark_timeout=1e-6))
    off.set_mark(-1.0, _on(0.0), _normal(0.0))                     # stale from the start
    assert _lift_and_land(off, math.radians(60), 0.0, mark=False) == a
    away = [pl for pl in a if not pl.touching and pl.status == "ok"]
    assert away and all(abs(dot(sub(pl.origin, pl.contact), pl.normal)) < 1e-9 for pl in away)   # on it


@pytest.mark.parametrize("shape", [CYL, make_shape("sphere", {"center": (-0.04, 0.0, 0.0), "radius": 0.04})],
                         ids=["cylinder", "sphere"])
def test_the_sheet_turns_around_the_object_never_through_it_and_lands_in_pose_earlier(shape):
    """Touching at 60°, lifted and carried to 0° where the mark is: with the mark every planned sheet stands
    outside the object and the plan is in the landing's pose long before the finger arrives; without it the
    plan turns only as the finger's projection does."""
    with_mark = _lift_and_land(SurfacePlanner(shape, CFG), math.radians(60), 0.0, mark=True)
    without = _lift_and_land(SurfacePlanner(shape, CFG), math.radians(60), 0.0, mark=False)
    n_end = _normal(0.0)
    away = [i for i, pl in enumerate(with_mark) if not pl.touching]
    assert away
    assert min(clearance(shape, with_mark[i].origin, with_mark[i].normal, with_mark[i].contact)
               for i in away) >= -1e-9                                    # never inside while away
    first_in_pose = {name: next(i for i, pl in enumerate(plans) if _deg(pl.normal, n_end) < 1.0)
                     for name, plans in (("mark", with_mark), ("none", without))}
    assert first_in_pose["mark"] <= 24 + 30            # within 0.625 s of the lift (60° at w_max, 3 rad/s)
    assert first_in_pose["none"] - first_in_pose["mark"] >= 12            # ≥ 0.25 s earlier (measured 0.31)
    landed = with_mark[-1]
    assert landed.touching and _deg(landed.normal, n_end) < 0.5


def test_a_finger_that_lands_elsewhere_than_the_mark_takes_the_sheet_there():
    p = SurfacePlanner(CYL, CFG)
    plans = []
    t = 0.0
    for k in range(120):                             # 30 mm out over 0.5 rad, then down onto it, resting
        out = 0.03 if k < 48 else 0.03 * (1.0 - (k - 48) / 40.0)
        p.set_mark(t, _on(0.0), _normal(0.0))
        plans.append(p.update(t, _on(0.5, max(out, -0.0005))))
        t += DT
    assert _deg(plans[40].normal, _normal(0.0)) < 1.0                 # waiting at the mark
    assert _deg(plans[-1].normal, _normal(0.5)) < 0.5 and plans[-1].touching
