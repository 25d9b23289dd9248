"""Foxglove scene primitives from display geometry (no I/O): colours, stamps, poses, quaternions, camera
frustums, the sheet's triangle mesh, and the protobuf wire format of bulk arrays (points, colours, triangles),
appended to SDK-encoded messages (protobuf.dev "Encoding": concatenation and packed repeated fields)."""

from __future__ import annotations

import math
from functools import cache

import numpy as np
from foxglove.messages import (
    Color,
    LinePrimitive,
    LinePrimitiveLineType,
    Point3,
    Pose,
    Quaternion,
    Timestamp,
    TriangleListPrimitive,
    Vector3,
)
from scipy.spatial.transform import Rotation

from flexsheet.model.sheet import SheetSurface

__all__ = ["quaternions", "frustum_points", "sheet_mesh"]

_RGBA = {
    "object": (0.95, 0.55, 0.20, 0.9), "object_invalid": (0.6, 0.6, 0.6, 0.7),
    "sheet": (0.75, 0.85, 1.0, 0.45),
    "sheet_true": (1.0, 1.0, 1.0, 0.6), "measured": (0.1, 0.9, 0.2, 1.0), "predicted": (1.0, 0.9, 0.1, 1.0),
    "true": (0.9, 0.2, 0.9, 1.0), "contact": (1.0, 0.15, 0.15, 1.0), "sheet_normal": (0.2, 0.45, 1.0, 1.0),
    "camera": (0.2, 0.9, 0.9, 1.0), "projector": (1.0, 0.8, 0.3, 1.0), "eye": (0.3, 0.5, 1.0, 1.0),
    "arm": (0.62, 0.64, 0.68, 1.0), "clamp": (0.25, 0.25, 0.28, 1.0), "text": (1.0, 1.0, 1.0, 1.0),
}


def named_color(name: str) -> Color:
    """The scene's colour of ``name`` (a key of the palette: "object", "sheet", "arm", …); ``KeyError``
    else."""
    r, g, b, a = _RGBA[name]
    return Color(r=r, g=g, b=b, a=a)


def stamp_of(stamp: float) -> Timestamp:
    """A foxglove ``Timestamp`` of ``stamp`` s (clamped at 0)."""
    return Timestamp.from_epoch_secs(max(0.0, float(stamp)))


def _p3(p) -> Point3:
    return Point3(x=float(p[0]), y=float(p[1]), z=float(p[2]))


def pose_msg(p, q=(0.0, 0.0, 0.0, 1.0)) -> Pose:
    """A foxglove ``Pose`` at ``p`` (3,) m with the quaternion ``q`` (x, y, z, w)."""
    return Pose(position=Vector3(x=float(p[0]), y=float(p[1]), z=float(p[2])),
                orientation=Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])))


def quaternions(R: np.ndarray) -> np.ndarray:
    """Unit quaternions (x, y, z, w) of rotation matrices ``R`` (..., 3, 3) → (..., 4) (scipy ``Rotation``).

    Raises ``ValueError`` for a shape other than (..., 3, 3) or non-finite entries."""
    R = np.asarray(R, dtype=float)
    if R.shape[-2:] != (3, 3) or not np.all(np.isfinite(R)):
        raise ValueError(f"R must be finite (..., 3, 3) rotations, got shape {R.shape}")
    flat = R.reshape(-1, 3, 3)
    return Rotation.from_matrix(flat).as_quat().reshape(*R.shape[:-2], 4)


def rotation_z_to(d: np.ndarray) -> np.ndarray:
    """Quaternion (x, y, z, w) turning +z onto the unit vector ``d`` (3,) (shortest arc; q ∝ (z × d, 1 +
    z·d))."""
    if d[2] < -1.0 + 1e-9:
        return np.array([1.0, 0.0, 0.0, 0.0])
    q = np.array([-d[1], d[0], 0.0, 1.0 + d[2]])
    return q / math.sqrt(float(q @ q))


