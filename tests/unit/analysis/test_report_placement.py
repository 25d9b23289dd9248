"""The sheet's placement against the object's surface (flexsheet/analysis/report_placement.py)."""

from __future__ import annotations

import numpy as np
import pytest

from flexsheet.analysis.report_placement import placement
from flexsheet.model.scenes import load_scene
from messages import FingerTruth, Header, SheetState

BOX = "launch/scenes/rounded_box.yaml"      # front face x = 0, top face z = 30 mm


def _sheet_state(t: float, origin, normal) -> SheetState:
    n = np.asarray(normal, float)
    return SheetState(header=Header(stamp=t), origin=np.asarray(origin, float), normal=n / np.linalg.norm(n),
                      axis_u=np.array([0.0, 1.0, 0.0]), corners=np.zeros((4, 3)), pushed_point=np.zeros(3),
                      depth=0.0, stretch=0.05, membrane=np.zeros((2, 2)))


def _finger(t: float, x: float):
    return (t, FingerTruth(header=Header(stamp=t), position=np.array([x, 0.0, 0.01]), velocity=np.zeros(3),
                           phase="stroke"))


def test_placement_measures_the_sheet_against_the_surface_and_counts_a_late_sheet():
    """Two touches of the box's front face at 10 mm/s: in the first the sheet stands at the surface all along
    (it waited 200 ms for the finger); in the second it stands 4 mm behind until 1.75 s and at the surface
    from 1.76 s, while the finger arrives at 1.70 s: late by 58.75 ms (the crossing of 0.5 mm behind,
    interpolated)."""
    fingers, sheets = [], []
    for k in range(251):
        t = round(0.01 * k, 10)
        if t <= 1.0:
            x, xs = 0.002 - 0.01 * t, 0.0
        elif t < 1.5:
            x, xs = 0.02, 0.0
        else:
            x, xs = 0.002 - 0.01 * (t - 1.5), (-0.004 if t <= 1.75 + 1e-9 else 0.0)
        fingers.append(_finger(t, x))
        sheets.append((t, _sheet_state(t, [xs, 0.0, 0.01], [1, 0, 0])))
    d = {"/world/finger": fingers, "/world/sheet": sheets}
    p = placement(d, load_scene(BOX))
    assert p["touches"] == 2 and p["arrivals"] == 2 and p["late"] == 1 and p["never"] == 0
    assert p["sheet_first"] == 0.5 and p["verdicts"]["sheet_first"] == "MISSED"
    assert p["arrival_ms"]["max"] == pytest.approx(58.75, abs=1e-6)
    assert p["arrival_ms"]["median"] == pytest.approx(0.5 * (58.75 - 200.0), abs=1e-6)
    assert (p["distance_mm"]["max"] == pytest.approx(4.0, abs=1e-9)
            and p["distance_mm"]["p50"] == pytest.approx(0.0))
    assert p["signed_mm"]["p1"] == pytest.approx(-4.0, abs=1e-9)                      # behind: negative
    assert (p["distance_mm"]["p99"] > 2.0 and p["verdicts"]["distance"] == "MISSED"
            and p["verdict"] == "MISSED")
    # the same run with the sheet on time: met
    on_time = [(t, _sheet_state(t, [0.0, 0.0, 0.01], [1, 0, 0])) for t, _ in sheets]
    q = placement({**d, "/world/sheet": on_time}, load_scene(BOX))
    assert (q["sheet_first"] == 1.0 and q["distance_mm"]["max"] == pytest.approx(0.0, abs=1e-12)
            and q["verdict"] == "met")
    assert placement(d, None) == {}


def _plan(t: float, status: str):
    from messages import SheetTarget

    return (t, SheetTarget(header=Header(stamp=t), contact_point=np.array([0.0, 0.0, 0.01]),
                           normal=np.array([1.0, 0.0, 0.0]), axis_u=np.array([0.0, 1.0, 0.0]),
                           axis_v=np.array([0.0, 0.0, 1.0]), sheet_origin=np.array([0.0, 0.0, 0.01]),
                           stretch=0.05,
                           tension=100.0, stiffness=100.0, object_stiffness=100.0, touching=True,
                           status=status))


