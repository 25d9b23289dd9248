"""RV-1A kinematics (flexsheet.arm.kinematics): FK/IK round trip, reachability of the paper's sheet poses,
refusals with clear status, the datasheet's joint speeds in the URDF."""

import math

import numpy as np
import pinocchio as pin
import pytest

from flexsheet.arm.kinematics import (
    DATASHEET_SPEED_DEG,
    JOINT_NAMES,
    Q_LOWER,
    Q_UPPER,
    QD_MAX,
    URDF_PATH,
    ArmKinematics,
    home_joints,
    rotation_angle,
)
from flexsheet.arm.tracking import TargetTracker
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
                assert (np.all(res.q - Q_LOWER > math.radians(10))
                        and np.all(Q_UPPER - res.q > math.radians(10)))
                assert res.manipulability > 5e-3
            q = res.q


def test_home_joints_hold_the_home_clamp_frame():
    for side, base, idx in (("left", LEFT_BASE, 0), ("right", RIGHT_BASE, 1)):
        T = ArmKinematics(side, base).fk(home_joints(side))
        want = clamp_poses(np.zeros(3), np.array([1.0, 0, 0]), np.array([0.0, 1, 0]), 0.0)[idx]
        assert np.linalg.norm(T[:3, 3] - want[:3, 3]) < 1e-3
        assert np.allclose(T[:3, :3], want[:3, :3], atol=1e-3)   # columns (normal, axis_u, axis_v)


def test_joint_origins_follow_the_urdf_chain():
    """Base, J1…J6 and clamp points of the left arm at home, against the URDF's offsets by hand."""
    kin = ArmKinematics("left", LEFT_BASE)
    q = home_joints("left")
    p = kin.joint_origins(q)
    assert p.shape == (8, 3)
    base = np.array(LEFT_BASE[:3])
    np.testing.assert_allclose(p[0], base, atol=1e-12)
    np.testing.assert_allclose(p[1], base + (0.0, 0.0, 0.165), atol=1e-12)     # J1 on the base z axis
    np.testing.assert_allclose(p[2], base + (0.0, 0.0, 0.300), atol=1e-12)     # J2 0.135 m above J1
    # J3: the 0.250 m upper arm turned by J2 about y, then J1 + base yaw about z
    c1, s1 = math.cos(LEFT_BASE[3] + q[0]), math.sin(LEFT_BASE[3] + q[0])
    arm = 0.250 * np.array([math.sin(q[1]) * c1, math.sin(q[1]) * s1, math.cos(q[1])])
    np.testing.assert_allclose(p[3], p[2] + arm, atol=1e-12)
    lengths = np.linalg.norm(np.diff(p[3:], axis=0), axis=1)
    np.testing.assert_allclose(lengths, (math.hypot(0.090, 0.043), 0.117, 0.0527, 0.0493), atol=1e-12)
    np.testing.assert_allclose(p[7], kin.fk(q)[:3, 3], atol=1e-12)
    with pytest.raises(ValueError, match="q"):
        kin.joint_origins(np.zeros(7))


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


def test_urdf_speeds_are_the_rv1a_datasheet():
    # Mitsubishi BFP-A8050 RV-1A: J1 180, J2 90, J3 135, J4 180, J5 180, J6 210 deg/s
    assert DATASHEET_SPEED_DEG == (180.0, 90.0, 135.0, 180.0, 180.0, 210.0)
    model = pin.buildModelFromUrdf(str(URDF_PATH))
    for k, name in enumerate(JOINT_NAMES):
        j = model.getJointId(name)
        assert math.degrees(model.velocityLimit[model.joints[j].idx_v]) == pytest.approx(
            DATASHEET_SPEED_DEG[k],
                                                                                       abs=1e-9)
    assert np.degrees(QD_MAX) == pytest.approx(DATASHEET_SPEED_DEG, abs=1e-9)


