"""The shipped Foxglove layout matches its generator and only names channels (and fields) that exist; the
preview draws a bag's Foxglove channels; the scene builder's geometry helpers hold their contracts."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from mcap.writer import Writer

from flexsheet.model import geometry
from flexsheet.model.projector import Projector
from flexsheet.model.sheet import SheetSurface, clamp_poses
from flexsheet.runtime.codec import encode
from flexsheet.viz.foxglove import channel_schemas, inputs_for
from flexsheet.viz.foxglove_bag import FoxgloveBagChannels
from flexsheet.viz.layout import layout
from flexsheet.viz.preview import read_foxglove, render
from flexsheet.viz.primitives import frustum_points, quaternions, sheet_mesh
from flexsheet.viz.samples import sample_state
from flexsheet.viz.scene_builder import SceneBuilder

ROOT = Path(__file__).resolve().parents[3]


def _leaves(tree) -> list[str]:
    return [tree] if isinstance(tree, str) else _leaves(tree["first"]) + _leaves(tree["second"])


def test_docs_layout_is_the_generated_one_and_names_only_real_channels_and_fields():
    shipped = json.loads((ROOT / "docs" / "foxglove_layout.json").read_text())
    assert shipped == layout(), "regenerate: python -m flexsheet.viz.layout docs/foxglove_layout.json"
    schemas = channel_schemas()
    cfg = shipped["configById"]
    assert sorted(_leaves(shipped["layout"])) == sorted(cfg)          # every panel placed exactly once
    kinds = {k.split("!")[0] for k in cfg}
    assert {"3D", "Image", "Plot"} <= kinds
    for k, c in cfg.items():
        if k.startswith("3D"):
            assert set(c["topics"]) == {"/viz/scene", "/viz/tf"} <= set(schemas)
        if k.startswith("Image"):
            for key in ("imageTopic", "calibrationTopic"):
                if key in c["imageMode"]:
                    assert c["imageMode"][key] in schemas, c["imageMode"][key]
        if k.startswith("Plot"):
            for p in c["paths"]:
                topic, _, field = p["value"].partition(".")
                schema = json.loads(schemas[topic][0].data)
                for part in field.split("."):           # the field exists in the channel's JSON schema
                    assert part in schema["properties"], p["value"]
                    schema = schema["properties"][part]
    titles = " ".join(c.get("title", "") for c in cfg.values())
    assert "Δθ" in titles and "latency" in titles and "tension" in titles


def test_outputs_name_their_inputs():
    assert [t.name for t in inputs_for("/camera/left")] == ["/camera/stereo"]
    scene_in = {t.name for t in inputs_for("/viz/scene")}
    assert {"/object/deformation", "/arm/left/joint_state", "/world/finger"} <= scene_in
    assert "/camera/stereo" not in scene_in
    assert [t.name for t in inputs_for("/fingertip")] == ["/fingertip"] and inputs_for("/nope") == []


def test_preview_draws_the_bag(tmp_path):
    path = tmp_path / "fox.mcap"
    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start()
        fox = FoxgloveBagChannels(w)
        for k in range(12):
            t = 1.7e9 + k * 0.1
            for name, msg in sample_state(stamp=t, push=0.0005 * k, seq=k).items():
                fox.add_frames(encode(name, msg), int(t * 1e9))
        fox.close()
        w.finish()
    data = read_foxglove(path)
    numbers = render(data, tmp_path / "p.png")
    assert (tmp_path / "p.png").stat().st_size > 20_000
    drawn = numbers["scene_entities"]
    st = sample_state()
    assert drawn["object:triangles"] == len(st["/object/deformation"].faces)
    assert drawn["arm_left:cylinders"] == 7 and drawn["cameras:lines"] == 16 and drawn["fingertip:spheres"] == 3
    tension = numbers["plots"]["Plot!tension"]["tension (N/m)"]
    assert len(tension) >= 10 and {v for _, v in tension} == {120.0}
    with pytest.raises(ValueError, match="MCAP"):
        read_foxglove(__file__)


def test_frustum_corners_reproject_to_the_image_corners():
    P = Projector.default()
    Tp = np.eye(4)
    Tp[:3, :3], Tp[:3, 3] = P.R, P.position
    pts = frustum_points(P.K, P.width, P.height, Tp, depth=1.0)
    assert np.allclose(pts[0], geometry.PROJECTOR)
    assert np.allclose(pts[1:, 0], 0.0, atol=1e-12)      # optical axis +x: depth 1 m reaches the screen x = 0
    xc = (pts[1:] - P.position) @ P.R                     # back into the projector frame, then project
    uv = (P.K @ xc.T).T
    assert np.allclose(uv[:, :2] / uv[:, 2:], [[0, 0], [P.width, 0], [P.width, P.height], [0, P.height]])
    # one projector pixel is 0.7 mm on the screen
    assert abs(np.linalg.norm(pts[2] - pts[1]) / P.width - geometry.PIXEL_ON_SCREEN) < 1e-9
    with pytest.raises(ValueError, match="depth"):
        frustum_points(P.K, 10, 10, Tp, depth=0.0)


def test_sheet_mesh_carries_the_membrane_depression():
    clamps = clamp_poses(np.zeros(3), geometry.SCREEN_NORMAL, np.array([0.0, 1.0, 0.0]), 0.0)
    sheet = SheetSurface.from_clamps(*clamps, pushed_point=np.array([-0.01, 0.0, 0.0]),
                                     membrane_kwargs={"modes": 64})
    v, f = sheet_mesh(sheet, 21)
    assert v.shape == (441, 3) and f.shape == (800, 3) and f.max() == 440
    centre = v[10 * 21 + 10]
    assert np.allclose(centre, [-0.01, 0.0, 0.0], atol=2e-4)          # the deepest point is under the finger
    edges = v.reshape(21, 21, 3)[[0, -1], :, 0]
    assert np.allclose(edges, 0.0, atol=1e-12)                         # clamped edges stay on the plane
    with pytest.raises(ValueError, match="n must be"):
        sheet_mesh(sheet, 1)


def test_quaternions_match_known_rotations_and_reject_bad_input():
    Rz = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # 90° about z
    assert np.allclose(quaternions(Rz), [0, 0, np.sqrt(0.5), np.sqrt(0.5)])
    assert quaternions(np.stack([np.eye(3)] * 3)).shape == (3, 4)
    with pytest.raises(ValueError, match="rotations"):
        quaternions(np.full((3, 3), np.nan))


def test_bad_joint_state_is_refused_and_the_arm_kept():
    b = SceneBuilder()
    st = sample_state()
    b.update("/arm/left/joint_state", st["/arm/left/joint_state"])
    before = b.frames()
    bad = st["/arm/left/joint_state"].model_copy(update={"position": np.zeros(5)})
    with pytest.raises(ValueError, match="q must be"):
        b.update("/arm/left/joint_state", bad)
    after = b.frames()
    assert len(before) == len(after) and all(np.allclose(x[2], y[2]) for x, y in zip(before, after, strict=True))


def test_scene_bytes_decode_as_the_sdk_would_encode_them():
    """The scene's bulk arrays are written with numpy on the protobuf wire (foxglove_scene: "protobuf wire
    format"); decoded against the SDK's schema they must equal the same entities built with the SDK's classes."""
    import base64

    from foxglove.messages import (
        Color,
        LinePrimitive,
        LinePrimitiveLineType,
        Point3,
        SceneEntity,
        SceneUpdate,
        Timestamp,
        TriangleListPrimitive,
    )

    from flexsheet.viz.wsclient import proto_class

    schema = base64.b64encode(SceneUpdate.get_schema().data).decode()
    Update = proto_class(schema, "foxglove.SceneUpdate")
    Entity = Update.DESCRIPTOR.fields_by_name["entities"].message_type._concrete_class
    st = sample_state(stamp=1234.5)
    b = SceneBuilder()
    for name, msg in st.items():
        b.update(name, msg)
    su = Update.FromString(b.scene_bytes(1234.5))
    ents = {e.id: e for e in su.entities}
    assert {"object", "sheet", "sheet_true", "fingertip", "contact", "projector", "eyes", "cameras", "arm_left",
            "arm_right"} == set(ents)
    d = st["/object/deformation"]

    def pts(a):
        return [Point3(x=float(x), y=float(y), z=float(z)) for x, y, z in np.asarray(a, dtype=float)]

    sdk = SceneEntity(timestamp=Timestamp.from_epoch_secs(1234.5), frame_id="display", id="object",
                      triangles=[TriangleListPrimitive(points=pts(d.vertices), indices=d.faces.ravel().tolist(),
                                                       color=Color(r=0.95, g=0.55, b=0.2, a=0.9))])
    assert Entity.FromString(sdk.encode()) == ents["object"]
    assert len(ents["object"].triangles[0].points) == len(d.vertices) == 1200
    v, f = sheet_mesh(b.believed_sheet(), b.cfg.sheet_grid)
    sheet = ents["sheet"].triangles[0]
    assert np.allclose([(p.x, p.y, p.z) for p in sheet.points], v, rtol=0, atol=0)   # doubles, bit-exact
    assert list(sheet.indices) == f.ravel().tolist()
    strip = ents["sheet_true"].lines[0]
    sdk_line = LinePrimitive(type=LinePrimitiveLineType.LineStrip, thickness=1.0, scale_invariant=True,
                             points=[Point3(x=p.x, y=p.y, z=p.z) for p in strip.points],
                             color=Color(r=1.0, g=1.0, b=1.0, a=0.6))
    LineMsg = type(strip)
    assert LineMsg.FromString(sdk_line.encode()) == strip and len(strip.points) == 16
    # unchanged inputs: the same bytes again, rebuilt only for what changed
    assert b.scene_bytes(1234.5) == b.scene_bytes(1234.5)
    left, right = b._entities["arm_left"][1], b._entities["arm_right"][1]
    b.update("/arm/left/joint_state", st["/arm/left/joint_state"].model_copy())
    b.scene_bytes(1234.5)
    assert b._entities["arm_left"][1] is not left and b._entities["arm_right"][1] is right