def rotation_x_to(d: np.ndarray) -> np.ndarray:
    """Quaternion (x, y, z, w) turning +x onto the unit vector ``d`` (3,) (shortest arc; q ∝ (x × d, 1 +
    x·d))."""
    if d[0] < -1.0 + 1e-9:
        return np.array([0.0, 0.0, 1.0, 0.0])
    q = np.array([0.0, -d[2], d[1], 1.0 + d[0]])
    return q / math.sqrt(float(q @ q))


def rigid_inverse(Tm: np.ndarray) -> np.ndarray:
    """The inverse (4, 4) of a rigid transform ``Tm`` (4, 4) (Rᵀ, −Rᵀt)."""
    out = np.eye(4)
    out[:3, :3] = Tm[:3, :3].T
    out[:3, 3] = -Tm[:3, :3].T @ Tm[:3, 3]
    return out


def frustum_points(K: np.ndarray, width: float, height: float, T_display_sensor: np.ndarray,
                   depth: float) -> np.ndarray:
    """Apex and the four image-corner points of a pinhole frustum, (5, 3) m in the display frame.

    ``K`` (3, 3) px intrinsics, ``width``/``height`` px, ``T_display_sensor`` (4, 4) the optical frame
    (+z forward, OpenCV), ``depth`` m along +z where the far rectangle is drawn. Corners in the order
    (0, 0), (w, 0), (w, h), (0, h) px. Raises ``ValueError`` on bad shapes, a singular K or depth ≤ 0.
    Source: pinhole back-projection x = depth · K⁻¹ (u, v, 1) (Hartley & Zisserman §6.1).
    """
    K = np.asarray(K, dtype=float)
    Tm = np.asarray(T_display_sensor, dtype=float)
    if K.shape != (3, 3) or Tm.shape != (4, 4) or not (np.all(np.isfinite(K)) and np.all(np.isfinite(Tm))):
        raise ValueError(f"K must be (3, 3) and T_display_sensor (4, 4), finite; got {K.shape}, {Tm.shape}")
    if not (depth > 0 and math.isfinite(depth)):
        raise ValueError(f"depth must be > 0, got {depth!r}")
    if abs(np.linalg.det(K)) < 1e-12:
        raise ValueError("K is singular")
    uv = np.array([[0.0, 0.0, 1.0], [width, 0.0, 1.0], [width, height, 1.0], [0.0, height, 1.0]])
    rays = (np.linalg.inv(K) @ uv.T).T
    pts = np.vstack([np.zeros(3), rays / rays[:, 2:3] * depth])
    return pts @ Tm[:3, :3].T + Tm[:3, 3]


def frustum_lines(pts: np.ndarray) -> list[Point3]:
    """LINE_LIST points for a frustum (5, 3): four edges from the apex and the far rectangle."""
    idx = [0, 1, 0, 2, 0, 3, 0, 4, 1, 2, 2, 3, 3, 4, 4, 1]
    return [_p3(pts[i]) for i in idx]


def sheet_mesh(sheet: SheetSurface, n: int = 20) -> tuple[np.ndarray, np.ndarray]:
    """Triangle mesh of ``sheet`` (with its membrane depression): vertices (n², 3) m, display frame, on an
    n × n grid over u ∈ [−a, a], v ∈ [−b, b]; faces (2(n−1)², 3) int32. Raises ``ValueError`` for n < 2."""
    if n < 2:
        raise ValueError(f"n must be >= 2, got {n!r}")
    u = np.linspace(-sheet.half_span, sheet.half_span, n)
    v = np.linspace(-sheet.half_width, sheet.half_width, n)
    U, V = np.meshgrid(u, v, indexing="ij")
    verts = sheet.point(U, V).reshape(-1, 3)
    return verts, _grid_faces(n, n)


@cache
def _grid_faces(nu: int, nv: int) -> np.ndarray:
    i, j = np.meshgrid(np.arange(nu - 1), np.arange(nv - 1), indexing="ij")
    a = (i * nv + j).ravel()
    b, c, d = a + nv, a + 1, a + nv + 1
    f = np.concatenate([np.stack([a, b, c], 1), np.stack([c, b, d], 1)]).astype(np.int32)
    f.flags.writeable = False
    return f


