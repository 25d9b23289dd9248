"""The sheet's geometry in one place (flexsheet.model.sheet): clamps ↔ sheet frame ↔ stretch, used by the
planner, the world twin and the tension model; the arm bases defined once; the rate limiter's state API."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flexsheet.arm import kinematics
from flexsheet.model import geometry as scene
from flexsheet.model.shapes import paper_cylinder
from flexsheet.model.sheet import (
    SheetSurface,
    clamp_half_span,
    clamp_points,
    clamp_poses,
    frame_from_clamps,
    stretch_of_span,
)
from flexsheet.model.tension import SheetMaterial, stiffness, tension
from flexsheet.planning.limits import MotionLimits, RateLimiter
from flexsheet.planning.surface_planner import SurfacePlanner

TILT = math.radians(30.0)
N_TILT = np.array([math.cos(TILT), 0.0, -math.sin(TILT)])
Y = np.array([0.0, 1.0, 0.0])


def test_clamp_poses_place_the_edges_and_invert_to_the_sheet_frame():
    o = np.array([-0.01, 0.002, -0.02])
    Tl, Tr = clamp_poses(o, N_TILT, Y, 0.05)
    # 0.24 m sheet stretched 5 %: the clamped edges are 0.126 m either side of the centre along axis_u
    assert Tl[:3, 3] == pytest.approx([-0.01, 0.128, -0.02], abs=1e-15)
    assert Tr[:3, 3] == pytest.approx([-0.01, -0.124, -0.02], abs=1e-15)
    assert Tl[:3, 0] == pytest.approx(N_TILT) and Tl[:3, 2] == pytest.approx([math.sin(TILT), 0.0, math.cos(TILT)])
    origin, n, u, a = frame_from_clamps(Tl, Tr)
    assert origin == pytest.approx(o, abs=1e-15) and n == pytest.approx(N_TILT) and u == pytest.approx(Y)
    assert a == pytest.approx(0.126, abs=1e-15) and stretch_of_span(a) == pytest.approx(0.05, abs=1e-12)
    # the world's sheet state: the stretch comes from the same function, for any sheet size
    surf = SheetSurface.from_clamps(Tl, Tr, size=0.2)
    assert surf.stretch == pytest.approx(0.26, abs=1e-12) and surf.half_span == pytest.approx(0.126)
    assert stretch_of_span(0.1) == 0.0                          # a slack sheet has no negative stretch


def test_sheet_geometry_rejects_bad_input_naming_it():
    with pytest.raises(ValueError, match="stretch"):
        clamp_poses(np.zeros(3), N_TILT, Y, -0.1)
    with pytest.raises(ValueError, match="axis_u"):
        clamp_poses(np.zeros(3), N_TILT, [0.0, 2.0, 0.0], 0.0)
    with pytest.raises(ValueError, match="orthogonal"):
        clamp_poses(np.zeros(3), N_TILT, [1.0, 0.0, 0.0], 0.0)
    with pytest.raises(ValueError, match="stretch"):
        clamp_half_span(-1.5)
    T = np.eye(4)
    T[:3, :3] *= 1.1                                             # not a rotation
    with pytest.raises(ValueError, match="T_right"):
        frame_from_clamps(np.eye(4), T)
    with pytest.raises(ValueError, match="1 mm"):
        frame_from_clamps(np.eye(4), np.eye(4))


def test_planner_clamps_and_tension_use_the_sheet_geometry():
    pl = SurfacePlanner(paper_cylinder())
    plan = pl.update(0.0, (0.01, 0.0, 0.0), object_stiffness=20.0)
    a = clamp_half_span(plan.stretch)
    assert plan.left == pytest.approx(tuple(np.add(plan.origin, np.multiply(a, plan.axis_u))), abs=1e-15)
    assert (plan.left, plan.right) == clamp_points(plan.origin, plan.axis_u, plan.stretch)
    Tl, Tr = plan.clamp_matrices()
    assert Tl[:3, 3] == pytest.approx(plan.left, abs=1e-15) and Tr[:3, 3] == pytest.approx(plan.right, abs=1e-15)
    # string model at the centre: k = T·w·2/a with a the clamp half span
    mat = SheetMaterial()
    assert stiffness(plan.stretch, mat) == pytest.approx(tension(plan.stretch, mat) * mat.contact_width * 2 / a)
    assert plan.stiffness == pytest.approx(20.0, rel=1e-6)


def test_arm_bases_are_defined_once_and_the_sheet_geometry_lives_in_sheet():
    for name in ("LEFT_BASE", "RIGHT_BASE"):                 # one copy: the display geometry's
        assert not hasattr(kinematics, name)
    from flexsheet.model.sheet import sheet_rotation
    assert sheet_rotation(N_TILT, Y)[:, 2] == pytest.approx(np.cross(N_TILT, Y))
    for moved in ("clamp_poses", "sheet_rotation"):        # no second path to the sheet's geometry
        with pytest.raises(AttributeError):
            getattr(scene, moved)


def test_rate_limiter_snapshot_restore_and_clear():
    rl = RateLimiter(MotionLimits(v_max=0.3, a_max=3.0))
    eye = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    assert not rl.initialised
    rl.step((0.0, 0.0, 0.0), eye, 0.0, 0.02)                     # first step initialises at the target
    assert rl.initialised and rl.origin == (0.0, 0.0, 0.0)
    rl.step((0.1, 0.0, 0.0), eye, 0.0, 0.02)
    snap = rl.snapshot()
    assert snap.vel[0] == pytest.approx(0.06)                     # a_max·dt
    rl.step((0.1, 0.0, 0.0), eye, 0.0, 0.02)
    assert rl.origin != snap.origin
    rl.restore(snap)
    assert rl.snapshot() == snap
    rl.restore(snap, at_rest=True)
    assert rl.origin == snap.origin and rl.vel == (0.0, 0.0, 0.0) and rl.omega == (0.0, 0.0, 0.0)
    rl.clear()
    assert not rl.initialised and rl.vel == (0.0, 0.0, 0.0)
