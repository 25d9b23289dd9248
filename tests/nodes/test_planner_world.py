"""World twin node: typed finger truth, the sheet state from the measured joints through the truth's
kinematics (stretch by the one sheet geometry; the bridge's own pose is not used), and its script params are
FingerScript's fields."""

from __future__ import annotations

import asyncio
import math

import numpy as np
import pytest

from flexsheet.arm.kinematics import ArmKinematics, home_joints
from flexsheet.model.geometry import LEFT_BASE, RIGHT_BASE
from flexsheet.model.sheet import clamp_poses
from flexsheet.runtime.testing import NodeHarness
from flexsheet.twin.finger import FingerScript
from messages import ArmJointState, Header
from messages import topics as T
from nodes.world.node import Segment, WorldNode, WorldParams


def _arm(arm: str, q: np.ndarray, pose: np.ndarray, stamp: float) -> ArmJointState:
    return ArmJointState(header=Header(stamp=stamp), arm=arm, position=q, velocity=np.zeros(6), commanded=q,
                         executing=q,
                         pose=pose, status=0)


def _joints_for(T_clamp: np.ndarray, side: str) -> np.ndarray:
    kin = ArmKinematics(side, LEFT_BASE if side == "left" else RIGHT_BASE)
    res = kin.ik(T_clamp, home_joints(side))
    assert res.ok
    return res.q


def test_world_publishes_typed_truth_and_sheet_from_measured_joints(tmp_path, monkeypatch):
    monkeypatch.setenv("FLEXSHEET_CACHE", str(tmp_path))
    tilt = math.radians(20.0)
    n = np.array([math.cos(tilt), 0.0, -math.sin(tilt)])
    Tl, Tr = clamp_poses(np.zeros(3), n, np.array([0.0, 1.0, 0.0]), 0.05)
    ql, qr = _joints_for(Tl, "left"), _joints_for(Tr, "right")

    async def scenario():
        params = {"start_delay": 0.0, "script": [{"mode": "stroke_push", "moving_time": 2.0, "seed": 3}],
                  "rate_hz": 100.0, "sheet_rate_hz": 50.0, "twin": {"realism": "ideal"}}
        async with NodeHarness(WorldNode, params=params) as h:
            truth = (await h.wait_for(T.FINGER_TRUTH, n=2, timeout=3.0))[-1]
            assert ((truth.segment, truth.mode, truth.moving_time, truth.phase)
                    == (0, "stroke_push", 2.0, "approach"))
            assert truth.position[0] > 0.0                      # approaching from in front of the cylinder
            bad = Tl.copy()
            bad[:3, :3] *= 1.5                                  # the bridge's pose is not used: no effect
            h.inject(T.ARM_LEFT_STATE, _arm("left", ql, bad, h.node.now()))
            h.inject(T.ARM_RIGHT_STATE, _arm("right", qr, Tr, h.node.now()))
            sheet = (await h.wait_for(T.SHEET_STATE, n=1, timeout=3.0))[-1]
            assert h.rejected(T.ARM_LEFT_STATE) == 0
            # ideal twin: the true FK of the joints is the nominal model's, so the commanded sheet comes back
            assert sheet.stretch == pytest.approx(0.05, abs=1e-9)
            assert (sheet.normal == pytest.approx(n, abs=1e-9)
                    and sheet.origin == pytest.approx(np.zeros(3), abs=1e-9))
            assert (sheet.corners[0]
                    == pytest.approx([0.12 * math.sin(tilt), 0.126, 0.12 * math.cos(tilt)], abs=1e-9))
    asyncio.run(scenario())


def test_world_script_params_are_finger_script_fields():
    seg = Segment(mode="push", moving_time=3.0, push_depth=0.01, end_angle=0.5)
    assert seg.script() == FingerScript(mode="push", moving_time=3.0, push_depth=0.01, end_angle=0.5)
    assert Segment().script() == FingerScript()
    with pytest.raises(ValueError, match="moving_time"):
        WorldParams(script=[{"moving_time": -1.0}])
    with pytest.raises(ValueError, match="end_angle_deg"):    # SI only: the angle is end_angle, rad
        WorldParams(script=[{"end_angle_deg": 30.0}])


def test_world_publishes_the_scripts_target_mark_on_the_task_topic(tmp_path, monkeypatch):
    """/task/mark: the mark the script shows (its start point while the finger approaches), on the surface,
    with its outward normal."""
    monkeypatch.setenv("FLEXSHEET_CACHE", str(tmp_path))

    async def scenario():
        params = {"start_delay": 0.0, "script": [{"mode": "stroke", "moving_time": 2.0, "seed": 3}],
                  "rate_hz": 100.0, "sheet_rate_hz": 50.0, "twin": {"realism": "ideal"}}
        async with NodeHarness(WorldNode, params=params) as h:
            mark = (await h.wait_for(T.TASK_MARK, n=2, timeout=3.0))[-1]
            script = FingerScript(mode="stroke", moving_time=2.0, seed=3)
            q, n = script.surface_point(0.0)
            assert mark.visible and np.allclose(mark.point, q[0]) and np.allclose(mark.normal, n[0])
            assert np.linalg.norm(mark.normal) == pytest.approx(1.0)
    asyncio.run(scenario())
