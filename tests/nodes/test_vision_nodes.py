"""Camera and triangulator nodes through the in-process harness (real encode/decode)."""

import asyncio

import numpy as np

from flexsheet.runtime.codec import encode
from flexsheet.runtime.testing import NodeHarness
from flexsheet.twin.camera import StereoCameraTwin
from flexsheet.twin.camera_config import SimConfig
from flexsheet.vision.camera_model import DEFAULT_CAMERA_POSITION, camera_model, look_at
from flexsheet.vision.stereo_calibration import to_message
from messages import FingerTruth, Header, StereoFrame, topics
from nodes.camera.node import CameraNode
from nodes.triangulator.node import TriangulatorNode

CALIB = camera_model("ximea")
T_DC = look_at(DEFAULT_CAMERA_POSITION)
RENDER = StereoCameraTwin(CALIB, T_DC, SimConfig.ideal(seed=4))   # node mechanics: the ideal twin's sensing
IDEAL = {"realism": "ideal", "truth_seed": 0}


def _frame(left, right, stamp, seq=0, skew=0.0):
    return StereoFrame(header=Header(stamp=stamp, frame_id="camera_left", seq=seq), left=left, right=right,
                       exposure_stamp=stamp, exposure_time=0.004, stereo_skew=skew)


def _calib_msg():
    return to_message(CALIB, Header(stamp=0.0, frame_id="camera_left"), T_DC)


def test_triangulator_valid_invalid_and_bad_frames():
    async def scenario():
        async with NodeHarness(TriangulatorNode, params={"method": "optimal"}) as h:
            p = np.array([0.02, 0.01, 0.01])
            L, R = RENDER.render(p)
            h.inject(topics.STEREO, _frame(L, R, 100.0))             # before calibration: rejected
            await h.settle(0.1)
            assert h.rejected(topics.STEREO) == 1 and not h.messages(topics.FINGERTIP)
            h.inject(topics.CALIBRATION, _calib_msg())
            await h.settle(0.1)
            stamps = []
            for k in range(3):
                h.inject(topics.STEREO, _frame(L, R, 101.0 + k / 48, seq=k + 1))
                stamps.append(101.0 + k / 48)
                await h.wait_for(topics.FINGERTIP, n=k + 1, timeout=3.0)
            out = h.messages(topics.FINGERTIP)
            for m, st in zip(out, stamps, strict=False):
                assert m.valid and m.exposure_stamp == st and m.header.frame_id == "display"
                e = m.position - p
                assert e @ np.linalg.solve(m.covariance, e) < 14.16  # within 3σ (χ²₃)
            # occlusion: marker hidden -> invalid, zero position (never stale)
            Lh, Rh = RENDER.render(p, visible=False)
            h.inject(topics.STEREO, _frame(Lh, Rh, 102.0, seq=10))
            out = await h.wait_for(topics.FINGERTIP, n=4, timeout=3.0)
            assert (not out[-1].valid and np.all(out[-1].position == 0)
                    and np.all(out[-1].predicted_position == 0))
            # bad frames: wrong size, unsynchronised pair, wrong dtype (bypassing the sender's validation)
            h.inject(topics.STEREO, _frame(L[:100], R[:100], 102.1, seq=11))
            await h.settle(0.1)
            assert "left has shape (100, 640), expected (512, 640)" in h.node.last_rejection
            h.inject(topics.STEREO, _frame(L, R, 102.2, seq=12, skew=0.01))
            await h.settle(0.1)
            assert "stereo_skew 0.0100 s exceeds" in h.node.last_rejection
            bad = StereoFrame.model_construct(header=Header(stamp=102.3, seq=13), left=L.astype(np.uint16),
                                              right=R.astype(np.uint16), exposure_stamp=102.3,
                                              exposure_time=0.0,
                                              stereo_skew=0.0)
            h.transport.deliver(encode(topics.STEREO.name, bad))
            await h.settle(0.1)
            assert "uint8" in h.node.last_rejection and "uint16" in h.node.last_rejection
            h.inject_raw(topics.STEREO, [b"garbage"])
            await h.settle(0.1)
            assert h.rejected(topics.STEREO) == 1 + 4
            assert len(h.messages(topics.FINGERTIP)) == 4                 # nothing published for bad frames
            # ... and the node keeps running: a good frame gives a valid fix again
            h.inject(topics.STEREO, _frame(L, R, 102.5, seq=14))
            out = await h.wait_for(topics.FINGERTIP, n=5, timeout=3.0)
            assert out[-1].valid and np.linalg.norm(out[-1].position - p) < 2e-3
    asyncio.run(scenario())


