"""The bridges' stream limiter (flexsheet.arm.limiter): limits never exceeded, a held goal reached exactly,
the feed-forward through sparse goals, snapshot and restore."""

import numpy as np
import pytest

from flexsheet.arm.kinematics import Q_HOME, Q_LOWER, Q_UPPER, QD_MAX
from flexsheet.arm.limiter import StreamLimiter

T = 0.0071


@pytest.mark.parametrize("feed_forward", [False, True])
def test_limiter_never_commands_beyond_position_speed_accel(feed_forward):
    qd, qdd, margin = 0.5 * QD_MAX, 1.0 * QD_MAX, 0.02
    lim = StreamLimiter(Q_HOME, T, qd, qdd, Q_LOWER, Q_UPPER, margin)
    rng = np.random.default_rng(11)
    c_prev, v_prev = lim.c.copy(), np.zeros(6)
    goal, w = Q_HOME.copy(), None
    for k in range(6000):
        if k % 40 == 0:   # jumpy goals, including far outside the joint range, and wild goal velocities
            goal = rng.uniform(Q_LOWER - 1.0, Q_UPPER + 1.0)
            w = rng.uniform(-3.0, 3.0, 6) * QD_MAX if feed_forward else None
        c = lim.step(goal, w)
        v = (c - c_prev) / T
        assert np.all(np.abs(v) <= qd * (1 + 1e-9))
        assert np.all(np.abs(v - v_prev) <= qdd * T + 1e-9)
        assert np.all(c >= Q_LOWER + margin - 1e-12) and np.all(c <= Q_UPPER - margin + 1e-12)
        c_prev, v_prev = c, v


def test_limiter_reaches_a_held_goal_exactly_and_stops():
    lim = StreamLimiter(Q_HOME, T, QD_MAX, 2 * QD_MAX, Q_LOWER, Q_UPPER)
    goal = Q_HOME + np.array([0.3, -0.2, 0.1, 0.5, -0.4, 1.0])
    for _ in range(400):
        c = lim.step(goal)
    assert np.allclose(c, goal, atol=1e-12) and np.allclose(lim.v, 0.0)


def test_feed_forward_streams_through_48_hz_goals_where_the_rate_limiter_brakes_at_each():
    """A finger-like ramp of 0.1 rad/s sampled as goals at 48 Hz (every 3 periods): fed the goal moved on at
    its velocity (what TargetTracker.reference gives) the command runs one period ahead of the ramp; fed the
    held goal, the limiter brakes toward each and trails it by more than a target period."""
    w = np.full(6, 0.1)
    err = {}
    for ff in (False, True):
        lim = StreamLimiter(Q_HOME, T, QD_MAX, 4 * QD_MAX, Q_LOWER, Q_UPPER)
        e = []
        for k in range(600):
            k0 = k - k % 3                                  # the newest goal's period
            held = Q_HOME + w * k0 * T
            c = lim.step(held + w * (k - k0) * T, w) if ff else lim.step(held)
            e.append(Q_HOME + w * k * T - c)                # the ramp now minus the command
        err[ff] = np.abs(np.array(e[300:])).mean(axis=0)
    assert np.allclose(err[True], w * T, rtol=1e-6), err[True]
    assert np.all(err[False] > 1.5 * w * T), err[False]


def test_limiter_snapshot_restore_redoes_a_step_toward_a_newer_goal():
    lim = StreamLimiter(Q_HOME, T, QD_MAX, 2 * QD_MAX, Q_LOWER, Q_UPPER)
    for _ in range(10):
        lim.step(Q_HOME + 0.5)                           # moving: v != 0
    snap = lim.snapshot()
    a = lim.step(Q_HOME + 0.5)
    snap_copy = (snap[0].copy(), snap[1].copy())
    lim.c[:] += 1.0                                      # the snapshot is a copy: later changes do not leak
    assert np.array_equal(snap[0], snap_copy[0])
    lim.restore(snap)
    assert np.array_equal(lim.step(Q_HOME + 0.5), a)     # same state, same goal → the same command
    lim.restore(snap)
    b = lim.step(Q_HOME - 0.5)                           # redo the step toward a newer goal
    assert np.all(np.abs(b - snap[0]) <= QD_MAX * T * (1 + 1e-9))               # still one period's step
    assert np.all(np.abs((b - snap[0]) / T - snap[1]) <= 2 * QD_MAX * T + 1e-9)  # and one period's Δv
    assert not np.array_equal(a, b)
    for bad in [(np.zeros(5), np.zeros(6)), (np.full(6, np.nan), np.zeros(6)), "xy", None, (1, 2, 3)]:
        with pytest.raises(ValueError, match="snapshot"):
            lim.restore(bad)
