"""The bridges' span guard: an arm brakes rather than take the clamp span further outside its band."""

import numpy as np
import pytest

from flexsheet.arm.kinematics import QD_MAX, ArmKinematics, home_joints
from flexsheet.arm.limiter import StreamLimiter
from flexsheet.arm.stream import ArmStream
from flexsheet.arm.tracking import TargetTracker
from flexsheet.model.geometry import LEFT_BASE, RIGHT_BASE
from flexsheet.model.sheet import clamp_poses

BAND = (0.2424, 0.264)        # clamp strain 0.01-0.10 of the 0.240 m sheet


def _home():
    kl, kr = ArmKinematics("left", LEFT_BASE), ArmKinematics("right", RIGHT_BASE)
    left, right = clamp_poses(np.zeros(3), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]), 0.05)
    rl, rr = kl.ik(left, home_joints("left")), kr.ik(right, home_joints("right"))
    assert rl.ok and rr.ok
    return kl, kr, rl.q, rr.q, left


def _tracker(kl, ql):
    t = TargetTracker(kl)
    t.set_span_band(BAND)
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
    kl, kr, ql, qr, _ = _home()
    t = _tracker(kl, ql)
    t.peer_clamp = kr.fk(qr)[:3, 3]
    span0 = np.linalg.norm(kl.fk(ql)[:3, 3] - t.peer_clamp)
    assert span0 == pytest.approx(0.252, abs=1e-9)               # home: clamp strain 0.05, inside the band
    assert not t.span_worse(ql, _toward(kl, ql, -0.005))          # 0.247 m: inside, taken
    assert t.span_worse(ql, _toward(kl, ql, -0.012))              # 0.240 m: slack (below 0.2424)
    assert t.span_worse(ql, _toward(kl, ql, +0.015))              # 0.267 m: over-pull (above 0.264)
    assert t.span_waits == 2
    # from outside the band, a step back toward it is taken, a step further out is not
    q_slack = _toward(kl, ql, -0.015)                             # 0.237 m
    assert not t.span_worse(q_slack, _toward(kl, ql, -0.013))
    assert t.span_worse(q_slack, _toward(kl, ql, -0.016))
    assert t.span_waits == 3


def test_without_a_partner_or_a_band_nothing_waits_and_a_bad_band_is_refused():
    kl, kr, ql, qr, _ = _home()
    t = _tracker(kl, ql)
    assert not t.span_worse(ql, _toward(kl, ql, -0.030))          # no partner state yet: no guard
    t.peer_clamp = kr.fk(qr)[:3, 3]
    t.set_span_band(None)
    assert not t.span_worse(ql, _toward(kl, ql, -0.030)) and t.span_waits == 0
    t.set_span_band(BAND)
    t.move_to(_toward(kl, ql, -0.030))                              # a service's goal: the operator's, not judged
    assert not t.span_worse(ql, _toward(kl, ql, -0.030)) and t.span_waits == 0
    t.release()
    assert t.span_worse(ql, _toward(kl, ql, -0.030)) and t.span_waits == 1
    for band in ((0.26, 0.25), (0.0, 0.2), (0.2, float("inf"))):
        with pytest.raises(ValueError, match="span_band"):
            t.set_span_band(band)


class _NoLink:
    connected = True


def test_the_stream_brakes_where_a_lagging_partner_would_slacken_the_sheet():
    """A 30 mm target shift toward a partner that has not moved: the stream brakes at the band's edge (within
    one braking distance) instead of closing the span; once the partner follows, it goes on to the target."""
    kl, kr, ql, qr, left = _home()
    t = _tracker(kl, ql)
    peer = kr.fk(qr)[:3, 3]
    t.peer_clamp = peer.copy()
    period = 0.0071
    qd = QD_MAX * 0.5
    lim = StreamLimiter(ql, period, qd, qd * 2.0, np.full(6, -3.0), np.full(6, 3.0))
    stream = ArmStream(t, lim, _NoLink(), clock=lambda: now)
    T = np.array(left, float)
    T[1, 3] -= 0.030
    now = 1.0
    t.set_target(T, now, now)
    spans = []
    for k in range(300):                                          # 2.1 s: far longer than the move needs
        now = 1.0 + k * period
        t.set_target(T, now, now)
        cmd = stream._next_command()
        spans.append(np.linalg.norm(kl.fk(cmd)[:3, 3] - peer))
    assert min(spans) > BAND[0] - 0.001 and t.span_waits > 0       # held at the edge (braking: < 1 mm past it)
    assert spans[-1] < BAND[0] + 0.001                            # and stays there, 20 mm short of the target
    assert np.linalg.norm(kl.fk(lim.c)[:3, 3] - T[:3, 3]) > 0.015
    t.peer_clamp = peer + np.array([0.0, -0.030, 0.0])           # the partner followed
    for k in range(300):
        now = 3.2 + k * period
        t.set_target(T, now, now)
        stream._next_command()
    assert np.linalg.norm(kl.fk(lim.c)[:3, 3] - T[:3, 3]) < 1e-4   # reached the target
