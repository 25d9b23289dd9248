"""The two-arm span guard (flexsheet.arm.span_guard, asked by the bridge's tracker): a step that takes the
clamp span further outside its band waits, one back toward it is taken; without a partner or a band nothing
waits; a service's goal is not judged."""

import numpy as np
import pytest

from flexsheet.arm.kinematics import ArmKinematics, home_joints
from flexsheet.arm.tracking import TargetTracker
from flexsheet.model.geometry import LEFT_BASE, RIGHT_BASE
from flexsheet.model.sheet import clamp_poses

BAND = (0.2424, 0.264)        # clamp strain 0.01-0.10 of the 0.240 m sheet


def _home():
    kl, kr = ArmKinematics("left", LEFT_BASE), ArmKinematics("right", RIGHT_BASE)
    left, right = clamp_poses(np.zeros(3), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]), 0.05)
    rl, rr = kl.ik(left, home_joints("left")), kr.ik(right, home_joints("right"))
    assert rl.ok and rr.ok
    return kl, kr, rl.q, rr.q


def _tracker(kl, ql):
    t = TargetTracker(kl)
    t.span.set_band(BAND)
    t.seed(ql)
    return t


def _toward(kl, q, dy):
    """Joints that move the left clamp ``dy`` m along y (the span changes by dy)."""
    T = kl.fk(q)
    T[1, 3] += dy
    res = kl.ik(T, q)
    assert res.ok
    return res.q


def test_steps_that_take_the_span_further_out_are_refused_and_counted():
    kl, kr, ql, qr = _home()
    t = _tracker(kl, ql)
    t.span.peer_clamp = kr.fk(qr)[:3, 3]
    span0 = np.linalg.norm(kl.fk(ql)[:3, 3] - t.span.peer_clamp)
    assert span0 == pytest.approx(0.252, abs=1e-9)               # home: clamp strain 0.05, inside the band
    assert not t.span_worse(ql, _toward(kl, ql, -0.005))          # 0.247 m: inside, taken
    assert t.span_worse(ql, _toward(kl, ql, -0.012))              # 0.240 m: slack (below 0.2424)
    assert t.span_worse(ql, _toward(kl, ql, +0.015))              # 0.267 m: over-pull (above 0.264)
    assert t.span.waits == 2
    # from outside the band, a step back toward it is taken, a step further out is not
    q_slack = _toward(kl, ql, -0.015)                             # 0.237 m
    assert not t.span_worse(q_slack, _toward(kl, ql, -0.013))
    assert t.span_worse(q_slack, _toward(kl, ql, -0.016))
    assert t.span.waits == 3


def test_without_a_partner_or_a_band_nothing_waits_and_a_bad_band_is_refused():
    kl, kr, ql, qr = _home()
    t = _tracker(kl, ql)
    assert not t.span_worse(ql, _toward(kl, ql, -0.030))          # no partner state yet: no guard
    t.span.peer_clamp = kr.fk(qr)[:3, 3]
    t.span.set_band(None)
    assert not t.span_worse(ql, _toward(kl, ql, -0.030)) and t.span.waits == 0
    t.span.set_band(BAND)
    t.move_to(_toward(kl, ql, -0.030))  # a service's goal: the operator's, not judged
    assert not t.span_worse(ql, _toward(kl, ql, -0.030)) and t.span.waits == 0
    t.release()
    assert t.span_worse(ql, _toward(kl, ql, -0.030)) and t.span.waits == 1
    for band in ((0.26, 0.25), (0.0, 0.2), (0.2, float("inf"))):
        with pytest.raises(ValueError, match="span_band"):
            t.span.set_band(band)
