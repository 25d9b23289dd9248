"""The head camera node (the twin's camera) and the planner's head guard through the in-process harness."""

import asyncio
import time

import numpy as np
import pytest

from flexsheet.calibration.display_calib import HeadCameraEntry, Provenance, nominal_display_calib
from flexsheet.calibration.display_calib_file import write_display_calib
from flexsheet.calibration.eye import tracked_eye_entry
from flexsheet.calibration.head_camera import design_head_camera
from flexsheet.model import geometry
from flexsheet.runtime.testing import NodeHarness
from flexsheet.twin.head import IPD_MEAN, NOMINAL_EYE_OFFSET, HeadMotion, Viewer
from messages import EyePose, Fingertip, Header, HeadTruth, topics
from nodes.head_camera.node import HeadCameraNode
from nodes.planner.node import PlannerNode

IDEAL = {"realism": "ideal", "truth_seed": 0}


def _display_yaml(tmp_path, head=True) -> str:
    c = nominal_display_calib()
    c.eye = tracked_eye_entry(geometry.EYE, IPD_MEAN, NOMINAL_EYE_OFFSET, "test")
    if head:
        K, T, w, h = design_head_camera()
        c.head_camera = HeadCameraEntry(K, np.zeros(5), w, h, T, Provenance("test"))
    path = str(tmp_path / "display.yaml")
    write_display_calib(path, c)
    return path


def _truth(hs, stamp) -> HeadTruth:
    """The head held still at ``hs`` (velocity 0: the wall-clock node renders it a few ms after ``stamp``)."""
    T = hs.T_display_glasses
    return HeadTruth(header=Header(stamp=stamp), position=T[:3, 3].copy(),
                     rotation=np.ascontiguousarray(T[:3, :3]),
                     left=hs.left, right=hs.right, eye=hs.eye, velocity=np.zeros(3), visible=hs.visible)


def test_the_node_tracks_the_twins_head_and_says_when_the_glasses_are_lost(tmp_path):
    head = HeadMotion(Viewer.draw(0, "ideal"), seed=3, occlusions=((0.5, 10.0),))

    async def scenario():
        async with NodeHarness(HeadCameraNode,
                               params={"source": "sim", "display_calib": _display_yaml(tmp_path),
                                       "twin": IDEAL, "rate_hz": 30.0}) as h:
            t0 = time.time()
            hs = head.state(0.2)
            h.inject(topics.HEAD_TRUTH, _truth(hs, t0))
            out = await h.wait_for(topics.EYE_POSE, n=3, timeout=5.0)
            good = [m for m in out if m.valid]
            assert good, [m.valid for m in out]
            for m in good:
                assert (np.linalg.norm(m.left - hs.left) < 1.5e-3
                        and np.linalg.norm(m.right - hs.right) < 1.5e-3)
                assert m.markers >= 10 and m.reprojection_px < 0.5 and m.header.frame_id == "display"
            h.inject(topics.HEAD_TRUTH, _truth(head.state(1.0), time.time()))      # the glasses occluded
            n = len(h.messages(topics.EYE_POSE))
            out = await h.wait_for(topics.EYE_POSE, n=n + 3, timeout=5.0)
            lost = out[-1]
            assert not lost.valid and lost.age > 0.0 and np.allclose(lost.left, good[-1].left)
    asyncio.run(scenario())


def test_without_a_head_camera_entry_the_node_names_the_fix(tmp_path):
    async def scenario():
        with pytest.raises(Exception, match="no head_camera entry"):
            async with NodeHarness(HeadCameraNode, params={"source": "sim", "twin": IDEAL,
                                                           "display_calib": _display_yaml(tmp_path,
                                                                                          head=False)}):
                pass
    asyncio.run(scenario())


def _ft(p, stamp):
    p = np.asarray(p, float)
    return Fingertip(header=Header(stamp=stamp), position=p, covariance=np.eye(3) * 1e-8, valid=True,
                     predicted_position=p, prediction_horizon=0.0, exposure_stamp=stamp - 0.012)


def _eye(eye, valid, stamp):
    e = np.asarray(eye, float)
    return EyePose(header=Header(stamp=stamp), position=e, rotation=np.eye(3), left=e - [0, 0.032, 0],
                   right=e + [0, 0.032, 0], eye=e, velocity=np.zeros(3), valid=valid)


def test_the_planner_holds_when_the_glasses_are_lost_and_keeps_the_sheet_out_of_the_head():
    async def scenario():
        async with NodeHarness(PlannerNode, params={"object_stiffness": 20.0,
                                                    "stiffness_from_scene": False}) as h:
            t = time.time()
            h.inject(topics.EYE_POSE, _eye(geometry.EYE, True, t))
            await h.settle(0.05)
            h.inject(topics.FINGERTIP, _ft([0.02, 0.0, 0.0], t))
            st = (await h.wait_for(topics.SHEET_TARGET, n=1))[0]
            assert st.status == "ok"
            h.inject(topics.EYE_POSE, _eye(geometry.EYE, False, t + 0.01))
            await h.settle(0.05)
            h.inject(topics.FINGERTIP, _ft([0.02, 0.0, 0.0], t + 0.02))
            out = await h.wait_for(topics.SHEET_TARGET, n=2)
            assert out[1].status == "hold:head_lost" and np.array_equal(out[1].sheet_origin, st.sheet_origin)
            # the head leans right up to the sheet: the next step backs off along -x instead
            h.inject(topics.EYE_POSE, _eye([0.07, 0.0, 0.0], True, t + 0.03))
            await h.settle(0.05)
            h.inject(topics.FINGERTIP, _ft([0.02, 0.0, 0.0], t + 0.04))
            out = await h.wait_for(topics.SHEET_TARGET, n=3)
            assert "hold:keep_out" in out[2].status and out[2].sheet_origin[0] < st.sheet_origin[0]
    asyncio.run(scenario())
