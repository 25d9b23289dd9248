"""The sheet's geometry in one place (flexsheet.model.sheet): clamps ↔ sheet frame ↔ stretch, used by the
planner, the world twin and the tension model; the arm bases defined once; the membrane's boundary
conditions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flexsheet.arm import kinematics
from flexsheet.model import geometry as scene
from flexsheet.model.sheet import (
    Membrane,
    SheetSurface,
    clamp_half_span,
    clamp_poses,
    frame_from_clamps,
    stretch_of_span,
)

TILT = math.radians(30.0)
N_TILT = np.array([math.cos(TILT), 0.0, -math.sin(TILT)])
Y = np.array([0.0, 1.0, 0.0])


def test_clamp_poses_place_the_edges_and_invert_to_the_sheet_frame():
    o = np.array([-0.01, 0.002, -0.02])
    Tl, Tr = clamp_poses(o, N_TILT, Y, 0.05)
    # 0.24 m sheet stretched 5 %: the clamped edges are 0.126 m either side of the centre along axis_u
    assert Tl[:3, 3] == pytest.approx([-0.01, 0.128, -0.02], abs=1e-15)
    assert Tr[:3, 3] == pytest.approx([-0.01, -0.124, -0.02], abs=1e-15)
    assert (Tl[:3, 0] == pytest.approx(N_TILT)
            and Tl[:3, 2] == pytest.approx([math.sin(TILT), 0.0, math.cos(TILT)]))
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


def test_arm_bases_are_defined_once_and_the_sheet_geometry_lives_in_sheet():
    for name in ("LEFT_BASE", "RIGHT_BASE"):                 # one copy: the display geometry's
        assert not hasattr(kinematics, name)
    from flexsheet.model.sheet import sheet_rotation
    assert sheet_rotation(N_TILT, Y)[:, 2] == pytest.approx(np.cross(N_TILT, Y))
    for moved in ("clamp_poses", "sheet_rotation"):        # no second path to the sheet's geometry
        with pytest.raises(AttributeError):
            getattr(scene, moved)


def test_membrane_boundary_conditions_and_pde():
    m = Membrane(0.12, 0.10, 0.02, -0.01, 0.03, tension_ratio=1.0)
    assert abs(m.deflection(0.02, -0.01) - 0.03) < 1e-12                       # depth at the pushed point
    v = np.linspace(-0.1, 0.1, 7)
    assert np.abs(m.deflection(0.12, v)).max() < 1e-12                          # clamped edges
    assert np.abs(m.deflection(-0.12, v)).max() < 1e-12
    u = np.linspace(-0.1, 0.1, 7)
    _, _, wv = m.deflection_grad(u, np.full_like(u, 0.10))
    assert np.abs(wv).max() < 1e-9                                              # free edges: dw/dv = 0
    # Laplace equation away from the load: w_uu + w_vv ≈ 0 (relative to the terms)
    h, p = 1e-3, (-0.06, 0.05)
    wuu = (m.deflection(p[0] + h, p[1]) - 2 * m.deflection(*p) + m.deflection(p[0] - h, p[1])) / h**2
    wvv = (m.deflection(p[0], p[1] + h) - 2 * m.deflection(*p) + m.deflection(p[0], p[1] - h)) / h**2
    assert abs(wuu + wvv) < 1e-3 * max(abs(wuu), abs(wvv)) + 1e-6
    w, wu, wv = m.deflection_grad(0.05, 0.03)
    e = 1e-6
    assert abs(wu - (m.deflection(0.05 + e, 0.03) - m.deflection(0.05 - e, 0.03)) / (2 * e)) < 1e-6
    assert abs(wv - (m.deflection(0.05, 0.03 + e) - m.deflection(0.05, 0.03 - e)) / (2 * e)) < 1e-6
    with pytest.raises(ValueError, match="push_u"):
        Membrane(0.12, 0.1, 0.2, 0.0, 0.01)
    with pytest.raises(ValueError, match="depth"):
        Membrane(0.12, 0.1, 0.0, 0.0, -0.01)
