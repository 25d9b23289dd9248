"""The sheet's pull against the arm's joint torques (flexsheet.arm.pull_limit): Jᵀ·F agrees with the virtual
work of the pull along the clamp's motion (finite differences of the forward kinematics, independent of the
Jacobian), the largest pull loads exactly one joint to its limit, and at the home pose a 40 N pull passes the
J3 limit that the rated 1 kg sets (3.34 against 2.80 N·m)."""

from __future__ import annotations

import numpy as np
import pytest

from flexsheet.arm.kinematics import Q_LOWER, Q_UPPER, ArmKinematics, home_joints
from flexsheet.arm.pull_limit import TORQUE_LIMITS, joint_torques, max_pull
from flexsheet.model.geometry import LEFT_BASE, RIGHT_BASE


@pytest.mark.parametrize("side", ["left", "right"])
def test_torques_are_the_virtual_work_of_the_pull(side):
    kin = ArmKinematics(side, LEFT_BASE if side == "left" else RIGHT_BASE)
    rng = np.random.default_rng(4 if side == "left" else 5)
    for q in [home_joints(side)] + [home_joints(side) + rng.normal(0.0, 0.2, 6) for _ in range(4)]:
        q = np.clip(q, Q_LOWER + 0.05, Q_UPPER - 0.05)
        F = float(rng.uniform(5.0, 50.0))
        T = kin.fk(q)
        f = F * (-T[:3, 1] if side == "left" else T[:3, 1])         # toward the sheet's centre along axis_u
        h = 1e-6
        work = []
        for j in range(6):
            dq = np.zeros(6)
            dq[j] = h
            dp = (kin.fk(q + dq)[:3, 3] - kin.fk(q - dq)[:3, 3]) / (2 * h)
            work.append(f @ dp)  # τ_j = f · ∂p/∂q_j (no moment at the clamp)
        np.testing.assert_allclose(joint_torques(kin, q, F), work, atol=1e-6 * F)


def test_the_largest_pull_loads_one_joint_to_its_limit_and_home_passes_j3_at_40n():
    kin = ArmKinematics("left", LEFT_BASE)
    q = home_joints("left")
    tau40 = joint_torques(kin, q, 40.0)
    assert abs(tau40[2]) == pytest.approx(3.34, abs=0.01) and abs(tau40[2]) > TORQUE_LIMITS[2]
    f, joint = max_pull(kin, q)
    assert joint == 3 and 30.0 < f < 40.0
    tau = np.abs(joint_torques(kin, q, f))
    assert tau[2] == pytest.approx(TORQUE_LIMITS[2], rel=1e-9) and np.all(tau <= TORQUE_LIMITS * (1 + 1e-9))
    doubled = max_pull(kin, q, TORQUE_LIMITS * 2.0)
    assert doubled[0] == pytest.approx(2.0 * f, rel=1e-9)
    with pytest.raises(ValueError, match="pull"):
        joint_torques(kin, q, -1.0)
    with pytest.raises(ValueError, match="limits"):
        max_pull(kin, q, [1.0, 2.0])
    with pytest.raises(ValueError, match="q must"):
        max_pull(kin, [0.0] * 5)