def test_a_sheet_that_yields_to_the_head_is_counted_apart_until_it_is_back_at_the_planned_contact():
    """The finger rests 2 mm into the box's front face for 2 s. The sheet stands at the surface, then 6 mm
    behind it from 0.50 to 1.20 s. The plans say keep_out from 0.45 to 0.90 s (the guard backed it off), then
    ok; the sheet is back at 1.21 s. The 71 samples 0.50-1.20 s (and the 5 at the surface before, under a
    keep_out plan) are the head's: the verdict is met and distance_mm_all keeps the 6 mm. With no keep_out
    plan the same run is MISSED."""
    fingers, sheets, plans = [], [], []
    for k in range(201):
        t = round(0.01 * k, 10)
        fingers.append(_finger(t, -0.002))
        xs = -0.006 if 0.5 - 1e-9 <= t <= 1.2 + 1e-9 else 0.0
        sheets.append((t, _sheet_state(t, [xs, 0.0, 0.01], [1, 0, 0])))
        plans.append(_plan(t, "keep_out" if 0.45 - 1e-9 <= t <= 0.9 + 1e-9 else "ok"))
    d = {"/world/finger": fingers, "/world/sheet": sheets, "/sheet/target": plans}
    p = placement(d, load_scene(BOX))
    assert p["head_yield"]["n"] == 76 and p["head_yield"]["share"] == pytest.approx(76 / 201)
    assert p["n"] == 201 - 76
    assert p["distance_mm"]["max"] == pytest.approx(0.0, abs=1e-9) and p["verdicts"]["distance"] == "met"
    assert p["distance_mm_all"]["max"] == pytest.approx(6.0, abs=1e-9)
    ok_plans = [(t, _plan(t, "ok")[1]) for t, _ in plans]
    q = placement({**d, "/sheet/target": ok_plans}, load_scene(BOX))
    assert q["head_yield"]["n"] == 0 and q["distance_mm"]["max"] == pytest.approx(6.0, abs=1e-9)
    assert q["verdicts"]["distance"] == "MISSED"


def test_a_yield_ends_at_the_object_s_surface_and_a_later_miss_is_still_judged():
    """The planned contact stands 0.6 mm off the true sheet all along (the planner's belief), so the sheet
    never comes "back at the planned contact". The plans say keep_out 0.10-0.15 s; the sheet is at the
    object's surface from 0.16 s, and 6 mm behind it again 1.50-1.90 s with ok plans: the yield ends at 0.16 s
    and the later 6 mm is judged (MISSED). When every touching sample yields, the distance has no verdict and
    no NaN."""
    fingers, sheets, plans = [], [], []
    for k in range(201):
        t = round(0.01 * k, 10)
        fingers.append(_finger(t, -0.002))
        xs = -0.006 if 0.1 - 1e-9 <= t <= 0.15 + 1e-9 or 1.5 - 1e-9 <= t <= 1.9 + 1e-9 else 0.0
        sheets.append((t, _sheet_state(t, [xs, 0.0, 0.01], [1, 0, 0])))
        t_, m = _plan(t, "keep_out" if 0.1 - 1e-9 <= t <= 0.15 + 1e-9 else "ok")
        m = m.model_copy(update={"contact_point": np.array([0.0006, 0.0, 0.01])})
        plans.append((t_, m))
    d = {"/world/finger": fingers, "/world/sheet": sheets, "/sheet/target": plans}
    p = placement(d, load_scene(BOX))
    assert p["head_yield"]["n"] == 6
    assert p["distance_mm"]["max"] == pytest.approx(6.0, abs=1e-9) and p["verdicts"]["distance"] == "MISSED"
    all_out = [(t, _plan(t, "keep_out")[1]) for t, _ in plans]
    q = placement({**d, "/sheet/target": all_out}, load_scene(BOX))
    assert q["head_yield"]["n"] == 201 and q["n"] == 0 and q["distance_mm"] is None and q["signed_mm"] is None
    assert (q["verdicts"]["distance"] == "no verdict"
            and q["distance_mm_all"]["max"] == pytest.approx(6.0, abs=1e-9))


def test_the_misses_split_into_the_arms_the_plan_s_pose_and_its_contact():
    """The sheet 6 mm behind the box's front face for 0.5 s under ok plans: with the plan's pose on the
    surface the whole miss is the arms' (share 1, median −6 mm); with the plan's pose itself 6 mm back and the
    sheet on it, the plan's pose (share 1); the planned contact on the surface in both (its term 0)."""
    def run(plan_x: float) -> dict:
        fingers, sheets, plans = [], [], []
        for k in range(101):
            t = round(0.01 * k, 10)
            fingers.append(_finger(t, -0.002))
            back = 0.2 - 1e-9 <= t <= 0.7 + 1e-9
            sheets.append((t, _sheet_state(t, [-0.006 if back else 0.0, 0.0, 0.01], [1, 0, 0])))
            t_, m = _plan(t, "ok")
            m = m.model_copy(update={"sheet_origin": np.array([plan_x if back else 0.0, 0.0, 0.01])})
            plans.append((t_, m))
        return placement({"/world/finger": fingers, "/world/sheet": sheets, "/sheet/target": plans},
                         load_scene(BOX))["split"]
    arms, pose = run(0.0), run(-0.006)
    assert arms["n"] == 51 and pose["n"] == 51
    assert (arms["share"]["arms"] == pytest.approx(1.0)
            and arms["share"]["plan_pose"] == pytest.approx(0.0, abs=1e-12))
    assert arms["median_mm"]["arms"] == pytest.approx(-6.0, abs=1e-9)
    assert (pose["share"]["plan_pose"] == pytest.approx(1.0)
            and pose["share"]["arms"] == pytest.approx(0.0, abs=1e-12))
    assert arms["share"]["contact"] == pytest.approx(0.0, abs=1e-12) == pose["share"]["contact"]


