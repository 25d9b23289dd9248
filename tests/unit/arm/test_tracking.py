"""The bridges' target tracker (flexsheet.arm.tracking): a jump is allowed once the arm could have moved that
far; which partner states hold this arm too (the span guard: test_span_guard.py)."""

import numpy as np
import pytest

from flexsheet.arm.kinematics import QD_MAX, ArmKinematics, home_joints
from flexsheet.arm.tracking import TargetTracker, peer_holds
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
    t.span.set_band(BAND)
    t.seed(ql)
    return t


def test_a_target_after_a_pause_may_ask_what_the_arm_could_move_meanwhile():
    """TargetTracker: within a flowing stream (targets 30 ms apart) a 0.9 rad change is a branch jump, refused
    with the goal kept; the same target after the stream paused 2 s (a planner respawning while the finger
    moved on) is taken: 0.5 rad + 2 s at the fastest joint's speed."""
    kin = ArmKinematics("left", LEFT_BASE)
    q = home_joints("left")
    q_far = q + np.array([0.9, 0.0, 0.0, 0.0, 0.0, 0.0])
    tr = TargetTracker(kin, target_timeout=0.25, max_jump=0.5)
    tr.seed(q)
    assert tr.set_target(kin.fk(q), 1.0, now=0.0).ok
    res = tr.set_target(kin.fk(q_far), 2.0, now=0.03)
    assert not res.ok and res.status == "jump" and np.allclose(tr.goal, q, atol=1e-6)
    assert tr.status(0.04) == "hold:jump"
    res = tr.set_target(kin.fk(q_far), 3.0, now=0.06)        # still flowing: still refused
    assert not res.ok and res.status == "jump"
    res = tr.set_target(kin.fk(q_far), 4.0, now=2.06)        # after a 2 s pause
    assert res.ok and np.abs(tr.goal - q_far).max() < 1e-6 and tr.status(2.07) == "ok"


def test_a_stream_that_starts_far_away_is_joined_once_the_arm_could_have_got_there():
    """After a release (a registration left the arm 0.9 rad away) targets flow every 20 ms from the start: the
    first are refused as a jump, but they do not start the stream, so the allowance grows from the release
    (0.5 rad + the fastest joint's speed × the time since) and a target is taken within 0.3 s; before, each
    refused target restarted the stream and the arm held on hold:jump for as long as targets came."""
    kin = ArmKinematics("left", LEFT_BASE)
    q = home_joints("left")
    q_far = q + np.array([0.9, 0.0, 0.0, 0.0, 0.0, 0.0])
    tr = TargetTracker(kin, target_timeout=0.25, max_jump=0.5)
    tr.move_to(q)
    tr.release(now=10.0)
    taken = None
    for k in range(50):
        if tr.set_target(kin.fk(q_far), 1.0 + k, now=10.0 + 0.02 * k).ok:
            taken = 0.02 * k
            break
    need = (0.9 - 0.5) / float(np.max(QD_MAX))
    assert taken is not None and need <= taken <= need + 0.021, (taken, need)
    assert np.abs(tr.goal - q_far).max() < 1e-6 and tr.status(10.0 + taken) == "ok"
    # once flowing, a branch jump is refused as before
    assert tr.set_target(kin.fk(q), 99.0, now=10.0 + taken + 0.02).status == "jump"


@pytest.mark.parametrize("status,holds",
                         [("hold:limit:J3", True), ("hold:jump", True), ("hold:unreachable", True),
                          ("fault:watchdog", True), ("disconnected", True), ("ok", False),
                          ("hold:no_target", False), ("hold:disabled", False),
                          ("hold:peer", False), ("hold:refused", False), ("manual", False)])
def test_which_partner_states_hold_this_arm_too(status, holds):
    kin = ArmKinematics("left", LEFT_BASE)
    q = home_joints("left")
    tr = TargetTracker(kin)
    tr.seed(q)
    assert tr.set_target(kin.fk(q + 0.05), 1.0, now=0.0).ok
    assert peer_holds(status) is holds
    tr.peer_hold = status if peer_holds(status) else None
    goal, vel = tr.reference(0.01, q)
    if holds:
        assert tr.status(0.01) == "hold:peer" and np.allclose(goal, q) and not vel.any()
    else:
        assert tr.status(0.01) == "ok" and np.allclose(goal, q + 0.05, atol=1e-6)


