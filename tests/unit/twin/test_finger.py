"""The scripted finger (flexsheet.twin.finger): it follows the mark, deterministically per seed, with the
stated tremor; position and velocity in one call."""

import numpy as np
import pytest

from flexsheet.model import geometry
from flexsheet.twin.finger import FingerScript

R = geometry.CYLINDER_RADIUS


def test_finger_script_follows_mark_and_is_deterministic():
    f = FingerScript(moving_time=10.0, tremor_rms=0.0, wander_deg=0.0, wander_axial=0.0, lag=0.0, depth=0.0)
    t = np.array([0.0, f.t_move, f.t_move + 5.0, f.t_move + 10.0])
    P = f.positions(t)
    assert np.degrees(f.angle_of(P[1:])) == pytest.approx([0.0, 30.0, 60.0], abs=1e-9)
    assert np.linalg.norm(P[1:] - geometry.CYLINDER_CENTER, axis=1) == pytest.approx([R] * 3)
    assert P[0][0] == pytest.approx(0.03)                    # approach starts 30 mm in front
    assert P[3][2] > 0                                         # positive angles go up (+z)
    g1, g2 = FingerScript(seed=4), FingerScript(seed=4)
    tt = np.linspace(0, 13, 500)
    assert np.array_equal(g1.positions(tt), g2.positions(tt))
    trem = FingerScript(seed=1, wander_deg=0, wander_axial=0).positions(tt) - \
        FingerScript(seed=1, wander_deg=0, wander_axial=0, tremor_rms=0).positions(tt)
    assert np.sqrt(np.mean(trem ** 2, axis=0)) == pytest.approx([5e-5] * 3, rel=0.35)
    assert f.phase(0.5) == "approach" and f.phase(f.t_move + 1) == "stroke" and f.phase(100) == "idle"
    with pytest.raises(ValueError, match="mode"):
        FingerScript(mode="dance")


@pytest.mark.parametrize("t", [0.5, 3.7, 6.05])
def test_finger_script_state_is_position_and_velocity_in_one_call(t):
    """The world's per-tick (position, velocity): the same numbers as the two separate calls, and the velocity
    is the stroke's (≈ R·dφ/dt on the linear profile plus the tremor's), not zero."""
    fs = FingerScript(mode="stroke", moving_time=5.0, seed=3)
    p, v = fs.state(t)
    assert (p == pytest.approx(fs.position(t), abs=1e-15)
            and v == pytest.approx(fs.velocity(t), rel=1e-9, abs=1e-12))
    assert np.linalg.norm(v) > 1e-4


def test_between_segments_the_finger_lifts_off_and_moves_through_free_space():
    """The next segment's approach starts where the last one ended (no jump), stays in front of the object
    (never deeper than the last stroke's own light contact) and ends on the script's own approach; on the
    paper's cylinder a jump put it 2.7 mm behind the sheet still tangent at 60 degrees."""
    from flexsheet.twin.finger import after

    a, b = FingerScript(mode="stroke", moving_time=10.0), FingerScript(mode="stroke", moving_time=30.0)
    R = 0.025 * 2 ** 0.5
    t = np.linspace(0.0, b.approach_time, 401)
    P = np.array([after(a, b, x)[0] for x in t])
    assert np.linalg.norm(P[0] - a.position(a.duration)) < 1e-12
    assert np.linalg.norm(after(a, b, b.approach_time)[0] - b.position(b.approach_time)) < 1e-12
    out = np.hypot(P[:, 0] + R, P[:, 2]) - R                           # distance outside the cylinder, m
    assert out.min() >= -a.depth - 2e-4 and out.max() > 0.02         # lifted off by most of approach_distance
    steps = np.linalg.norm(np.diff(P, axis=0), axis=1)
    assert steps.max() < 0.002                                        # continuous: < 2 mm per 2.5 ms
    v_num = (after(a, b, 0.4 + 1e-4)[0] - after(a, b, 0.4 - 1e-4)[0]) / 2e-4
    assert np.allclose(after(a, b, 0.4)[1], v_num, atol=1e-6)
