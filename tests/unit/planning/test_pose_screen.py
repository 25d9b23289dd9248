"""The planner's last screen of a pose (flexsheet.planning.pose_screen): the arms are kept out of the viewer's
keep-out by the bridges' own test, so no bridge refuses a plan for it."""

from __future__ import annotations

import numpy as np

from flexsheet.arm.bridge_config import BridgeConfig
from flexsheet.model import geometry
from flexsheet.model.shapes import make_shape
from flexsheet.model.sheet import clamp_poses
from flexsheet.planning.arm_reach import ArmReach
from flexsheet.planning.head_guard import HeadGuard
from flexsheet.planning.keepout import KeepOut, arm_keepout_clearance
from flexsheet.planning.planner_config import PlannerConfig
from flexsheet.planning.surface_planner import SurfacePlanner

BASES = {"left": geometry.LEFT_BASE, "right": geometry.RIGHT_BASE}
DT = 1.0 / 48.0
BRIDGE = KeepOut(margin=BridgeConfig.keepout_margin)       # the bridge's own keep-out (0.03 m)


def _home_joints(reach: ArmReach) -> dict:
    reach.solve(*clamp_poses(np.zeros(3), np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), 0.03, 0.24))
    return reach.solution()


def test_the_guard_judges_the_arms_by_the_bridges_test_at_its_larger_margin():
    reach = ArmReach(BASES)
    q = _home_joints(reach)
    g = HeadGuard()                                 # 0.05 m + the 0.01 m band
    rng = np.random.default_rng(3)
    refused = 0
    for V in rng.uniform([-0.1, -0.45, -0.2], [0.35, 0.45, 0.25], (400, 3)):
        g.eye = V
        v = g.arms(reach.kin, q)
        bridge = min(arm_keepout_clearance(BRIDGE, V, reach.kin[s], q[s])[0] for s in q)
        assert abs(v.clearance - (bridge - 0.03)) < 1e-12   # one geometry: the margins differ by 0.03 m
        if bridge < 0.0:
            refused += 1
            assert v.inside                          # whatever a bridge refuses, the planner does first
    assert refused > 10


def test_a_head_closing_on_an_arm_backs_the_sheet_off_and_no_plan_is_refused():
    reach = ArmReach(BASES)
    g = HeadGuard()
    pl = SurfacePlanner(make_shape("plane"), PlannerConfig(jump_distance=1.0), guard=g, arm_reach=reach)
    said = 0
    for k in range(240):                        # the head comes in toward the right arm at 0.1 m/s
        g.set_eye((0.10, -0.60 + 0.1 * k * DT, 0.02), True)
        plan = pl.update(k * DT, (0.01, 0.0, 0.0))
        said += "keep_out:right arm" in plan.status
        reach.solve(*plan.clamp_matrices(), commit=False)
        q = reach.solution()
        assert all(arm_keepout_clearance(BRIDGE, g.eye, reach.kin[s], q[s])[0] > 0.0 for s in q)
    assert said > 10                                # the plan says why it backed off
    assert plan.origin[0] < -0.02                   # away from the viewer, along -x
