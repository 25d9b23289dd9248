"""The 3-D scene the viz bridge serves (:class:`SceneBuilder`): the believed sheet and arms, the fingertip,
the deformed object, cameras, projector and eyes as Foxglove ``SceneUpdate``/``FrameTransforms``, from the
newest display messages (:class:`flexsheet.viz.config.VizConfig`)."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from foxglove.messages import (
    ArrowPrimitive,
    CameraCalibration,
    CubePrimitive,
    CylinderPrimitive,
    FrameTransform,
    FrameTransforms,
    LinePrimitive,
    LinePrimitiveLineType,
    Quaternion,
    RawImage,
    SceneEntity,
    SpherePrimitive,
    TextPrimitive,
    Vector3,
)
from scipy.spatial.transform import Rotation

from flexsheet.model import geometry
from flexsheet.model.checks import check_pose
from flexsheet.model.projector import eye_positions
from flexsheet.model.sheet import SheetSurface, clamp_poses
from flexsheet.model.sheet_model import NominalSheetModel, believed_sheet, drawable, sheet_model_for
from flexsheet.viz.config import VizConfig
from flexsheet.viz.foxglove import ARM_LINKS, JSON_EXCLUDE, LINK_DIAMETER
from flexsheet.viz.primitives import (
    ENTITY_LINES,
    ENTITY_TRIANGLES,
    SCENE_ENTITIES,
    frustum_lines,
    frustum_points,
    len_field,
    line_bytes,
    named_color,
    pose_msg,
    quaternions,
    rigid_inverse,
    rotation_x_to,
    rotation_z_to,
    sheet_mesh,
    stamp_of,
    triangles_bytes,
)
from messages import (
    ArmJointState,
    Fingertip,
    FingerTruth,
    Message,
    ObjectDeformation,
    RenderedFrame,
    SheetState,
    SheetTarget,
    StereoCalibration,
    StereoFrame,
)
from messages import topics as T

__all__ = ["SceneBuilder"]


class _Arm:
    """One RV-1A: Pinocchio FK of every URDF link in the display frame."""

    def __init__(self, side: str, base) -> None:
        from flexsheet.arm.kinematics import ArmKinematics  # Pinocchio: loaded only when arms are drawn

        self.side = side
        self.kin = ArmKinematics(side, base)
        self.fids = [self.kin.model.getFrameId(name) for name in ARM_LINKS]

    def link_poses(self, q: np.ndarray) -> np.ndarray:
        """(len(ARM_LINKS), 4, 4) T_display_link for joints ``q`` (6,) rad."""
        import pinocchio as pin

        q = self.kin.check_q(q)
        pin.framesForwardKinematics(self.kin.model, self.kin.data, q)
        Tb = self.kin.T_display_base
        return np.stack([Tb @ self.kin.data.oMf[f].homogeneous for f in self.fids])

    def clamp_pose(self, links: np.ndarray) -> np.ndarray:
        """T_display_clamp (4, 4) in the sheet convention (the right arm's is turned by π about x)."""
        return links[-1] @ self.kin.T_link_tool


class SceneBuilder:
    """Holds the newest input of every topic and builds Foxglove messages from them.

    Feed it with :meth:`update` (topic name, decoded message); bad input raises ``ValueError`` naming the
    topic and field and leaves the previous state. Build with :meth:`scene_bytes`, :meth:`transforms` and
    the others. Not thread-safe: call from one thread."""

    def __init__(self, config: VizConfig | None = None, sheet_model: NominalSheetModel | None = None) -> None:
        self.cfg = config or VizConfig()
        self.latest: dict[str, Message] = {}
        self.stamp = 0.0
        self._arms: dict[str, _Arm] | None = None
        self._links: dict[str, np.ndarray] = {}
        self._entities: dict[str, tuple[tuple, bytes]] = {}  # entity id -> (input objects, encoded entity)
        self._static: list[bytes] | None = None
        self._sheet_key: tuple | None = None
        self._sheet: SheetSurface | None = None
        #: the renderer's pushed-sheet model of the same SheetConfig (tables loaded when used, never built)
        self.sheet_model: NominalSheetModel = sheet_model if sheet_model is not None else sheet_model_for(
            self.cfg.sheet)
        P = self.cfg.projector
        T_proj = np.eye(4)
        T_proj[:3, :3], T_proj[:3, 3] = P.R, P.position
        self.T_display_projector = T_proj
        self.eyes = eye_positions(self.cfg.eye, self.cfg.ipd)

    # ------------------------------------------------------------------ inputs
    def update(self, topic: str, msg: Message) -> None:
        """Store ``msg`` as the newest on ``topic``. Raises ``ValueError`` for input it cannot draw (faces out
        of range, a non-rigid pose, a joint vector of the wrong shape); the previous value is kept."""
        if isinstance(msg, ObjectDeformation):
            v, f = msg.vertices, msg.faces
            if len(v) == 0 or len(f) == 0:
                raise ValueError(f"{topic}: deformation has {len(v)} vertices and {len(f)} faces")
            if f.min() < 0 or f.max() >= len(v):
                raise ValueError(f"{topic}: faces index out of range [0, {len(v)}): {f.min()}..{f.max()}")
        elif isinstance(msg, ArmJointState):
            self._arm_links(msg.arm, msg.position)  # raises on bad joints; caches the link poses
        elif isinstance(msg, StereoCalibration):
            check_pose(f"{topic}.T_display_camera", msg.T_display_camera)
        self.latest[topic] = msg
        self.stamp = max(self.stamp, float(msg.header.stamp))

    def get(self, topic) -> Message | None:
        """Newest message on ``topic`` (a :class:`messages.Topic` or name), or None."""
        return self.latest.get(getattr(topic, "name", topic))

    def _arm_links(self, side: str, q) -> np.ndarray:
        if self._arms is None:
            self._arms = {"left": _Arm("left", self.cfg.left_base),
                          "right": _Arm("right", self.cfg.right_base)}
        links = self._arms[side].link_poses(q)
        self._links[side] = links
        return links

    # ------------------------------------------------------------------ believed and true sheet
    def clamp_poses(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(T_left, T_right) T_display_clamp (4, 4) from FK of the newest joint states (home pose for an arm
        not heard from), or None before any joint state."""
        if not self._links:
            return None
        home = clamp_poses(np.zeros(3), geometry.SCREEN_NORMAL, np.array([0.0, 1.0, 0.0]), 0.0)
        out = []
        for i, side in enumerate(("left", "right")):
            links = self._links.get(side)
            out.append(self._arms[side].clamp_pose(links) if links is not None else home[i])
        return out[0], out[1]

    def believed_sheet(self) -> SheetSurface | None:
        """The sheet from the measured clamps, depressed by a valid fingertip more than
        ``cfg.sheet.push_threshold`` behind it (None before any joint state / for clamps that give no sheet),
        as the renderer draws it (:meth:`NominalSheetModel.pushed`, ``build=False``: the 4-triangle dent until
        the renderer's worker has built the stretch's table into the shared cache)."""
        key = tuple(id(self.latest.get(t.name)) for t in (T.ARM_LEFT_STATE, T.ARM_RIGHT_STATE, T.FINGERTIP))
        if key != self._sheet_key:
            self._sheet_key, self._sheet = key, self._believed_sheet()
        return self._sheet

    def _believed_sheet(self) -> SheetSurface | None:
        clamps = self.clamp_poses()
        if clamps is None:
            return None
        tip = self.get(T.FINGERTIP)
        try:
            sheet = believed_sheet(*clamps, tip.position if tip is not None and tip.valid else None,
                                   self.sheet_model, self.cfg.sheet, build=False)
        except ValueError:
            return None
        return drawable(sheet)

    # ------------------------------------------------------------------ /viz/scene
    def _entity(self, eid: str, stamp: float, **prims) -> bytes:
        """Encoded ``foxglove.SceneEntity`` ``eid`` in frame ``display`` with SDK-built primitives."""
        return SceneEntity(timestamp=stamp_of(stamp), frame_id="display", id=eid, **prims).encode()

    def _cached(self, eid: str, key: tuple, build: Callable[[], bytes]) -> bytes:
        """Entity bytes of ``eid`` rebuilt only when one of the objects in ``key`` was replaced (compared by
        identity: the cache holds them, so an id cannot be reused while they are compared)."""
        hit = self._entities.get(eid)
        if (hit is not None and len(hit[0]) == len(key)
            and all(x is y for x, y in zip(hit[0], key, strict=True))):
            return hit[1]
        data = build()
        self._entities[eid] = (key, data)
        return data

    def _object_entity(self, stamp: float) -> bytes:
        d: ObjectDeformation | None = self.get(T.DEFORMATION)
        return self._cached("object", (d,), lambda: self._build_object(d, stamp))

    def _build_object(self, d: ObjectDeformation | None, stamp: float) -> bytes:
        if d is None:  # the FEM has not published: the undeformed paper cylinder (axis along y)
            q = rotation_z_to(np.asarray(geometry.CYLINDER_AXIS, dtype=float))
            cyl = CylinderPrimitive(pose=pose_msg(geometry.CYLINDER_CENTER, q),
                                    size=Vector3(x=2 * geometry.CYLINDER_RADIUS,
                                                 y=2 * geometry.CYLINDER_RADIUS, z=geometry.CYLINDER_LENGTH),
                                    bottom_scale=1.0, top_scale=1.0, color=named_color("object"))
            return self._entity("object", stamp, cylinders=[cyl])
        tri = triangles_bytes(d.vertices, d.faces, named_color("object" if d.valid else "object_invalid"))
        return self._entity("object", float(d.header.stamp)) + len_field(ENTITY_TRIANGLES, tri)

    def _static_entities(self, stamp: float) -> list[bytes]:
        """Projector frustum and the eyes (fixed geometry): built once."""
        if self._static is None:
            P = self.cfg.projector
            depth = float(-P.position[0])  # optical axis +x: the screen plane x = 0
            pts = frustum_points(P.K, P.width, P.height, self.T_display_projector, depth)
            proj = self._entity("projector", stamp, lines=[LinePrimitive(
                type=LinePrimitiveLineType.LineList, thickness=2.0, scale_invariant=True,
                points=frustum_lines(pts), color=named_color("projector"))],
                texts=[self._label(P.position, "projector")])
            e = self.eyes
            eyes = self._entity("eyes", stamp, spheres=[
                SpherePrimitive(pose=pose_msg(p), size=Vector3(x=0.012, y=0.012, z=0.012),
                                color=named_color("eye"))
                for p in (e[0], e[1])], texts=[self._label(self.cfg.eye + [0, 0, 0.03], "eye")])
            self._static = [proj, eyes]
        return self._static

    @staticmethod
    def _label(p, text: str) -> TextPrimitive:
        return TextPrimitive(pose=pose_msg(p), billboard=True, font_size=14.0, scale_invariant=True,
                             color=named_color("text"), text=text)

    def _sphere(self, p, d: float, color: str) -> SpherePrimitive:
        return SpherePrimitive(pose=pose_msg(p), size=Vector3(x=d, y=d, z=d), color=named_color(color))

    def _arrow(self, p, direction, length: float, color: str) -> ArrowPrimitive:
        n = np.asarray(direction, dtype=float)
        q = rotation_x_to(n / np.linalg.norm(n))  # arrows point along their +x
        return ArrowPrimitive(pose=pose_msg(p, q), shaft_length=0.8 * length, shaft_diameter=0.003,
                              head_length=0.2 * length, head_diameter=0.008, color=named_color(color))

    def _fingertip_entity(self, stamp: float) -> bytes:
        tip: Fingertip | None = self.get(T.FINGERTIP)
        truth: FingerTruth | None = self.get(T.FINGER_TRUTH)
        return self._cached("fingertip", (tip, truth), lambda: self._build_fingertip(tip, truth, stamp))

    def _build_fingertip(self, tip: Fingertip | None, truth: FingerTruth | None, stamp: float) -> bytes:
        spheres, texts = [], []
        if tip is not None and tip.valid:
            spheres.append(self._sphere(tip.position, 0.010, "measured"))
            if tip.prediction_horizon > 0:
                spheres.append(self._sphere(tip.predicted_position, 0.007, "predicted"))
        if truth is not None:
            spheres.append(self._sphere(truth.position, 0.005, "true"))
            texts.append(self._label(truth.position + [0, 0, 0.02], f"finger ({truth.phase})"))
        return self._entity("fingertip", stamp, spheres=spheres, texts=texts)

    def _contact_entity(self, stamp: float, sheet: SheetSurface | None) -> bytes:
        tgt: SheetTarget | None = self.get(T.SHEET_TARGET)
        return self._cached("contact", (tgt, sheet), lambda: self._build_contact(tgt, sheet, stamp))

    def _build_contact(self, tgt: SheetTarget | None, sheet: SheetSurface | None, stamp: float) -> bytes:
        spheres, arrows = [], []
        if tgt is not None:
            spheres.append(self._sphere(tgt.contact_point, 0.006, "contact"))
            arrows.append(self._arrow(tgt.contact_point, tgt.normal, 0.05, "contact"))
        if sheet is not None:
            arrows.append(self._arrow(sheet.origin, sheet.normal, 0.05, "sheet_normal"))
        return self._entity("contact", stamp, spheres=spheres, arrows=arrows)

    def _sheet_entities(self, stamp: float, sheet: SheetSurface | None) -> list[bytes]:
        out = []
        if sheet is not None:
            out.append(self._cached("sheet", (sheet,), lambda: self._build_sheet(sheet, stamp)))
        true: SheetState | None = self.get(T.SHEET_STATE)
        if true is not None:
            out.append(self._cached("sheet_true", (true,), lambda: self._build_true_sheet(true)))
        return out

    def _build_sheet(self, sheet: SheetSurface, stamp: float) -> bytes:
        n = self.cfg.sheet_grid
        v, f = sheet_mesh(sheet, n)
        return (self._entity("sheet", stamp)
                + len_field(ENTITY_TRIANGLES, triangles_bytes(v, f, named_color("sheet"))))

    def _build_true_sheet(self, true: SheetState) -> bytes:
        g = true.membrane
        a = float(np.linalg.norm(true.corners[0] - true.corners[1])) / 2
        b = float(np.linalg.norm(true.corners[1] - true.corners[2])) / 2
        u = np.linspace(-a, a, g.shape[0])
        v = np.linspace(-b, b, g.shape[1])
        ev = np.cross(true.normal, true.axis_u)
        P = (true.origin + u[:, None, None] * true.axis_u + v[None, :, None] * ev
             - g[:, :, None] * true.normal)
        # every ~8th grid line of constant u, then of constant v
        rows = [P[i, :] for i in range(0, g.shape[0], max(1, g.shape[0] // 8))]
        rows += [P[:, j] for j in range(0, g.shape[1], max(1, g.shape[1] // 8))]
        color = named_color("sheet_true")
        return self._entity("sheet_true", float(true.header.stamp)) + b"".join(
            len_field(ENTITY_LINES, line_bytes(r, LinePrimitiveLineType.LineStrip, color, 1.0)) for r in rows)

    def _camera_entity(self, stamp: float) -> bytes | None:
        cal: StereoCalibration | None = self.get(T.CALIBRATION)
        if cal is None:
            return None
        return self._cached("cameras", (cal,), lambda: self._build_cameras(cal, stamp))

    def _build_cameras(self, cal: StereoCalibration, stamp: float) -> bytes:
        w, h = (float(x) for x in cal.image_size)
        Tl, Tr = self._camera_poses(cal)
        lines = []
        for K, Tm in ((cal.K1, Tl), (cal.K2, Tr)):
            pts = frustum_points(K, w, h, Tm, self.cfg.frustum_depth)
            lines.append(LinePrimitive(type=LinePrimitiveLineType.LineList, thickness=2.0,
                                       scale_invariant=True, points=frustum_lines(pts),
                                       color=named_color("camera")))
        return self._entity("cameras", stamp, lines=lines, texts=[self._label(Tl[:3, 3], "camera")])

    @staticmethod
    def _camera_poses(cal: StereoCalibration) -> tuple[np.ndarray, np.ndarray]:
        """T_display_camera_left, T_display_camera_right (x_r = R x_l + T ⇒ T_left_right = [R | T]⁻¹)."""
        T_rl = np.eye(4)
        T_rl[:3, :3], T_rl[:3, 3] = cal.R, cal.T
        return cal.T_display_camera, cal.T_display_camera @ np.linalg.inv(T_rl)

    def _arm_entities(self, stamp: float) -> list[bytes]:
        return [self._cached(f"arm_{side}", (links,), lambda s=side, lk=links: self._build_arm(s, lk, stamp))
                for side, links in self._links.items()]

    def _build_arm(self, side: str, links: np.ndarray, stamp: float) -> bytes:
        p = links[:, :3, 3]
        cyls = []
        for k in range(len(ARM_LINKS) - 1):
            d = p[k + 1] - p[k]
            L = float(np.linalg.norm(d))
            if L < 1e-6:
                continue
            dia = LINK_DIAMETER[k]
            cyls.append(CylinderPrimitive(pose=pose_msg(0.5 * (p[k] + p[k + 1]), rotation_z_to(d / L)),
                                          size=Vector3(x=dia, y=dia, z=L), bottom_scale=1.0, top_scale=1.0,
                                          color=named_color("arm")))
        spheres = [self._sphere(p[k], LINK_DIAMETER[min(k, len(LINK_DIAMETER) - 1)] * 1.05, "arm")
                   for k in range(1, len(ARM_LINKS) - 1)]
        Tc = links[-1]
        jaw = CubePrimitive(pose=pose_msg(Tc[:3, 3], quaternions(Tc[:3, :3])),
                            size=Vector3(x=0.02, y=0.03, z=self.cfg.sheet_half_width * 2),
                            color=named_color("clamp"))
        return self._entity(f"arm_{side}", stamp, cylinders=cyls, spheres=spheres, cubes=[jaw],
                            texts=[self._label(p[0] + [0, 0, -0.03], f"{side} arm")])

    def scene_bytes(self, stamp: float | None = None) -> bytes:
        """The whole scene as one encoded ``foxglove.SceneUpdate`` (every entity replaced; ids: object, sheet,
        sheet_true, fingertip, contact, projector, eyes, cameras, arm_left, arm_right). Entities whose inputs
        did not change since the last call are reused as bytes; an entity's timestamp is that of the input
        it was drawn from (``stamp``, s, default the newest input's, when it has none)."""
        stamp = self.stamp if stamp is None else stamp
        sheet = self.believed_sheet()
        ents = [self._object_entity(stamp), *self._sheet_entities(stamp, sheet),
                self._fingertip_entity(stamp),
                self._contact_entity(stamp, sheet), *self._static_entities(stamp), *self._arm_entities(stamp)]
        cam = self._camera_entity(stamp)
        if cam is not None:
            ents.append(cam)
        return b"".join(len_field(SCENE_ENTITIES, e) for e in ents)

    # ------------------------------------------------------------------ /viz/tf
    def frames(self) -> list[tuple[str, str, np.ndarray]]:
        """(parent, child, T_parent_child (4, 4)) of every frame known now (see module docstring)."""
        out = [("display", "projector", self.T_display_projector)]
        Te = np.eye(4)
        Te[:3, 3] = self.cfg.eye
        out.append(("display", "eye", Te))
        cal: StereoCalibration | None = self.get(T.CALIBRATION)
        if cal is not None:
            Tl, Tr = self._camera_poses(cal)
            out += [("display", "camera_left", Tl), ("camera_left", "camera_right", rigid_inverse(Tl) @ Tr)]
        sheet = self.believed_sheet()
        if sheet is not None:
            Ts = np.eye(4)
            Ts[:3, :3] = np.column_stack([sheet.normal, sheet.axis_u, sheet.axis_v])
            Ts[:3, 3] = sheet.origin
            out.append(("display", "sheet", Ts))
        tgt: SheetTarget | None = self.get(T.SHEET_TARGET)
        if tgt is not None:
            Tt = np.eye(4)
            R = np.column_stack([tgt.normal, tgt.axis_u, tgt.axis_v])
            Tt[:3, :3] = Rotation.from_matrix(R).as_matrix()  # re-orthonormalised (targets are unit, ~1e-12)
            Tt[:3, 3] = tgt.sheet_origin
            out.append(("display", "sheet_target", Tt))
        for side, links in self._links.items():
            parent, Tp = "display", np.eye(4)
            for name, Tl in zip(ARM_LINKS, links, strict=True):
                child = f"{side}/{name}"
                out.append((parent, child, rigid_inverse(Tp) @ Tl))
                parent, Tp = child, Tl
        return out

    def transforms(self, stamp: float | None = None) -> FrameTransforms:
        """All :meth:`frames` as one ``foxglove.FrameTransforms`` stamped ``stamp`` (s)."""
        stamp = self.stamp if stamp is None else stamp
        fr = self.frames()
        q = quaternions(np.stack([Tm[:3, :3] for _, _, Tm in fr]))
        ts = stamp_of(stamp)
        return FrameTransforms(transforms=[
            FrameTransform(timestamp=ts, parent_frame_id=p, child_frame_id=c,
                           translation=Vector3(x=float(Tm[0, 3]), y=float(Tm[1, 3]), z=float(Tm[2, 3])),
                           rotation=Quaternion(x=float(qi[0]), y=float(qi[1]), z=float(qi[2]),
                                               w=float(qi[3])))
            for (p, c, Tm), qi in zip(fr, q, strict=True)])

    # ------------------------------------------------------------------ images
    def camera_images(self) -> tuple[RawImage, RawImage] | None:
        """Newest stereo pair as two ``foxglove.RawImage`` mono8 (downscaled by ``camera_scale``), or None."""
        fr: StereoFrame | None = self.get(T.STEREO)
        if fr is None:
            return None
        return (self._mono(fr.left, "camera_left", fr.exposure_stamp),
                self._mono(fr.right, "camera_right", fr.exposure_stamp))

    def _mono(self, img: np.ndarray, frame: str, stamp: float) -> RawImage:
        s = self.cfg.camera_scale
        if s < 1.0:
            import cv2

            img = cv2.resize(img, (max(1, round(img.shape[1] * s)), max(1, round(img.shape[0] * s))),
                             interpolation=cv2.INTER_AREA)
        img = np.ascontiguousarray(img)
        return RawImage(timestamp=stamp_of(stamp), frame_id=frame, width=img.shape[1], height=img.shape[0],
                        encoding="mono8", step=img.shape[1], data=img.tobytes())

    def calibrations(self) -> tuple[CameraCalibration, CameraCalibration] | None:
        """``foxglove.CameraCalibration`` of the left and right camera (raw images: R = I, P = [K | 0]),
        scaled like the images, or None before ``/camera/calibration``."""
        cal: StereoCalibration | None = self.get(T.CALIBRATION)
        if cal is None:
            return None
        s = self.cfg.camera_scale
        w, h = (round(float(x) * s) for x in cal.image_size)
        S = np.diag([s, s, 1.0])
        out = []
        for K, D, frame in ((cal.K1, cal.D1, "camera_left"), (cal.K2, cal.D2, "camera_right")):
            Ks = S @ K
            P = np.hstack([Ks, np.zeros((3, 1))])
            out.append(CameraCalibration(timestamp=stamp_of(cal.header.stamp), frame_id=frame, width=w,
                                         height=h,
                                         distortion_model="plumb_bob", D=[float(x) for x in D],
                                         K=Ks.ravel().tolist(), R=np.eye(3).ravel().tolist(),
                                         P=P.ravel().tolist()))
        return out[0], out[1]

    def render_image(self) -> RawImage | None:
        """The projector's newest left|right pair side by side as one ``foxglove.RawImage`` rgb8, or None."""
        fr: RenderedFrame | None = self.get(T.RENDERED)
        if fr is None:
            return None
        img = np.ascontiguousarray(np.hstack([fr.left, fr.right]))
        return RawImage(timestamp=stamp_of(fr.header.stamp), frame_id="projector", width=img.shape[1],
                        height=img.shape[0], encoding="rgb8", step=3 * img.shape[1], data=img.tobytes())

    # ------------------------------------------------------------------ JSON
    def metrics(self) -> dict:
        """Live metrics (see ``/viz/metrics`` in the module docstring); None where an input is missing."""
        tgt: SheetTarget | None = self.get(T.SHEET_TARGET)
        sheet = self.believed_sheet()
        dtheta = None
        if tgt is not None and sheet is not None:
            n, m = tgt.normal, sheet.normal
            dtheta = math.degrees(math.atan2(float(np.linalg.norm(np.cross(n, m))), float(n @ m)))
        lat = {}

        def hop(key: str, msg, end: float, start: float) -> None:
            lat[key] = (end - start) * 1e3 if msg is not None and start > 0 else None

        tip: Fingertip | None = self.get(T.FINGERTIP)
        hop("fingertip", tip, tip.header.stamp if tip else 0.0, tip.exposure_stamp if tip else 0.0)
        hop("target", tgt, tgt.header.stamp if tgt else 0.0, tgt.source_stamp if tgt else 0.0)
        d: ObjectDeformation | None = self.get(T.DEFORMATION)
        hop("fem", d, d.header.stamp if d else 0.0, d.source_stamp if d else 0.0)
        for side, topic in (("left", T.ARM_LEFT_STATE), ("right", T.ARM_RIGHT_STATE)):
            js: ArmJointState | None = self.get(topic)
            hop(f"arm_{side}", js, js.write_stamp if js else 0.0, js.target_stamp if js else 0.0)
        r: RenderedFrame | None = self.get(T.RENDERED)
        hop("render", r, r.header.stamp if r else 0.0, r.source_stamp if r else 0.0)
        return {"stamp": self.stamp, "dtheta_deg": dtheta, "tension": tgt.tension if tgt else None,
                "stretch": tgt.stretch if tgt else None, "contact_force": d.contact_force if d else None,
                "push_depth_mm": d.depth * 1e3 if d else None, "latency_ms": lat}

    @staticmethod
    def json_copy(topic: str, msg: Message) -> bytes:
        """``msg`` as JSON bytes for its Foxglove JSON channel (fields of :data:`JSON_EXCLUDE` left out)."""
        drop = JSON_EXCLUDE.get(topic)
        return msg.model_dump_json(exclude=drop).encode() if drop else msg.model_dump_json().encode()


