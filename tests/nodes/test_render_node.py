"""RendererNode through the in-process harness: frames, model choice, latency stamp, rejected input."""

import asyncio
import time

import numpy as np
import pydantic
import pytest

from flexsheet.runtime.testing import NodeHarness
from messages import ArmJointState, Fingertip, Header, ObjectDeformation, topics
from nodes.renderer.node import RendererNode
from nodes.renderer.params import RendererParams

PARAMS = {"width": 128, "height": 96, "publish_rate": 30.0, "publish_scale": 0.5}


def fingertip(pos, stamp=100.0, valid=True):
    p = np.asarray(pos, dtype=float)
    return Fingertip(header=Header(stamp=time.time()), position=p, covariance=np.eye(3) * 1e-8, valid=valid,
                     predicted_position=p, exposure_stamp=stamp)


def arm(name, T):
    z = np.zeros(6)
    return ArmJointState(header=Header(stamp=time.time()), arm=name, position=z, velocity=z, commanded=z,
                         executing=z,
                         pose=np.asarray(T, dtype=float), status=0)


async def next_frame(h, timeout=10.0):
    n = len(h.messages(topics.RENDERED))
    return (await h.wait_for(topics.RENDERED, n=n + 2, timeout=timeout))[-1]


async def frame_with(h, model, timeout):
    """Frames until one drawn with ``model`` (returned) or ``timeout`` s; the models seen before it."""
    seen, t_end = [], time.monotonic() + timeout
    while time.monotonic() < t_end:
        m = await next_frame(h, timeout=max(10.0, t_end - time.monotonic()))
        if m.correction == model:
            return m, seen
        seen.append(m.correction)
    raise AssertionError(f"no frame drawn with {model!r} in {timeout} s; saw {sorted(set(seen))}")


def test_frames_model_choice_and_source_stamp():
    # the planner's stretch 0.04: its pushed-sheet table is cached after the
    # first run on a machine (built in the node's worker process otherwise,
    # ~30 s of one core; pushes are drawn with the 4-triangle model meanwhile)
    from flexsheet.model.sheet import clamp_poses

    async def scenario():
        async with NodeHarness(RendererNode, params=PARAMS) as h:
            m = await next_frame(h)
            assert m.left.shape == (48, 64, 3) and m.right.shape == (48, 64, 3)
            assert m.correction == "flat" and m.left.max() > 100          # the cylinder is drawn
            Tl, Tr = clamp_poses(np.zeros(3), [1.0, 0, 0], [0, 1.0, 0], 0.04)
            h.inject(topics.ARM_LEFT_STATE, arm("left", Tl))
            h.inject(topics.ARM_RIGHT_STATE, arm("right", Tr))
            h.inject(topics.FINGERTIP, fingertip([-0.03, 0.0, 0.0], stamp=123.5))
            await h.settle(0.1)
            m, before = await frame_with(h, "fine", timeout=600.0)  # 30 mm push: 4-triangle misses 0.7 mm
            assert set(before) <= {"four_triangle"}                         # never uncorrected while it waits
            assert m.source_stamp == 123.5
            h.inject(topics.FINGERTIP, fingertip([0.05, 0.0, 0.0], stamp=124.0))   # in front: not pushing
            await h.settle(0.1)
            m = await next_frame(h)
            assert m.correction == "flat"
            assert h.rejected() == 0
    asyncio.run(scenario())


def test_missing_sheet_table_is_built_in_a_worker_while_drawing(tmp_path):
    """A push at a stretch whose table is not cached: drawn with the 4-triangle model (said in the
    diagnostics) while a worker process builds it, then with the fine model. A coarse FEM mesh keeps the build
    to seconds."""
    from flexsheet.model.sheet import clamp_poses

    params = dict(PARAMS, sheet_cache=str(tmp_path), sheet_mesh={"h_fine": 0.02, "h_coarse": 0.04})

    async def scenario():
        async with NodeHarness(RendererNode, params=params) as h:
            await next_frame(h)
            Tl, Tr = clamp_poses(np.zeros(3), [1.0, 0, 0], [0, 1.0, 0], 0.04)
            h.inject(topics.ARM_LEFT_STATE, arm("left", Tl))
            h.inject(topics.ARM_RIGHT_STATE, arm("right", Tr))
            h.inject(topics.FINGERTIP, fingertip([-0.04, 0.01, 0.0]))
            await h.settle(0.1)
            m = await next_frame(h)
            assert m.correction == "four_triangle"
            assert "not built yet" in h.node.state_message
            m, before = await frame_with(h, "fine", timeout=300.0)
            assert set(before) <= {"four_triangle"} and h.rejected() == 0
            assert any(p.name.startswith("indent_") for p in tmp_path.iterdir())  # cached for the next start
            await next_frame(h)
            assert h.node.state_message == ""
    asyncio.run(scenario())


