"""The Foxglove scene builder (flexsheet.viz.scene_builder): a bad joint state is refused and the arm kept;
the scene's bytes decode as the SDK would encode them.

The Foxglove bridge draws the pushed sheet the renderer corrects for (its nominal-FEM model,
:func:`flexsheet.model.sheet_model.sheet_model_for` of the same :class:`SheetConfig`), not the old linear
series dent (:class:`flexsheet.model.sheet.Membrane`).

Two routes to the same sheet: the bridge gets the clamp poses by its own forward kinematics of the arms'
measured joints and reads the depression off the vertices it encodes into ``/viz/scene``; the renderer side is
:class:`flexsheet.rendering.state.RendererState` fed the arm bridges' ``pose`` field and the fingertip, as the
node does. The tables are the shipped ones (stretch 0.04 and 0.05 are shipped nodes), so nothing is built.
"""

from __future__ import annotations

import base64

import numpy as np
import pytest
from foxglove.messages import SceneUpdate

from flexsheet.arm.kinematics import ArmKinematics, home_joints
from flexsheet.model import geometry
from flexsheet.model.geometry import LEFT_BASE, RIGHT_BASE
from flexsheet.model.sheet import SheetSurface, clamp_poses
from flexsheet.model.sheet_model import FourTriangleDent, SampledShape, SheetConfig
from flexsheet.rendering.state import RendererState
from flexsheet.viz.config import VizConfig
from flexsheet.viz.primitives import sheet_mesh
from flexsheet.viz.samples import sample_state
from flexsheet.viz.scene_builder import SceneBuilder
from messages import ArmJointState, Fingertip, Header

TOL = 5e-5          # 0.05 mm


def _arm_states(stretch: float) -> dict[str, ArmJointState]:
    """Both arms' joint states holding the sheet at the home plane with clamp strain ``stretch`` (IK)."""
    targets = dict(zip(("left", "right"),
                       clamp_poses(np.zeros(3), geometry.SCREEN_NORMAL, [0.0, 1.0, 0.0], stretch),
                       strict=True))
    out = {}
    for side, base in (("left", LEFT_BASE), ("right", RIGHT_BASE)):
        kin = ArmKinematics(side, base)
        res = kin.ik(targets[side], home_joints(side))
        assert res.ok, (side, res.status)
        out[side] = ArmJointState(header=Header(stamp=10.0, frame_id="display", seq=0), arm=side,
                                  position=res.q,
                                  velocity=np.zeros(6), commanded=res.q, executing=res.q, pose=kin.fk(res.q),
                                  status=1,
                                  target_stamp=9.99, write_stamp=9.999)
    return out


def _tip(p) -> Fingertip:
    return Fingertip(header=Header(stamp=10.0, frame_id="display", seq=0), position=np.asarray(p, float),
                     covariance=np.eye(3) * 1e-8, valid=True, predicted_position=np.asarray(p, float),
                     prediction_horizon=0.0, exposure_stamp=9.99, frame_stamp=9.995, reprojection_px=0.1)


def _bridge(arms, tip, cfg: SheetConfig) -> SceneBuilder:
    b = SceneBuilder(VizConfig(sheet=cfg, sheet_grid=41))
    for side, msg in arms.items():
        b.update(f"/arm/{side}/joint_state", msg)
    b.update("/fingertip", tip)
    return b


def _drawn_sheet_points(b: SceneBuilder) -> np.ndarray:
    """Vertices of the ``sheet`` entity as encoded in ``/viz/scene`` (decoded with the SDK's own schema)."""
    from flexsheet.viz.wsclient import proto_class

    Update = proto_class(base64.b64encode(SceneUpdate.get_schema().data).decode(), "foxglove.SceneUpdate")
    ents = {e.id: e for e in Update.FromString(b.scene_bytes(10.0)).entities}
    return np.array([(p.x, p.y, p.z) for p in ents["sheet"].triangles[0].points])


def _renderer_sheet(arms, tip_pos, cfg: SheetConfig) -> SheetSurface:
    st = RendererState(geometry.EYE, geometry.PROJECTOR, cfg, build=False)
    for side, msg in arms.items():
        st.set_arm_pose(side, msg.pose)
    st.set_fingertip(tip_pos, 10.0)
    sheet, _ = st.sheet_for_frame()
    return sheet


@pytest.mark.parametrize("stretch, depth, pu, pv",
                         [(0.04, 0.030, 0.020, 0.010), (0.05, 0.045, -0.030, 0.040)])