def test_a_target_in_the_viewers_keep_out_is_refused_and_the_partner_holds_with_it():
    from flexsheet.arm.tracking import TargetRefused
    from flexsheet.planning.keepout import KeepOut, arm_clearance

    kl, _, ql, _, left = _home()
    t = _tracker(kl, ql)
    ko = KeepOut(margin=0.03)
    forward = left.copy()
    forward[0, 3] += 0.02
    t.keep_out = lambda q: arm_clearance(ko, [0.40, 0.0, 0.0], kl, q) < 0.0     # the viewer at V: far away
    assert t.set_target(forward, 1.0, 1.0).ok and t.ik_status == "ok"
    goal = t.goal.copy()
    t.keep_out = lambda q: True                                                 # a head where the arm goes
    with pytest.raises(TargetRefused):
        t.set_target(left, 2.0, 1.01, strict=True)
    assert t.ik_status == "keep_out" and np.allclose(t.goal, goal)  # it stops short at the last goal
    assert t.status(1.02) == "hold:keep_out" and peer_holds("hold:keep_out")


def test_a_target_whose_pull_passes_a_joint_torque_is_refused_and_the_partner_holds_with_it():
    from flexsheet.arm.pull_limit import max_pull
    from flexsheet.arm.tracking import TargetRefused

    kl, _, ql, _, left = _home()
    t = _tracker(kl, ql)
    limit, joint = max_pull(kl, ql)
    assert t.set_target(left, 1.0, 1.0, pull=0.95 * limit).ok                # within the torque limit
    goal = t.goal.copy()
    with pytest.raises(TargetRefused):
        t.set_target(left, 2.0, 1.01, strict=True, pull=1.05 * limit)
    assert t.ik_status == f"torque:J{joint}" and np.allclose(t.goal, goal)
    assert t.status(1.02) == f"hold:torque:J{joint}" and peer_holds(f"hold:torque:J{joint}")


