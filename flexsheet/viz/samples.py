"""One consistent synthetic instant of the display, as the messages the viz bridge subscribes to (pure).

For tests and docs when no simulation runs: both arms holding the home sheet (joints
:func:`flexsheet.arm.kinematics.home_joints`, clamp poses by FK), a fingertip pushing ``push`` m behind
the sheet at the cylinder's front line, the object's surface as a cylinder grid dented under the finger,
the shipped XIMEA stereo calibration mounted by :func:`flexsheet.vision.camera_model.look_at`, small images.
Nothing here is a model of the display: the numbers only need to be plausible and self-consistent.
"""

from __future__ import annotations

import math
from functools import cache

import numpy as np

from flexsheet.arm.kinematics import ArmKinematics, home_joints
from flexsheet.model import geometry
from flexsheet.model.geometry import LEFT_BASE, RIGHT_BASE
from flexsheet.model.sheet import SheetSurface
from flexsheet.vision.camera_model import DEFAULT_CAMERA_POSITION, camera_model, look_at
from flexsheet.vision.stereo_calibration import to_message
from messages import (
    ArmJointState,
    ContactTruth,
    EyePose,
    Fingertip,
    FingerTruth,
    Header,
    HeadTruth,
    Message,
    ObjectDeformation,
    RenderedFrame,
    SheetState,
    SheetTarget,
    StereoFrame,
)
from messages import topics as T

__all__ = ["dented_cylinder", "sample_state"]


def dented_cylinder(depth: float, n_around: int = 48, n_along: int = 24, width: float = 0.01):
    """Side surface of the paper's cylinder (axis +y through ``geometry.CYLINDER_CENTER``) as a grid mesh,
    pushed in by a Gaussian dent of ``depth`` m (σ = ``width`` m) at its front line (x = 0, y = 0). Returns
    (vertices (N, 3) float32 m, faces (M, 3) int32). Raises ``ValueError`` on depth < 0."""
    if not (depth >= 0 and math.isfinite(depth)):
        raise ValueError(f"depth must be >= 0, got {depth!r}")
    R, L, c = geometry.CYLINDER_RADIUS, geometry.CYLINDER_LENGTH, geometry.CYLINDER_CENTER
    th = np.linspace(-math.pi, math.pi, n_around, endpoint=False)
    ys = np.linspace(-L / 2, L / 2, n_along + 1)
    TH, Y = np.meshgrid(th, ys, indexing="ij")
    arc = R * TH
    r = R - depth * np.exp(-(arc ** 2 + Y ** 2) / (2 * width ** 2))
    v = np.stack([c[0] + r * np.cos(TH), c[1] + Y, c[2] + r * np.sin(TH)], -1).reshape(-1, 3)
    faces = []
    n1 = n_along + 1
    for i in range(n_around):
        for j in range(n_along):
            a, b = i * n1 + j, ((i + 1) % n_around) * n1 + j
            faces += [(a, b, a + 1), (a + 1, b, b + 1)]
    return v.astype(np.float32), np.asarray(faces, dtype=np.int32)


@cache
def _camera() -> tuple[dict, np.ndarray, np.ndarray]:
    cal = camera_model("ximea")
    w, hh = (int(x) for x in cal["image_size"])
    yy, xx = np.mgrid[0:hh, 0:w]
    left = ((xx + yy) % 256).astype(np.uint8)
    left.flags.writeable = False
    return cal, left, np.ascontiguousarray(left[:, ::-1])


