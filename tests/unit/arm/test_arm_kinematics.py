"""RV-1A kinematics: FK/IK round trip, reachability of the paper's sheet poses, refusals with clear status."""

import math

import numpy as np
import pytest

from flexsheet.arm.kinematics import Q_LOWER, Q_UPPER, QD_MAX, ArmKinematics, home_joints, rotation_angle
from flexsheet.arm.tracking import TargetTracker, peer_holds
from flexsheet.model import geometry
from flexsheet.model.geometry import LEFT_BASE, RIGHT_BASE
from flexsheet.model.sheet import clamp_poses

R_CYL = geometry.CYLINDER_RADIUS


def tilted_clamps(theta, stretch):
    """Clamp poses of the sheet tangent to the cylinder at angle theta (contact (-R+R cos, 0, R sin))."""
    c, s = math.cos(theta), math.sin(theta)
    return clamp_poses(np.array([-R_CYL + R_CYL * c, 0.0, R_CYL * s]), np.array([c, 0.0, s]),
                             np.array([0.0, 1.0, 0.0]), stretch)


@pytest.mark.parametrize("side", ["left", "right"])
def test_fk_ik_round_trip_random_reachable_poses(side):
    base = LEFT_BASE if side == "left" else RIGHT_BASE
    kin = ArmKinematics(side, base)
    rng = np.random.default_rng(7)
    n_checked = 0
    while n_checked < 150:
        q = rng.uniform(Q_LOWER + 0.05, Q_UPPER - 0.05)
        if kin.manipulability(q) < 2e-3:     # keep clear of singular poses for the accuracy check
            continue
        T = kin.fk(q)
        seed = np.clip(q + rng.uniform(-0.15, 0.15, 6), Q_LOWER, Q_UPPER)
        res = kin.ik(T, seed)
        assert res.ok, (res.status, q, seed)
        T2 = kin.fk(res.q)
        assert np.linalg.norm(T2[:3, 3] - T[:3, 3]) <= 1e-5           # 0.01 mm
        assert math.degrees(rotation_angle(T2[:3, :3], T[:3, :3])) <= 0.01
        n_checked += 1


@pytest.mark.parametrize("side", ["left", "right"])
def test_home_sheet_and_tilts_reachable_with_margin(side):
    base = LEFT_BASE if side == "left" else RIGHT_BASE
    kin = ArmKinematics(side, base)
    idx = 0 if side == "left" else 1
    for sign in (1.0, -1.0):
        q = home_joints(side)
        for deg in range(0, 61, 5):
            for stretch in (0.0, 0.1):
                T = tilted_clamps(sign * math.radians(deg), stretch)[idx]
                res = kin.ik(T, q)
                assert res.ok, (side, sign * deg, stretch, res.status)
                assert np.all(res.q - Q_LOWER > math.radians(10)) and np.all(Q_UPPER - res.q > math.radians(10))
                assert res.manipulability > 5e-3
            q = res.q


def test_home_joints_hold_the_home_clamp_frame():
    for side, base, idx in (("left", LEFT_BASE, 0), ("right", RIGHT_BASE, 1)):
        T = ArmKinematics(side, base).fk(home_joints(side))
        want = clamp_poses(np.zeros(3), np.array([1.0, 0, 0]), np.array([0.0, 1, 0]), 0.0)[idx]
        assert np.linalg.norm(T[:3, 3] - want[:3, 3]) < 1e-3
        assert np.allclose(T[:3, :3], want[:3, :3], atol=1e-3)   # columns (normal, axis_u, axis_v)


def test_unreachable_target_refused_and_goal_kept():
    kin = ArmKinematics("left", LEFT_BASE)
    q0 = home_joints("left")
    far = kin.fk(q0)
    far[:3, 3] += np.array([0.0, -1.5, 0.0])          # 1.5 m beyond the clamp: outside the 0.6 m reach
    res = kin.ik(far, q0)
    assert not res.ok and (res.status == "unreachable" or res.status.startswith("limit:"))
    assert np.all(res.q >= Q_LOWER) and np.all(res.q <= Q_UPPER)
    tr = TargetTracker(kin)
    tr.seed(q0)
    tr.set_target(far, 1.0, now=0.0)
    assert np.array_equal(tr.goal, q0)                 # stops short: goal unchanged
    assert tr.status(0.01).startswith("hold:")


def test_target_beyond_joint_limit_reports_the_joint():
    q_upper = Q_UPPER.copy()
    q_upper[5] = math.radians(60.0)                    # J6 allowed only up to 60 deg here
    kin = ArmKinematics("left", LEFT_BASE, Q_LOWER, q_upper)
    q = home_joints("left").copy()
    q[5] = math.radians(50.0)
    T = kin.fk(q)
    q_goal = q.copy()
    q_goal[5] = math.radians(80.0)                     # needs J6 = 80 deg > 60
    res = kin.ik(kin.fk(q_goal), q, max_jump=10.0)
    assert not res.ok and res.status == "limit:J6"
    assert res.q[5] <= q_upper[5] + 1e-12
    assert kin.ik(T, q).ok


def test_wrist_singularity_reported():
    kin = ArmKinematics("left", LEFT_BASE)
    q = home_joints("left").copy()
    q[4] = 0.0                                          # J5 = 0: J4 and J6 aligned
    assert kin.manipulability(q) < 1e-9
    res = kin.ik(kin.fk(q), q + np.array([0, 0, 0, 0.0, 1e-4, 0]))
    assert not res.ok and res.status == "singular"


def test_branch_jump_refused():
    kin = ArmKinematics("left", LEFT_BASE)
    q = home_joints("left")
    q_far = q + np.array([0.9, 0.0, 0.0, 0.0, 0.0, 0.0])
    res = kin.ik(kin.fk(q_far), q, max_jump=0.5)
    assert not res.ok and res.status == "jump"


def test_a_target_after_a_pause_may_ask_what_the_arm_could_move_meanwhile():
    """TargetTracker: within a flowing stream (targets 30 ms apart) a 0.9 rad change is a branch jump, refused
    with the goal kept; the same target after the stream paused 2 s (a planner respawning while the finger moved
    on) is taken: 0.5 rad + 2 s at the fastest joint's speed."""
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


@pytest.mark.parametrize("status,holds", [("hold:limit:J3", True), ("hold:jump", True), ("hold:unreachable", True),
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


@pytest.mark.parametrize("bad", [np.full((4, 4), np.nan), np.eye(3), np.diag([2.0, 1.0, 1.0, 1.0])])
def test_malformed_pose_raises_value_error(bad):
    kin = ArmKinematics("left", LEFT_BASE)
    with pytest.raises(ValueError, match="T_target"):
        kin.ik(bad, home_joints("left"))


def test_bad_side_and_seed_raise():
    with pytest.raises(ValueError, match="side"):
        ArmKinematics("middle")
    kin = ArmKinematics("left", LEFT_BASE)
    with pytest.raises(ValueError, match="q must"):
        kin.fk([0.0, 1.0])
