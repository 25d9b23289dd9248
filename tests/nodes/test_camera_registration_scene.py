"""The camera twin's registration scenes (``twin/scene``): what the camera sees while ``flexsheet calibrate
display --live`` drives the graph — the board on the sheet where the arms' joint states put it, the sheet lit
by the image on ``/projector/image``, the clamp markers in the dark — and the refusals of bad requests."""

import asyncio
import time

import cv2
import numpy as np
import pytest

from flexsheet.calibration import camera_pose as cp
from flexsheet.runtime.testing import NodeHarness
from flexsheet.twin.registration_camera import commanded_sheet_joints
from flexsheet.twin.truth import TwinTruth
from flexsheet.vision.stereo_calibration import parse_board
from messages import ArmJointState, Header, ProjectorImage, topics
from nodes.camera.node import CameraNode

PARAMS = {"rate_hz": 20.0, "drop_rate": 0.0, "twin": {"realism": "ideal", "truth_seed": 0}}
BOARD = parse_board("chessboard:9x8", 0.022)


def _joints(arm: str, q) -> ArmJointState:
    z = np.zeros(6)
    return ArmJointState(header=Header(stamp=time.time()), arm=arm, position=np.asarray(q, float), velocity=z,
                         commanded=z, executing=z, pose=np.eye(4), status=0)


def _hold(h, T_sheet) -> None:
    for side, q in commanded_sheet_joints(T_sheet).items():
        h.inject(topics.arm_state(side), _joints(side, q))


async def _fresh(h, n: int = 2):
    """A frame drawn after what was injected so far (skips ``n`` - 1 that may predate it)."""
    k = len(h.messages(topics.STEREO))
    return (await h.wait_for(topics.STEREO, n=k + n, timeout=20.0))[-1]


def test_board_scene_follows_the_arms_and_waits_for_them():
    async def scenario():
        async with NodeHarness(CameraNode, params=PARAMS) as h:
            call = {n: f for n, (f, *_) in h.node._pending_services.items()}
            assert call["twin/scene"]({"scene": "board"}) == "board"
            n0 = len(h.messages(topics.STEREO))
            await h.settle(0.5)
            assert len(h.messages(topics.STEREO)) == n0          # no joint states yet: nothing to draw
            _hold(h, np.eye(4))
            home = await _fresh(h)
            found = [cp.detect_corners(img, BOARD) for img in (home.left, home.right)]
            assert all(f is not None and len(f[1]) == BOARD.rows * BOARD.cols for f in found)
            tilted = cp.plan_board_views(2)[1]                     # 35° tilt: the corners move in the image
            _hold(h, tilted)
            moved = await _fresh(h)
            c1 = cp.detect_corners(moved.left, BOARD)
            assert c1 is not None
            shift = np.linalg.norm(c1[1].mean(axis=0) - found[0][1].mean(axis=0))
            spread = np.ptp(c1[1][:, 0]) / np.ptp(found[0][1][:, 0])
            assert shift > 5.0 or abs(spread - 1.0) > 0.1, (shift, spread)
            assert h.node.source.srv_twin_state({})["scene"] == "board"
            assert call["twin/scene"]({"scene": "finger"}) == "finger"
    asyncio.run(scenario())


def test_pattern_scene_lights_the_sheet_with_the_projected_image():
    truth = TwinTruth.draw(0, "ideal")
    w, h_ = truth.projector_size

    async def scenario():
        async with NodeHarness(CameraNode, params=PARAMS) as h:
            call = {n: f for n, (f, *_) in h.node._pending_services.items()}
            call["twin/scene"]({"scene": "patterns"})
            _hold(h, np.eye(4))
            dark = await _fresh(h)
            assert h.node.source.srv_twin_state({})["projector_stamp"] is None
            msg = ProjectorImage(header=Header(stamp=123.5, seq=7), image=np.full((h_, w), 255, np.uint8),
                                 showing=True, name="white.png")
            h.inject(topics.PROJECTOR_IMAGE, msg)
            await h.settle(0.2)
            assert h.node.source.srv_twin_state({})["projector_stamp"] == 123.5
            lit = await _fresh(h)
            gain = lit.left.astype(float) - dark.left.astype(float)
            assert np.percentile(gain, 95) > 80.0                # the sheet, lit white, ≫ the sensor noise
            assert np.percentile(gain, 5) < 10.0                 # the room around it stays dark
            h.inject(topics.PROJECTOR_IMAGE, ProjectorImage(header=Header(stamp=124.0, seq=8),
                                                            image=np.zeros((0, 0), np.uint8), showing=False))
            await h.settle(0.2)
            off = await _fresh(h)
            assert abs(float(off.left.mean()) - float(dark.left.mean())) < 1.0
    asyncio.run(scenario())


def test_marker_scene_shows_both_clamp_markers_in_the_dark():
    async def scenario():
        async with NodeHarness(CameraNode, params=PARAMS) as h:
            call = {n: f for n, (f, *_) in h.node._pending_services.items()}
            call["twin/scene"]({"scene": "markers"})
            _hold(h, np.eye(4))
            f = await _fresh(h)
            for img in (f.left, f.right):
                n, _ = cv2.connectedComponents((img > 150).astype(np.uint8))
                assert n - 1 == 2                                # background label excluded
                assert np.median(img) < 40                       # the room is dark
    asyncio.run(scenario())


@pytest.mark.parametrize("args,match", [
    ({"scene": "nope"}, "scene must be one of finger, board, patterns, markers, got 'nope'"),
    ({"scene": "board", "offset": 0.5}, r"offset must be within \[0, 0.02\] m, got 0.5"),
    ({"scene": "board", "colour": "red"}, "twin/scene takes scene, board, square, offset; got colour"),
    ({"scene": "board", "board": "chessboard:2"}, "board"),
])
def test_bad_scene_requests_are_refused_naming_the_field(args, match):
    async def scenario():
        async with NodeHarness(CameraNode, params=PARAMS) as h:
            call = {n: f for n, (f, *_) in h.node._pending_services.items()}
            with pytest.raises(ValueError, match=match):
                call["twin/scene"](args)
            assert h.node.source.scene.scene == "finger"                 # a refused request changes nothing
    asyncio.run(scenario())
