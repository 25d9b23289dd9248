"""The planner's pull limit at its targets (flexsheet.planning.pull_guard): margin × the smaller arm's
torque-limited pull at the IK solution of each clamp target; a target IK cannot reach keeps the last
figure."""

from __future__ import annotations

import numpy as np
import pytest

from flexsheet.arm.kinematics import ArmKinematics
from flexsheet.arm.pull_limit import max_pull
from flexsheet.model.geometry import LEFT_BASE, RIGHT_BASE
from flexsheet.model.sheet import clamp_poses
from flexsheet.planning.pull_guard import PullGuard


def test_the_limit_is_the_weaker_arms_at_its_target_and_holds_over_an_unreachable_one():
    g = PullGuard({"left": LEFT_BASE, "right": RIGHT_BASE}, margin=0.8)
    rng = np.random.default_rng(2)
    for _ in range(3):
        tilt = float(rng.uniform(-0.5, 0.5))
        n = np.array([np.cos(tilt), 0.0, np.sin(tilt)])
        Tl, Tr = clamp_poses(rng.normal(0.0, 0.01, 3), n, np.array([0.0, 1.0, 0.0]), 0.05)
        lim = g.limit(Tl, Tr)
        pulls = []
        for side, T, base in (("left", Tl, LEFT_BASE), ("right", Tr, RIGHT_BASE)):
            kin = ArmKinematics(side, base)
            pulls.append(max_pull(kin, kin.ik(T, g.seed[side]).q)[0])
        assert lim == pytest.approx(0.8 * min(pulls), rel=1e-6) and 10.0 < lim < 40.0
    far = np.eye(4)
    far[:3, 3] = (0.0, 3.0, 0.0)                                  # 3 m away: no IK
    assert g.limit(far, far) == pytest.approx(lim, rel=1e-12)
    side, joint, pull = g.limiting()
    assert side in ("left", "right") and 1 <= joint <= 6 and pull == pytest.approx(lim / 0.8)
    with pytest.raises(ValueError, match="margin"):
        PullGuard({"left": LEFT_BASE, "right": RIGHT_BASE}, margin=0.0)
    with pytest.raises(ValueError, match="bases"):
        PullGuard({"left": LEFT_BASE})