def sample_state(stamp: float = 1.0e9, push: float = 0.004, seq: int = 0) -> dict[str, Message]:
    """Topic name → message for one instant ``stamp`` (s): every input topic of the viz bridge except
    ``/diagnostics``. ``push`` m: fingertip depth behind the sheet (≥ 0)."""
    if not (push >= 0 and math.isfinite(push)):
        raise ValueError(f"push must be >= 0, got {push!r}")
    h = lambda frame="display": Header(stamp=stamp, frame_id=frame, seq=seq)  # noqa: E731
    exposure = stamp - 0.012
    out: dict[str, Message] = {}
    poses = {}
    for side, base in (("left", LEFT_BASE), ("right", RIGHT_BASE)):
        kin = ArmKinematics(side, base)
        q = home_joints(side)
        poses[side] = kin.fk(q)
        topic = T.arm_state(side).name
        out[topic] = ArmJointState(header=h(), arm=side, position=q, velocity=np.zeros(6), commanded=q,
                                   executing=q,
                                   pose=poses[side], status=1, target_stamp=exposure,
                                   write_stamp=stamp - 0.002)
    tip = np.array([-push, 0.01, 0.0])
    out[T.FINGERTIP.name] = Fingertip(header=h(), position=tip, covariance=np.eye(3) * 1e-8, valid=True,
                                      predicted_position=tip + [0.0, 0.002, 0.0], prediction_horizon=0.03,
                                      exposure_stamp=exposure, frame_stamp=stamp - 0.008, reprojection_px=0.2)
    out[T.FINGER_TRUTH.name] = FingerTruth(header=h(), position=tip + [0.0002, 0.0, 0.0001],
                                           velocity=np.zeros(3),
                                           phase="push", visible=True)
    out[T.SHEET_TARGET.name] = SheetTarget(
        header=h(), contact_point=np.zeros(3), normal=np.array([1.0, 0.0, 0.0]),
        axis_u=np.array([0.0, 1.0, 0.0]),
        axis_v=np.array([0.0, 0.0, 1.0]), sheet_origin=np.zeros(3), stretch=0.05, tension=120.0,
        stiffness=300.0,
        object_stiffness=250.0, touching=True, source_stamp=exposure)
    v, f = dented_cylinder(push)
    out[T.DEFORMATION.name] = ObjectDeformation(
        header=h(), vertices=v, faces=f, contact_force=0.8, stiffness=250.0, depth=push,
        contact_point=np.zeros(3),
        method="condensed", source_stamp=exposure)
    sheet = SheetSurface.from_clamps(poses["left"], poses["right"], pushed_point=tip,
                                     membrane_kwargs={"modes": 64})
    g = 16
    grid = sheet.membrane.grid(g) if sheet.membrane is not None else np.zeros((g, g))
    out[T.SHEET_STATE.name] = SheetState(
        header=h(), origin=sheet.origin, normal=sheet.normal, axis_u=sheet.axis_u, corners=sheet.corners,
        pushed_point=sheet.pushed_point, depth=float(sheet.membrane.depth) if sheet.membrane else 0.0,
        stretch=0.0, membrane=np.ascontiguousarray(grid))
    cal, left, right = _camera()
    out[T.CALIBRATION.name] = to_message(cal, h("camera_left"), look_at(DEFAULT_CAMERA_POSITION))
    out[T.STEREO.name] = StereoFrame(header=h("camera_left"), left=left, right=right, exposure_stamp=exposure,
                                     exposure_time=0.002)
    img = np.zeros((48, 64, 3), np.uint8)
    img[12:36, 20:44] = (255, 160, 60)
    out[T.RENDERED.name] = RenderedFrame(header=h("projector"), left=img,
                                         right=np.ascontiguousarray(img[:, ::-1]),
                                         scale=0.0625, correction="fine", render_time=0.004,
                                         source_stamp=exposure,
                                         eyes=
                                             np.stack([geometry.EYE - [0, 0.032, 0],
                                                       geometry.EYE + [0, 0.032, 0]]),
                                         eye_source="tracked")
    left_eye, right_eye = geometry.EYE - [0.0, 0.032, 0.0], geometry.EYE + [0.0, 0.032, 0.0]
    glasses = dict(position=geometry.EYE + [-0.015, 0.0, 0.0],
                   rotation=np.array([[0.0, 0, -1], [-1, 0, 0], [0, 1, 0]]),
                   left=left_eye, right=right_eye, eye=geometry.EYE.copy(), velocity=np.zeros(3))
    out[T.EYE_POSE.name] = EyePose(header=h(), valid=True, markers=14, reprojection_px=0.1, **glasses)
    out[T.HEAD_TRUTH.name] = HeadTruth(header=h(), **glasses)
    out[T.CONTACT_TRUTH.name] = ContactTruth(header=h(), touching=True, depth=0.01, force=0.9,
                                             point=np.array([-0.01, 0.0, 0.0]), stiffness=95.0)
    return out