def test_the_span_guard_judges_a_partner_on_the_motion_where_the_motion_has_it_now():
    """Both arms follow the sheet's motion (a 40 mm move along y at up to 0.3 m/s). The partner's measurement,
    20 ms old (servo and a cycle), lags by mm: judged against it, this arm's step on the motion waits (what
    stalled the organ's repositioning); judged where the motion has the partner now, it does not. A partner
    that stopped, 40 mm off the motion, is judged where it was measured, and the step waits."""
    from flexsheet.arm.sheet_motion import SheetShaper
    from flexsheet.model.sheet import sheet_rotation
    kl, kr, ql, qr, _ = _home()
    R = sheet_rotation([1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    sh = SheetShaper()
    sh.update(0.0, np.zeros(3), R, 0.05)
    seg = sh.update(0.0, np.array([0.0, 0.04, 0.0]), R, 0.05)
    t = 0.5 * seg.duration
    Tl, Tr = seg.clamp("left", t)[0], seg.clamp("right", t)[0]
    q_now = kl.ik(Tl, ql).q
    q_next = kl.ik(seg.clamp("left", t + 0.0071)[0], q_now).q
    tr = _tracker(kl, ql)
    assert tr.set_target(seg.clamp("left", 10.0)[0], 0.0, 0.0, motion=seg).ok
    tr.span.set_band((0.2515, 0.2525))             # the planned span 0.252 m, ± 0.5 mm: a lag of mm shows
    tr.span.peer_clamp, tr.span.peer_stamp = seg.clamp("right", t - 0.02)[0][:3, 3], t - 0.02
    assert not tr.span_worse(q_now, q_next, at=t + 0.0071)
    tr.motion = None                               # the same step judged against the measurement itself
    assert tr.span_worse(q_now, q_next, at=t + 0.0071)
    tr.motion = seg
    tr.span.peer_clamp = Tr[:3, 3] - np.array([0.0, 0.04, 0.0])     # stopped: 40 mm off the motion
    assert tr.span_worse(q_now, q_next, at=t + 0.0071)


def test_on_the_motion_the_span_guard_keeps_the_motions_own_span_within_5_mm():
    """Both arms on the sheet's motion: the band is the motion's span ± 5 mm (SPAN_ON_MOTION), not the fixed
    band whose floor sits 1.2 mm under the planner's least stretch. A step 2 mm short of the motion (a turn's
    tracking) goes on though the fixed band says it is out; a step that takes the span 6 mm short waits; an
    arm left 20 mm over the span, its partner at rest on the motion's end, steps back toward it (no
    deadlock)."""
    from flexsheet.arm.sheet_motion import SheetShaper
    from flexsheet.arm.tracking import SPAN_ON_MOTION
    from flexsheet.model.sheet import sheet_rotation
    assert SPAN_ON_MOTION == pytest.approx(0.005)
    kl, kr, ql, qr, _ = _home()
    R = sheet_rotation([1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    sh = SheetShaper()
    sh.update(0.0, np.zeros(3), R, 0.01)
    seg = sh.update(0.0, np.array([0.0, 0.0, 0.03]), R, 0.01)        # planned span 0.2424 m
    t = 0.5 * seg.duration
    Tl, Tr = seg.clamp("left", t)[0], seg.clamp("right", t)[0]
    span = float(np.linalg.norm(Tl[:3, 3] - Tr[:3, 3]))
    assert span == pytest.approx(0.2424, abs=2e-4)
    tr = _tracker(kl, ql)
    tr.span.set_band((span - 0.0012, 0.264))  # the fixed band: floor 1.2 mm under the plan
    assert tr.set_target(seg.clamp("left", 10.0)[0], 0.0, 0.0, motion=seg).ok
    tr.span.peer_clamp, tr.span.peer_stamp = Tr[:3, 3], t
    toward = (Tr[:3, 3] - Tl[:3, 3]) / span                          # (3,) from this clamp to the partner's

    def q_at(offset_m):  # this clamp moved offset_m toward the partner
        T = Tl.copy()
        T[:3, 3] += offset_m * toward
        res = kl.ik(T, ql, max_jump=10.0)
        assert res.ok
        return res.q
    assert not tr.span_worse(q_at(0.0015), q_at(0.002), at=t)      # 2 mm short: inside the motion's band
    tr.motion = None
    assert tr.span_worse(q_at(0.0015), q_at(0.002), at=t)          # the fixed band alone would have waited
    tr.motion = seg
    assert tr.span_worse(q_at(0.0055), q_at(0.006), at=t)          # 6 mm short and getting shorter: waits
    assert not tr.span_worse(q_at(-0.020), q_at(-0.019), at=t)     # 20 mm over, stepping back: goes


def test_the_planners_joints_are_checked_not_solved_and_refused_ones_are_solved_here():
    """A target with the publisher's IK: taken as it is when it puts the clamp at the pose (the same goal as
    solving from the seed, with at most one Newton step instead of a solve); joints of another pose, outside
    the limits, or of a branch beyond the jump limit are not taken: IK solves from the seed, as without them,
    and a branch jump is still refused."""
    kin = ArmKinematics("left", LEFT_BASE)
    q0 = home_joints("left")
    q1 = q0 + np.array([0.05, -0.04, 0.03, 0.02, -0.05, 0.04])
    T1 = kin.fk(q1)
    solved = TargetTracker(kin, max_jump=0.5)
    solved.seed(q0)
    ref = solved.set_target(T1, 1.0, now=0.0)
    assert ref.ok and ref.iterations > 2                  # a solve from the seed takes several iterations
    tr = TargetTracker(kin, max_jump=0.5)
    tr.seed(q0)
    res = tr.set_target(T1, 1.0, now=0.0, q_planned=q1)
    assert res.ok and res.iterations <= 2 and (tr.planned_taken, tr.planned_solved) == (1, 0)
    assert np.abs(tr.goal - ref.q).max() < 1e-7            # the same goal
    T2 = kin.fk(q1 + 0.02)
    res = tr.set_target(T2, 2.0, now=0.01, q_planned=q1)    # joints of another pose: solved here
    assert res.ok and np.allclose(kin.fk(tr.goal), T2, atol=1e-8) and tr.planned_solved == 1
    outside = q1.copy()
    outside[2] = kin.q_upper[2] + 0.1
    assert tr.set_target(T1, 3.0, now=0.02, q_planned=outside).ok and tr.planned_solved == 2
    far = tr.goal + np.array([0.9, 0.0, 0.0, 0.0, 0.0, 0.0])
    res = tr.set_target(kin.fk(far), 4.0, now=0.03, q_planned=far)   # a branch jump: refused as before
    assert not res.ok and res.status == "jump" and tr.planned_solved == 3