@pytest.mark.parametrize("side", ["left", "right"])
def test_a_newton_step_converges_quadratically_and_its_rate_moves_the_clamp_at_the_twist(side):
    kin = ArmKinematics(side, LEFT_BASE if side == "left" else RIGHT_BASE)
    rng = np.random.default_rng(5)
    q = home_joints(side)
    for scale in (1e-2, 1e-3, 1e-4):
        dq = rng.normal(size=6) * scale
        T_goal = kin.fk(q + dq)
        twist = rng.normal(size=6) * 0.1
        q1, qd, err, w = kin.track(T_goal, q, twist)
        # the residual after one step is second order in the step (error 1e-2 rad -> 1e-4 and less)
        assert np.abs(q1 - (q + dq)).max() < 10.0 * scale ** 2, scale
        assert err > 0.1 * scale and abs(w - kin.manipulability(q)) < 1e-12
        # q̇ moves the clamp at the twist (clamp frame), checked by finite differences of the FK
        h = 1e-7
        T0, T1 = kin.fk(q), kin.fk(q + h * qd)
        v = T0[:3, :3].T @ (T1[:3, 3] - T0[:3, 3]) / h
        assert np.allclose(v, twist[:3], atol=1e-5)
    T, m = kin.fk_manipulability(q)
    assert np.abs(T - kin.fk(q)).max() < 1e-14 and abs(m - kin.manipulability(q)) < 1e-12


@pytest.mark.parametrize("side", ["left", "right"])
def test_step_rates_steps_as_track_and_its_rates_move_the_clamp_at_the_given_twists(side):
    kin = ArmKinematics(side, LEFT_BASE if side == "left" else RIGHT_BASE)
    rng = np.random.default_rng(11)
    q = home_joints(side)
    dq = rng.normal(size=6) * 1e-2
    T_goal = kin.fk(q + dq)
    twist = rng.normal(size=6) * 0.1
    rates = np.column_stack([twist, rng.normal(size=6)])
    qn, v = kin.step_rates(T_goal, q, twist, rates)
    assert np.array_equal(qn, kin.track(T_goal, q, twist)[0])      # the same Newton step, bit for bit
    assert np.abs(qn - (q + dq)).max() < 1e-3 and v.shape == (6, 2)
    # each column of rates is the clamp-frame twist its joint rates give at the stepped joints (finite
    # differences of the FK: translation part)
    h = 1e-7
    T0 = kin.fk(qn)
    for k in range(2):
        T1 = kin.fk(qn + h * v[:, k])
        assert np.allclose(T0[:3, :3].T @ (T1[:3, 3] - T0[:3, 3]) / h, rates[:3, k], atol=1e-5)


def test_an_iterate_that_lands_exactly_singular_is_damped_not_raised():
    # found by seeding the right arm at random for a sheet turned 40 deg about +z: the undamped step's
    # Jacobian became exactly singular (numpy.linalg.LinAlgError crashed the caller)
    from flexsheet.arm.kinematics import ArmKinematics

    kin = ArmKinematics("right", (-0.05, -0.55, -0.4, 1.5708))
    T = np.array([[0.7660444431189781, -0.6208851530148456, 0.16636567534280192, 0.07586951607162253],
                  [0.6427876096865394, 0.7399421116938482, -0.19826689127414618, -0.0775494773067559],
                  [0.0, 0.25881904510252074, 0.9659258262890684, 0.006336416222768142],
                  [0.0, 0.0, 0.0, 1.0]])
    seed = np.array([2.597358915927031, 1.0964283671416035, 1.099011804160582, -2.652494133165792,
                     -1.425696533795577, 2.250524942886251])
    r = kin.ik(T, seed, max_jump=100.0)
    assert r.status in ("ok", "unreachable", "singular", "jump") or r.status.startswith("limit:")
    assert np.all(np.isfinite(r.q))
    assert np.all(r.q >= kin.q_lower - 1e-9) and np.all(r.q <= kin.q_upper + 1e-9)
