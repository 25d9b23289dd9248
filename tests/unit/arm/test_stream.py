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


class _LogLink:
    """A Modbus-like link (a second write per period allowed) that logs its calls in order; a read takes
    ``read_s`` wall seconds (a round trip on a busy loop)."""

    name = "log"
    rewrite_ok = True

    def __init__(self, q0, read_s):
        from flexsheet.arm.stream import Verdict
        from messages import registers as reg
        self.connected, self.on_ready, self.calls, self.read_s = True, None, [], read_s
        self.state = reg.ControllerState(reg.ST_ENABLED, 0, 0, 0, q0, np.zeros(6), 0, q0)
        self.verdict = Verdict(True)

    async def open(self):
        return True

    async def read(self):
        import asyncio
        self.calls.append("read")
        await asyncio.sleep(self.read_s)
        return self.state

    def supervise(self, st):
        return self.verdict

    async def send(self, cmd, rewrite=False):
        self.calls.append("rewrite" if rewrite else "send")
        return True

    async def keepalive(self):
        pass

    async def after_cycle(self):
        pass

    def ready_time(self):
        return None

    def next_deadline(self, deadline, t_start, period):
        return deadline + period

    async def close(self, end=False):
        pass

    def counters(self):
        return {}


def test_a_new_goal_leaves_before_the_next_cycles_read_even_when_that_cycle_is_due():
    """The wall-clock loop, its next cycle already overdue (a loop busy with other handlers) when a new goal
    arrives: the goal's command is the next thing sent (a rewrite of this period's step), not held behind the
    due cycle's read round trip; and the cycle then runs as scheduled."""
    import asyncio
    import time

    kl, t, peer, lim, stream, T, period = _shift_toward_partner(lambda: time.time())
    link = _LogLink(lim.c.copy(), read_s=0.004)
    stream.link = link

    async def scenario():
        task = asyncio.get_running_loop().create_task(stream.run(n_cycles=5))
        # the first cycle ran (a snapshot exists) and no read is in flight: a loaded machine can wake this
        # poll after the next cycle's read began, whose send would then rightly go first
        while link.calls.count("send") < 1 or link.calls[-1] != "send":
            await asyncio.sleep(0.0005)
        time.sleep(2 * period)                     # the loop is busy elsewhere: the next cycle is due
        t.set_target(T, time.time(), time.time())
        assert await stream.refresh()
        n = len(link.calls)
        await task
        return link.calls[n:]
    after = asyncio.run(scenario())
    assert after[0] == "rewrite", after                      # the new goal's command went first
    assert after[1:3] == ["read", "send"]                    # then the due cycle, read before its send
    assert stream.refreshes == 1
