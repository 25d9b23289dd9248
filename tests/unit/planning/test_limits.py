"""Motion limits (flexsheet.planning.limits): the rate limiter's braking, velocity and rotation bounds, its
snapshot, restore and clear."""

from __future__ import annotations

import math

import pytest

from flexsheet.model.motion_limits import MotionLimits
from flexsheet.model.vec import norm
from flexsheet.planning.limits import RateLimiter, limit_step


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


def test_limit_step_braking_and_velocity_bounds():
    v = (0.0, 0.0, 0.0)
    pos = 0.0
    for _ in range(2000):
        st, v, _ = limit_step((1.0 - pos, 0.0, 0.0), v, 0.3, 3.0, 0.005)
        assert norm(v) <= 0.3 + 1e-12
        pos += st[0]
    assert pos == pytest.approx(1.0, abs=1e-6)
    st, v2, lim = limit_step((0.001, 0.0, 0.0), (0.0, 0.0, 0.0), 0.3, 3.0, 0.02)
    assert not lim and st[0] == pytest.approx(0.001)        # within the limits: lands in one step
    st, v2, lim = limit_step((0.01, 0.0, 0.0), (0.0, 0.0, 0.0), 0.3, 3.0, 0.02)
    assert lim and v2[0] == pytest.approx(3.0 * 0.02)       # acceleration-bounded


def test_rate_limiter_rotation_bounded():
    rl = RateLimiter(MotionLimits(w_max=1.0, alpha_max=100.0))
    eye = ((1.0, 0, 0), (0, 1.0, 0), (0, 0, 1.0))
    rl.reset((0, 0, 0), eye, 0.0)
    Rz = ((0.0, -1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0))
    _, R1, _, lim = rl.step((0, 0, 0), Rz, 0.0, 0.1)
    ang = math.acos(max(-1, min(1, (R1[0][0] + R1[1][1] + R1[2][2] - 1) / 2)))
    assert lim and ang <= 1.0 * 0.1 + 1e-9
