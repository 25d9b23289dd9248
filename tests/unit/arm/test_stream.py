"""The arm's command stream (flexsheet.arm.stream): the span guard brakes a step that would take the clamp
span further outside its band, and goes on once the partner follows."""

import numpy as np
from test_tracking import BAND, _home, _tracker

from flexsheet.arm.kinematics import QD_MAX
from flexsheet.arm.limiter import StreamLimiter
from flexsheet.arm.stream import ArmStream


class _NoLink:
    connected = True


def _shift_toward_partner(clock):
    """The left arm at home, its partner's clamp known, a stream and a target 30 mm toward the partner."""
    kl, kr, ql, qr, left = _home()
    t = _tracker(kl, ql)
    peer = kr.fk(qr)[:3, 3]
    t.span.peer_clamp = peer.copy()
    period = 0.0071
    qd = QD_MAX * 0.5
    lim = StreamLimiter(ql, period, qd, qd * 2.0, np.full(6, -3.0), np.full(6, 3.0))
    stream = ArmStream(t, lim, _NoLink(), clock=clock)
    T = np.array(left, float)
    T[1, 3] -= 0.030
    return kl, t, peer, lim, stream, T, period


def test_the_stream_brakes_where_a_lagging_partner_would_slacken_the_sheet():
    """A 30 mm target shift toward a partner that is still moving but has not got there: the stream brakes at
    the band's edge (within one braking distance) instead of closing the span; once the partner follows, it
    goes on to the target."""
    kl, t, peer, lim, stream, T, period = _shift_toward_partner(lambda: now)
    now = 1.0
    t.set_target(T, now, now)
    spans = []
    for k in range(300):                                          # 2.1 s: far longer than the move needs
        now = 1.0 + k * period
        t.set_target(T, now, now)
        cmd = stream._next_command()
        spans.append(np.linalg.norm(kl.fk(cmd)[:3, 3] - peer))
    assert min(spans) > BAND[0] - 0.001 and t.span.waits > 0  # held at the edge (braking: < 1 mm past it)
    assert spans[-1] < BAND[0] + 0.001                            # and stays there, 20 mm short of the target
    assert np.linalg.norm(kl.fk(lim.c)[:3, 3] - T[:3, 3]) > 0.015
    t.span.peer_clamp = peer + np.array([0.0, -0.030, 0.0])           # the partner followed
    for k in range(300):
        now = 3.2 + k * period
        t.set_target(T, now, now)
        stream._next_command()
    assert np.linalg.norm(kl.fk(lim.c)[:3, 3] - T[:3, 3]) < 1e-4   # reached the target


def test_two_arms_each_waiting_for_the_other_step_together():
    """The same shift while the partner says it waits on its own span guard (``wait:span``): the step goes
    (the partner, waiting for this arm, would never move first) and the target is reached; without that the
    arm waits and says so."""
    kl, t, peer, lim, stream, T, period = _shift_toward_partner(lambda: now)
    now = 1.0
    for k in range(300):
        now = 1.0 + k * period
        t.set_target(T, now, now)
        stream._next_command()
        if k == 150:
            assert t.span.waiting and t.span.waits > 0            # waiting for a partner that does not wait
            waits = t.span.waits
            t.span.peer_waiting = True                            # the partner waits for this arm: step
    assert t.span.waits == waits and not t.span.waiting
    assert np.linalg.norm(kl.fk(lim.c)[:3, 3] - T[:3, 3]) < 1e-4
