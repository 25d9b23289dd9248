"""The head camera port's twin: frames of the glasses at the true head, moved on to each frame's
mid-exposure."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from flexsheet.calibration.head_camera import design_head_camera
from flexsheet.model.truth_choice import TruthChoice
from flexsheet.twin.head import IPD_MEAN, NOMINAL_EYE_OFFSET, HeadMotion, Viewer
from flexsheet.twin.head_camera_source import TwinHeadCamera
from flexsheet.vision.glasses import GlassesBoard, GlassesTracker
from messages import Header, HeadTruth, topics


def _truth(hs, stamp, velocity, visible=True) -> HeadTruth:
    T = hs.T_display_glasses
    return HeadTruth(header=Header(stamp=stamp), position=T[:3, 3].copy(),
                     rotation=np.ascontiguousarray(T[:3, :3]),
                     left=hs.left, right=hs.right, eye=hs.eye, velocity=np.asarray(velocity, float),
                     visible=visible)


def test_frames_show_the_true_head_moved_on_to_mid_exposure_by_at_most_a_tenth_of_a_second():
    board = GlassesBoard()
    src = TwinHeadCamera.open(SimpleNamespace(twin=TruthChoice(realism="ideal"), exposure_s=0.004), board)
    assert src.inputs == (topics.HEAD_TRUTH,) and not src.blocking
    assert src.grab(1.0) is None                                    # no true head yet
    K, T, _, _ = design_head_camera()
    tracker = GlassesTracker(K, np.zeros(5), T, board, NOMINAL_EYE_OFFSET, IPD_MEAN)
    hs = HeadMotion(Viewer.draw(0, "ideal"), seed=3).state(0.2)
    v = np.array([0.0, 0.05, 0.0])                                   # 50 mm/s to the user's left
    src.feed(topics.HEAD_TRUTH, _truth(hs, 1.0, v))
    for t_mid, moved in ((1.0, 0.0), (1.06, 0.003), (1.5, 0.005)):   # the last clamped to 0.1 s
        pose = tracker.track(src.grab(t_mid))
        assert pose is not None
        assert np.linalg.norm(pose.V - (hs.eye + moved / 0.05 * v)) < 1.5e-3, (t_mid, pose.V - hs.eye)
    src.feed(topics.HEAD_TRUTH, _truth(hs, 2.0, v, visible=False))  # the glasses covered: nothing to track
    img = src.grab(2.0)
    assert img.dtype == np.uint8 and tracker.track(img) is None
    assert src.frame_latency(0.004) > 0.002                          # readout and transfer after mid-exposure
