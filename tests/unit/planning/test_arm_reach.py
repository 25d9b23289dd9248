"""Both arms' IK for the planner's targets (flexsheet/planning/arm_reach.py): one solve per target pair,
and the nearest reachable sheet where the object's tangent plane is out of the arms' reach."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flexsheet.model import geometry
from flexsheet.model.shapes import Cylinder
from flexsheet.model.sheet import clamp_poses, sheet_rotation
from flexsheet.planning.arm_reach import ArmReach, rotation_power
from flexsheet.planning.planner_config import PlannerConfig
from flexsheet.planning.surface_planner import SurfacePlanner

BASES = {"left": geometry.LEFT_BASE, "right": geometry.RIGHT_BASE}
R_CYL = geometry.CYLINDER_RADIUS
#: the paper's cylinder stood on end: axis +z through (-R, 0, 0)
UPRIGHT = Cylinder((-R_CYL, 0.0, 0.0), (0.0, 0.0, 1.0), R_CYL, 0.12)


def _sheet_at(phi_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """(contact (3,), R (3, 3)) of the upright cylinder's tangent plane at ``phi_deg`` around its axis."""
    phi = math.radians(phi_deg)
    n = np.array([math.cos(phi), math.sin(phi), 0.0])
    u = np.array([-math.sin(phi), math.cos(phi), 0.0])
    return np.array([-R_CYL, 0.0, 0.0]) + R_CYL * n, sheet_rotation(n, u)


def test_one_solve_per_target_pair():
    reach = ArmReach(BASES)
    Tl, Tr = clamp_poses(np.zeros(3), np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), 0.04, 0.24)
    assert reach.reachable(Tl, Tr) == (True, "ok")
    assert reach.solves == 2
    reach.solve(Tl, Tr)
    assert reach.solves == 2                      # the same pair: kept, not solved again
    with pytest.raises(ValueError, match="bases must name 'left' and 'right'"):
        ArmReach({"left": geometry.LEFT_BASE})


def test_arotation_power_is_the_geodesic_fraction():
    R0 = sheet_rotation(np.array([1.0, 0, 0]), np.array([0, 1.0, 0]))
    _, R1 = _sheet_at(50.0)
    assert np.allclose(rotation_power(R0, R1, 0.0), R0) and np.allclose(rotation_power(R0, R1, 1.0), R1)
    half = rotation_power(R0, R1, 0.5)
    ang = math.degrees(math.acos(0.5 * (np.trace(R0.T @ half) - 1.0)))
    assert ang == pytest.approx(25.0, abs=1e-6)


def test_the_nearest_reachable_sheet_turns_as_far_as_the_arms_reach_through_the_contact():
    reach = ArmReach(BASES)
    q0, R0 = _sheet_at(0.0)
    q1, R1 = _sheet_at(60.0)
    Tl, Tr = clamp_poses(q1, R1[:, 0], R1[:, 1], 0.04, 0.24)
    ok, why = ArmReach(BASES).reachable(Tl, Tr)
    assert not ok                                 # 60° around an upright cylinder: beyond the arms
    t, o, R = reach.nearest(q1, (0.0, 0.0), R0, R1, 0.04, 0.24)
    assert 0.0 < t < 1.0
    assert np.allclose(o, q1, atol=1e-12)         # through the contact, at the sheet's centre
    Tl, Tr = clamp_poses(o, R[:, 0], R[:, 1], 0.04, 0.24)
    assert ArmReach(BASES).reachable(Tl, Tr)[0]
    Rb = rotation_power(R0, R1, t + 2.0 / 64)    # a little farther: beyond the arms (the bisection's edge)
    assert not ArmReach(BASES).reachable(*clamp_poses(q1, Rb[:, 0], Rb[:, 1], 0.04, 0.24))[0]
    assert reach.nearest(q1, (0.0, 0.0), R1, R1, 0.04, 0.24) is None   # not even the start: none


def _stroke(planner, degs):
    plans = []
    for i, d in enumerate(degs):
        phi = math.radians(d)
        p = (-R_CYL + (R_CYL + 0.0005) * math.cos(phi), (R_CYL + 0.0005) * math.sin(phi), 0.0)
        plans.append(planner.update(1.0 + 0.02 * i, p))
    return plans


def test_a_stroke_around_an_upright_cylinder_never_asks_the_arms_what_they_cannot_reach():
    degs = np.concatenate([np.zeros(20), np.linspace(0.0, 60.0, 600)])
    cfg = PlannerConfig(object_stiffness=100.0)
    with_ik = _stroke(SurfacePlanner(UPRIGHT, cfg, arm_reach=ArmReach(BASES)), degs)
    without = _stroke(SurfacePlanner(UPRIGHT, cfg), degs)

    def refused(plans):
        check = ArmReach(BASES)                     # what the bridges would say, plan after plan
        return sum(not check.reachable(*p.clamp_matrices())[0] for p in plans)

    assert refused(without) > 100                  # the paper's rule alone: the bridges would refuse these
    assert refused(with_ik) == 0
    nearest = [p for p in with_ik if "reach:nearest" in p.status]
    assert nearest                                 # turned only as far as the arms reach ...
    for p in nearest:                              # ... and still through the contact on the object
        c = np.asarray(p.origin) + p.offset[0] * np.asarray(p.axis_u) + p.offset[1] * np.asarray(p.axis_v)
        assert np.linalg.norm(c - np.asarray(p.contact)) < 0.003
    # past that, the last reachable sheet is held and the plan says so
    assert "unreachable" in with_ik[-1].status and with_ik[-1].origin == nearest[-1].origin


def test_a_first_target_far_from_the_arms_start_is_reachable_not_refused_as_a_jump():
    # the sheet tilted 40° up from home: each arm's IK lies 0.71 rad from its home joints (more than a
    # bridge's 0.5 rad jump); a jump bound on the planner's own seed would refuse it, and every target after
    reach = ArmReach(BASES)
    th = math.radians(40.0)
    Tl, Tr = clamp_poses(np.array([-0.01, 0.0, 0.01]), np.array([math.cos(th), 0.0, math.sin(th)]),
                         np.array([0.0, 1.0, 0.0]), 0.04, 0.24)
    assert reach.reachable(Tl, Tr) == (True, "ok")
