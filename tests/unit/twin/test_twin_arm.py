"""The arm twin's speeds are the RV-1A datasheet's, and with them the planner's stroke (and stroke + push) stays
reachable and within the bridge's commanded speed on the realistic twin, three truth seeds."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

from flexsheet.arm.kinematics import DATASHEET_SPEED_DEG, JOINT_NAMES, QD_MAX, URDF_PATH
from flexsheet.experiments.stroke_model import ArmChain, make_twin, simulate


def test_urdf_speeds_are_the_rv1a_datasheet():
    # Mitsubishi BFP-A8050 RV-1A: J1 180, J2 90, J3 135, J4 180, J5 180, J6 210 deg/s
    assert DATASHEET_SPEED_DEG == (180.0, 90.0, 135.0, 180.0, 180.0, 210.0)
    model = pin.buildModelFromUrdf(str(URDF_PATH))
    for k, name in enumerate(JOINT_NAMES):
        j = model.getJointId(name)
        assert math.degrees(model.velocityLimit[model.joints[j].idx_v]) == pytest.approx(DATASHEET_SPEED_DEG[k],
                                                                                       abs=1e-9)
    assert np.degrees(QD_MAX) == pytest.approx(DATASHEET_SPEED_DEG, abs=1e-9)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_stroke_and_push_fit_the_datasheet_speeds_on_the_realistic_twin(seed):
    stats: dict = {}
    row = simulate(10.0, make_twin("realistic", seed), seed=seed, stats=stats,
                   finger_kw={"mode": "stroke_push", "push_depth": 0.010})
    assert stats["ik_refused"] == 0                                   # every target reachable by the IK
    assert stats["peak_joint_speed_ratio"] < ArmChain().speed_scale   # below the bridge's command limit
    assert row["n"] > 300 and row["dtheta_mean_deg"] < 2.0