def test_triangulator_prediction_horizon():
    async def scenario():
        async with NodeHarness(TriangulatorNode, params={"horizon_s": 0.05}) as h:
            h.inject(topics.CALIBRATION, _calib_msg())
            await h.settle(0.1)
            v = np.array([0.0, 0.2, 0.0])
            p0 = np.array([0.02, -0.05, 0.0])
            for k in range(20):
                t = 200.0 + k / 48
                L, R = RENDER.render(p0 + v * (k / 48), v)
                h.inject(topics.STEREO, _frame(L, R, t, seq=k))
                await h.wait_for(topics.FINGERTIP, n=k + 1, timeout=3.0)
            last = h.messages(topics.FINGERTIP)[-1]
            assert last.valid and last.prediction_horizon == 0.05
            truth_ahead = p0 + v * (19 / 48 + 0.05)
            assert np.linalg.norm(last.predicted_position - truth_ahead) < 3e-3
            assert np.linalg.norm(last.position - truth_ahead) > 8e-3          # the prediction really leads
    asyncio.run(scenario())


def test_camera_node_sim_follows_finger_truth():
    async def scenario():
        async with NodeHarness(CameraNode, params={"rate_hz": 50.0, "seed": 1, "twin": IDEAL}) as h:
            cal = (await h.wait_for(topics.CALIBRATION, n=1, timeout=3.0))[0]
            assert tuple(cal.image_size) == (640, 512) and np.allclose(cal.T_display_camera, T_DC)
            p = np.array([0.025, 0.03, -0.02])
            h.inject(topics.FINGER_TRUTH, FingerTruth(header=Header(stamp=h.node.now()), position=p,
                                                      velocity=np.zeros(3)))
            await h.settle(0.15)
            n0 = len(h.messages(topics.STEREO))
            frames = await h.wait_for(topics.STEREO, n=n0 + 2, timeout=3.0)
            f = frames[-1]
            # published after exposure
            assert f.left.shape == (512, 640) and f.header.stamp >= f.exposure_stamp
            from flexsheet.vision.tracker import FingertipTracker
            res = FingertipTracker(cal).process(f.left, f.right, f.exposure_stamp)
            assert res.valid and np.linalg.norm(res.position - p) < 2e-3
            # occluded marker in the world -> no marker in the images
            h.inject(topics.FINGER_TRUTH, FingerTruth(header=Header(stamp=h.node.now(), seq=1), position=p,
                                                      velocity=np.zeros(3), visible=False))
            await h.settle(0.15)
            n1 = len(h.messages(topics.STEREO))
            f = (await h.wait_for(topics.STEREO, n=n1 + 1, timeout=3.0))[-1]
            assert not FingertipTracker(cal).process(f.left, f.right, f.exposure_stamp).valid
            # the viewers' preview: the same pairs, decimated to preview_rate (5 Hz) of the 50 Hz stream
            full = {m.exposure_stamp: m for m in h.messages(topics.STEREO)}
            prev = h.messages(topics.STEREO_PREVIEW)
            assert len(prev) >= 2 and all(np.array_equal(m.left, full[m.exposure_stamp].left) for m in prev)
            gaps = np.diff([m.exposure_stamp for m in prev])
            assert np.all(gaps >= 0.2 - 0.5 / 50.0 - 1e-9), gaps              # never faster than 5 Hz
            assert len(prev) <= len(full) / 8, (len(prev), len(full))
    asyncio.run(scenario())