def test_bad_input_is_rejected_and_node_keeps_running():
    async def scenario():
        async with NodeHarness(RendererNode, params=PARAMS) as h:
            await next_frame(h)
            h.inject_raw(topics.FINGERTIP, [b"garbage"])
            v = np.zeros((3, 3), np.float32)
            bad = ObjectDeformation(header=Header(stamp=time.time()), vertices=v,
                                    faces=np.array([[0, 1, 7]], np.int32),
                                    contact_force=0.0, stiffness=0.0, depth=0.0, contact_point=np.zeros(3),
                                    method="condensed")
            h.inject(topics.DEFORMATION, bad)
            flipped = np.eye(4)
            flipped[:3, :3] = np.diag([-1.0, -1.0, 1.0])  # sheet normal facing away from the eye
            flipped[:3, 3] = [0.0, 0.12, 0.0]
            h.inject(topics.ARM_LEFT_STATE, arm("left", flipped))
            shear = np.eye(4)
            shear[0, 1] = 0.5                                               # not a rotation
            h.inject(topics.ARM_RIGHT_STATE, arm("right", shear))
            await h.settle(0.3)
            assert h.rejected(topics.FINGERTIP) == 1
            assert h.rejected(topics.DEFORMATION) == 1
            assert h.rejected(topics.ARM_LEFT_STATE) == 1
            assert h.rejected(topics.ARM_RIGHT_STATE) == 1
            m = await next_frame(h)                                         # still drawing, last good sheet
            assert m.correction == "flat" and m.left.max() > 100
    asyncio.run(scenario())


def test_tilted_clamps_drive_the_flat_correction():
    async def scenario():
        async with NodeHarness(RendererNode, params=dict(PARAMS, correction="none")) as h:
            base = await next_frame(h)
        async with NodeHarness(RendererNode, params=PARAMS) as h:
            th = np.radians(40)
            n = np.array([np.cos(th), 0, -np.sin(th)])
            from flexsheet.model.sheet import clamp_poses
            Tl, Tr = clamp_poses(np.array([-0.01, 0, -0.02]), n, np.array([0.0, 1, 0]), 0.0)
            h.inject(topics.ARM_LEFT_STATE, arm("left", Tl))
            h.inject(topics.ARM_RIGHT_STATE, arm("right", Tr))
            await h.settle(0.2)
            m = await next_frame(h)
            assert h.rejected() == 0 and m.correction == "flat"
            assert not np.array_equal(m.left, base.left)                    # the image is pre-distorted
    asyncio.run(scenario())


def test_window_output_params_are_validated(monkeypatch):
    p = RendererParams(output="window", stereo="side_by_side", monitor="DP-1", fullscreen=True, mirror_x=True)
    assert (p.output, p.stereo, p.monitor, p.mirror_x) == ("window", "side_by_side", "DP-1", True)
    assert RendererParams().output == "offscreen" and RendererParams().stereo == "frame_sequential"
    for bad in ({"output": "screen"}, {"stereo": "anaglyph"}, {"monitor": -1}, {"monitor": " "},
                {"refresh_hz": 0.0}, {"display": "window"}, {"width": 8},
                {"ipd": 0.064}, {"projector_K": [[1, 0, 0]]}):     # eye and projector come from display.yaml
        with pytest.raises(pydantic.ValidationError, match=next(iter(bad))):
            RendererParams(**bad)
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name,
                        *a: None if name == "glfw" else real(name, *a))
    with pytest.raises(pydantic.ValidationError, match="glfw"):
        RendererParams(output="window")


def test_show_image_replaces_the_scene_in_both_eyes_until_cleared(tmp_path):
    """The renderer's show_image service (registration patterns through the projector): any image file, scaled
    to the projector with nearest neighbour, fills both eyes of the published pair; a bad path is refused
    naming it and the scene stays; clear_image draws the scene again."""
    import cv2

    pattern = np.zeros((48, 64, 3), np.uint8)
    pattern[:, 32:] = (255, 0, 0)                        # RGB: the right half red
    cv2.imwrite(str(tmp_path / "p.png"), pattern[:, :, ::-1])

    async def scenario():
        async with NodeHarness(RendererNode, params=PARAMS) as h:
            call = {n: f for n, (f, *_) in h.node._pending_services.items()}
            await next_frame(h)
            with pytest.raises(ValueError, match="cannot read an image from '/nope.png'"):
                call["show_image"]({"path": "/nope.png"})
            shown = call["show_image"]({"path": str(tmp_path / "p.png")})
            assert {k: shown[k] for k in ("path", "size")} == {"path": str(tmp_path / "p.png"),
                                                               "size": [128, 96]}
            # latched on /projector/image at the projector's size: what the camera twin lights the sheet with
            lit = (await h.wait_for(topics.PROJECTOR_IMAGE))[-1]
            assert lit.showing and lit.header.stamp == shown["stamp"] and lit.image.shape == (96, 128)
            red = round(0.299 * 255)                                 # luminance of pure red
            assert int(lit.image[:, :64].max()) == 0 and abs(int(lit.image[:, 64:].min()) - red) <= 1
            m, _ = await frame_with(h, "image", timeout=10.0)
            for img in (m.left, m.right):  # published at scale 0.5: 64 x 48, the pattern itself
                assert img.shape == (48, 64, 3)
                assert np.array_equal(img, pattern), np.abs(img.astype(int) - pattern).max()
            call["clear_image"]({})
            assert not h.messages(topics.PROJECTOR_IMAGE)[-1].showing
            m, _ = await frame_with(h, "flat", timeout=10.0)
            assert m.left.max() > 100 and not np.array_equal(m.left, pattern)
    asyncio.run(scenario())