def test_bridge_draws_the_renderers_nominal_fem_dent(stretch, depth, pu, pv):
    cfg = SheetConfig()
    arms = _arm_states(stretch)
    tip_pos = np.array([-depth, pu, pv])      # home plane: normal +x, axis_u +y, axis_v +z
    b = _bridge(arms, _tip(tip_pos), cfg)
    believed = b.believed_sheet()
    ren = _renderer_sheet(arms, tip_pos, cfg)
    assert isinstance(believed.membrane, SampledShape) and isinstance(ren.membrane, SampledShape)
    assert believed.half_span == pytest.approx(geometry.SHEET_SIZE * (1 + stretch) / 2, abs=1e-6)
    # at the contact: the fingertip's depth, as the renderer's model has it
    w_b = float(believed.membrane.deflection(pu, pv))
    w_r = float(ren.membrane.deflection(pu, pv))
    # (the depth table, bilinear between 2 mm samples, cuts the fingertip's cap: within 1.5 mm of its depth)
    assert abs(w_b - w_r) < TOL and abs(w_b - depth) < 1.5e-3, (w_b, w_r, depth)
    # across the sheet: the vertices the bridge encodes, against the renderer's surface at the same (u, v)
    P = _drawn_sheet_points(b)
    assert P.shape == (41 * 41, 3)
    d = P - ren.origin
    u, v, w_drawn = d @ ren.axis_u, d @ ren.axis_v, -(d @ ren.normal)
    w_ren = ren.membrane.deflection(u, v)
    assert np.max(np.abs(w_drawn - w_ren)) < TOL, np.max(np.abs(w_drawn - w_ren))
    assert w_drawn.max() > 0.9 * depth and np.min(w_drawn) > -1e-4
    # ... and it is not the old linear series dent the bridge drew before (6.6 mm and 11.1 mm apart here)
    old = SheetSurface.from_clamps(arms["left"].pose, arms["right"].pose, pushed_point=tip_pos,
                                   membrane_kwargs={"modes": 16, "contact_radius": 0.008})
    gap = np.max(np.abs(old.membrane.deflection(u, v) - w_ren))
    assert gap > 3e-3, gap


def test_bridge_follows_the_renderers_config_and_draws_four_triangles_while_the_table_is_missing(tmp_path):
    # an assumed uniform tension ratio the shipped tables do not have, and an empty cache: the renderer
    # meets a PendingPush (it draws four_triangle); the bridge builds nothing and draws that 4-triangle tent
    cfg = SheetConfig(tension_ratio=1.3, cache_dir=str(tmp_path))
    depth, pu, pv = 0.03, 0.02, -0.01
    arms = _arm_states(0.04)
    b = _bridge(arms, _tip([-depth, pu, pv]), cfg)
    sheet = b.believed_sheet()
    assert isinstance(sheet.membrane, FourTriangleDent)
    assert b.sheet_model.tension_ratio == 1.3
    a, hb = sheet.half_span, sheet.half_width
    assert float(sheet.membrane.deflection(pu, pv)) == pytest.approx(depth, abs=1e-9)
    # linear toward each edge: halfway from the contact to the +u clamp, half the depth; zero on the edges
    assert float(sheet.membrane.deflection((pu + a) / 2, pv)) == pytest.approx(depth / 2, abs=1e-9)
    assert np.allclose(sheet.membrane.deflection([a, -a, pu, pu], [pv, pv, hb, -hb]), 0.0, atol=1e-12)
    assert not list(tmp_path.iterdir())                       # nothing built by the bridge
    P = _drawn_sheet_points(b)
    assert np.max(-(P - sheet.origin) @ sheet.normal) <= depth + 1e-9


def test_flat_sheet_when_the_fingertip_is_not_behind_it():
    arms = _arm_states(0.04)
    b = _bridge(arms, _tip([-0.0005, 0.0, 0.0]), SheetConfig())    # 0.5 mm behind: under the 1 mm threshold
    assert b.believed_sheet().membrane is None
    with pytest.raises(ValueError, match="sheet must be a SheetConfig"):
        VizConfig(sheet={"half_width": 0.12})


def test_bad_joint_state_is_refused_and_the_arm_kept():
    b = SceneBuilder()
    st = sample_state()
    b.update("/arm/left/joint_state", st["/arm/left/joint_state"])
    before = b.frames()
    bad = st["/arm/left/joint_state"].model_copy(update={"position": np.zeros(5)})
    with pytest.raises(ValueError, match="q must be"):
        b.update("/arm/left/joint_state", bad)
    after = b.frames()
    assert (len(before) == len(after)
            and all(np.allclose(x[2], y[2]) for x, y in zip(before, after, strict=True)))


def test_scene_bytes_decode_as_the_sdk_would_encode_them():
    """The scene's bulk arrays are written with numpy on the protobuf wire (foxglove_scene: "protobuf wire
    format"); decoded against the SDK's schema they must equal the same entities built with the SDK's
    classes."""
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
    assert {"object", "sheet", "sheet_true", "fingertip", "contact", "projector", "eyes", "cameras",
            "arm_left",
            "arm_right"} == set(ents)
    d = st["/object/deformation"]

    def pts(a):
        return [Point3(x=float(x), y=float(y), z=float(z)) for x, y, z in np.asarray(a, dtype=float)]

    sdk = SceneEntity(timestamp=Timestamp.from_epoch_secs(1234.5), frame_id="display", id="object",
                      triangles=
                          [TriangleListPrimitive(points=pts(d.vertices), indices=d.faces.ravel().tolist(),
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