def test_each_landing_is_judged_and_a_sheet_far_ahead_is_a_wall_in_the_air_not_there():
    """One touch, two landings on the box's front face. The finger goes in at 0.2 s with the sheet at the
    surface. It lifts out of the object but stays behind the sheet, which moved 6 mm ahead: still the same
    touch (/world/contact touching). It lands again at 1.8 s while the sheet stands 6 mm ahead, a wall in the
    air, and the sheet reaches the surface at 2.01 s: that landing is late by 208.9 ms (the crossing of the
    2 mm band, interpolated). Counted per touch, the second landing was hidden and the sheet was "first"."""
    from messages import ContactTruth

    fingers, sheets, contacts = [], [], []
    for k in range(251):
        t = round(0.01 * k, 10)
        if t <= 1.0:
            x, xs = 0.002 - 0.01 * t, 0.0
        elif t <= 1.5:
            x, xs = -0.008 + 0.022 * (t - 1.0), 0.006
        else:
            x, xs = 0.003 - 0.01 * (t - 1.5), (0.006 if t <= 2.0 + 1e-9 else 0.0)
        fingers.append(_finger(t, x))
        sheets.append((t, _sheet_state(t, [xs, 0.0, 0.01], [1, 0, 0])))
        contacts.append((t,
                         ContactTruth(header=Header(stamp=t), touching=x < xs, depth=max(xs - x, 0.0),
                                      force=0.1,
                                      point=np.zeros(3), stiffness=100.0)))
    p = placement({"/world/finger": fingers, "/world/sheet": sheets, "/world/contact": contacts},
                  load_scene(BOX))
    assert p["touches"] == 1 and p["arrivals"] == 2 and p["late"] == 1 and p["never"] == 0
    assert p["sheet_first"] == 0.5 and p["verdicts"]["sheet_first"] == "MISSED"
    assert p["arrival_ms"]["max"] == pytest.approx(1000.0 * (2.0 + 0.01 * 0.004 / 0.0045 - 1.8), abs=1e-6)
    # the sheet 1.5 mm ahead at the second landing is within the band: there, and first
    near = [(t, _sheet_state(t, [min(m.origin[0], 0.0015), 0.0, 0.01], [1, 0, 0])) for t, m in sheets]
    q = placement({"/world/finger": fingers, "/world/sheet": near, "/world/contact": contacts},
                  load_scene(BOX))
    assert q["arrivals"] == 2 and q["sheet_first"] == 1.0 and q["late"] == 0


def test_a_sheet_in_place_but_off_the_tangent_is_not_there_first():
    """Two touches of the box's front face: the sheet's plane passes through the surface point under the
    finger both times, but in the second it is still turned 20° off the tangent plane when the finger arrives
    (upright again from 1.80 s): that landing is late and the onset is counted out of pose."""
    fingers, sheets = [], []
    tilt = np.radians(20.0)
    for k in range(251):
        t = round(0.01 * k, 10)
        if t <= 1.0:
            x = 0.002 - 0.01 * t
        elif t < 1.5:
            x = 0.02
        else:
            x = 0.002 - 0.01 * (t - 1.5)
        normal = [np.cos(tilt), 0.0, np.sin(tilt)] if 1.5 < t < 1.8 - 1e-9 else [1.0, 0.0, 0.0]
        fingers.append(_finger(t, x))
        sheets.append((t, _sheet_state(t, [0.0, 0.0, 0.01], normal)))
    p = placement({"/world/finger": fingers, "/world/sheet": sheets}, load_scene(BOX))
    assert p["arrivals"] == 2 and p["late"] == 1 and p["sheet_first"] == 0.5
    assert p["onsets"]["n"] == 2 and p["onsets"]["in_place_and_pose"] == 0.5
    assert p["onsets"]["angle_deg"]["max"] == pytest.approx(20.0, abs=1e-6)
    assert p["verdicts"]["onsets"] == "MISSED" and p["verdict"] == "MISSED"