def test_camera_node_holds_a_stale_finger_truth_and_never_returns_to_the_param_path():
    """A world node that stalls (no /world/finger for 1 s, as the loaded 2-core machine once did for 0.7 s)
    leaves the marker where its last truth put it, extrapolated at most 0.1 s with the truth's velocity. It
    never falls back to the param stroke: that would be a second finger ~20 mm away."""
    async def scenario():
        async with NodeHarness(CameraNode, params={"rate_hz": 50.0, "seed": 2, "twin": IDEAL}) as h:
            cal = (await h.wait_for(topics.CALIBRATION, n=1, timeout=3.0))[0]
            # 15 mm to the side of the param path's plane (y = 0): never within 5 mm of it, whenever the frame
            p, v = np.array([-0.010, 0.015, 0.024]), np.array([-0.02, 0.0, 0.03])
            h.inject(topics.FINGER_TRUTH,
                     FingerTruth(header=Header(stamp=h.node.now()), position=p, velocity=v))
            await h.settle(1.0)
            n0 = len(h.messages(topics.STEREO))
            f = (await h.wait_for(topics.STEREO, n=n0 + 2, timeout=3.0))[-1]
            from flexsheet.twin.camera import default_trajectory
            from flexsheet.vision.tracker import FingertipTracker
            res = FingertipTracker(cal).process(f.left, f.right, f.exposure_stamp)
            held = p + 0.1 * v                                       # the extrapolation stops at 0.1 s
            assert res.valid and np.linalg.norm(res.position - held) < 2e-3, (res.position, held)
            param, _ = default_trajectory(f.exposure_stamp - h.node.source._t0)
            assert np.linalg.norm(res.position - param) > 5e-3       # not the param path's finger
            line = h.node.status_line()
            assert "finger: /world/finger, last" in line and "s ago" in line, line
            age = float(line.split("finger: /world/finger, last ")[1].split(" s ago")[0])
            assert age >= 1.0, line
    asyncio.run(scenario())


def test_camera_node_falls_back_to_trajectory_bumblebee2():
    async def scenario():
        async with NodeHarness(CameraNode,
                               params={"model": "bumblebee2", "rate_hz": 50.0, "twin": IDEAL}) as h:
            cal = (await h.wait_for(topics.CALIBRATION, n=1, timeout=3.0))[0]
            assert tuple(cal.image_size) == (640, 480) and abs(cal.K1[0, 0] - 513.5) < 0.1
            assert abs(np.linalg.norm(cal.T) - 0.12) < 1e-9
            f = (await h.wait_for(topics.STEREO, n=2, timeout=3.0))[-1]
            from flexsheet.twin.camera import default_trajectory
            from flexsheet.vision.tracker import FingertipTracker
            res = FingertipTracker(cal).process(f.left, f.right, f.exposure_stamp)
            truth, _ = default_trajectory(f.exposure_stamp - h.node.source._t0)
            assert res.valid and np.linalg.norm(res.position - truth) < 2e-3
    asyncio.run(scenario())


def test_camera_link_delay_needs_the_simulated_clock():
    """link_delay_s (the stability sweep's delay) is charged on the simulated clock only; on the wall clock
    the camera twin refuses it at set-up, naming it, and a negative one is refused by the params."""
    import pydantic
    import pytest

    from flexsheet.runtime.config import ConfigError

    async def scenario():
        async with NodeHarness(CameraNode, params={"rate_hz": 50.0, "twin": IDEAL, "link_delay_s": 0.05}):
            pass

    with pytest.raises((ValueError, ConfigError), match="link_delay_s 0.05 is the camera twin.s on the "
                                                        "simulated clock"):
        asyncio.run(scenario())
    with pytest.raises(pydantic.ValidationError, match="link_delay_s"):
        CameraNode.Params.model_validate({"link_delay_s": -0.01})