# ---------------------------------------------------------------- protobuf wire format, bulk arrays
# A Point3 per vertex built through the SDK's classes costs ~1 µs each (a deformed object: ~1 ms per scene).
# The protobuf wire format lets a message be assembled from parts: the encoding of a message is the
# concatenation of its fields' encodings, in any order, and a repeated field is one record per element
# (protobuf.dev/programming-guides/encoding: "Concatenation"/"Repeated elements"). So the SDK encodes every
# scalar part of an entity (timestamp, ids, colours, poses) and numpy writes only the bulk arrays below: the
# repeated ``Point3 points`` (one length-delimited record of 3 doubles per point) and the packed
# ``fixed32 indices``. tests/unit/viz/test_scene_builder.py decodes the result against the SDK's schema.
_LEN = 2  # wire type of length-delimited fields (submessages, bytes, packed arrays)
_POINT3_RECORD = np.dtype([("tag", "u1"), ("len", "u1"), ("tx", "u1"), ("x", "<f8"), ("ty", "u1"),
                           ("y", "<f8"),
                           ("tz", "u1"), ("z", "<f8")])  # 29 bytes, unaligned: exactly the wire bytes


def _varint(n: int) -> bytes:
    out = bytearray()
    while n >= 0x80:
        out.append((n & 0x7F) | 0x80)
        n >>= 7
    out.append(n)
    return bytes(out)


def len_field(number: int, payload: bytes) -> bytes:
    """One length-delimited field ``number`` (a submessage or packed array) on the wire."""
    return _varint(number << 3 | _LEN) + _varint(len(payload)) + payload


def _point3_field(number: int, pts: np.ndarray) -> bytes:
    """Repeated ``foxglove.Point3`` field ``number`` holding ``pts`` (N, 3) m (float64 on the wire)."""
    pts = np.asarray(pts, dtype=float).reshape(-1, 3)
    if number >= 16:
        raise ValueError(f"field number {number} needs a 2-byte tag")
    rec = np.empty(len(pts), _POINT3_RECORD)
    rec["tag"], rec["len"] = number << 3 | _LEN, 27
    rec["tx"], rec["ty"], rec["tz"] = 0x09, 0x11, 0x19  # Point3 fields 1, 2, 3: double (wire type 1)
    rec["x"], rec["y"], rec["z"] = pts[:, 0], pts[:, 1], pts[:, 2]
    return rec.tobytes()


def _fixed32_field(number: int, values: np.ndarray) -> bytes:
    """Packed repeated ``fixed32`` field ``number`` (proto3 packs repeated scalars)."""
    v = np.ascontiguousarray(values, dtype="<u4").ravel()
    return len_field(number, v.tobytes()) if len(v) else b""


#: field numbers (foxglove/SceneUpdate.proto, SceneEntity.proto,
#: TriangleListPrimitive.proto, LinePrimitive.proto)
SCENE_ENTITIES, ENTITY_LINES, ENTITY_TRIANGLES, _TRI_POINTS, _TRI_INDICES, _LINE_POINTS = 2, 11, 12, 2, 5, 5


def triangles_bytes(points: np.ndarray, indices: np.ndarray, color: Color) -> bytes:
    """Encoded ``foxglove.TriangleListPrimitive`` of ``points`` (N, 3) m and ``indices`` (3M,) (or (M, 3))."""
    return (TriangleListPrimitive(color=color).encode() + _point3_field(_TRI_POINTS, points)
            + _fixed32_field(_TRI_INDICES, indices))


def line_bytes(points: np.ndarray, line_type: LinePrimitiveLineType, color: Color, thickness: float) -> bytes:
    """Encoded ``foxglove.LinePrimitive`` through ``points`` (N, 3) m (thickness in px, scale invariant)."""
    return (LinePrimitive(type=line_type, thickness=thickness, scale_invariant=True, color=color).encode()
            + _point3_field(_LINE_POINTS, points))


