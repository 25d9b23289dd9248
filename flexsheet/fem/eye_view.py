"""What the user's eyes see of a pushed surface, and where on the imaginary screen, in projector pixels (the
ground of every FEM accuracy figure; :mod:`flexsheet.fem.eye_judge` judges a served surface with it).

A rendered vertex counts where an eye sees it: the segment from the eye to the vertex's position on the
*reference's* deformed surface crosses neither that surface (self-occlusion: the crater's rim, the object's
far side; a ray cast with :mod:`trimesh`) nor the finger, a capsule of the fingertip's radius from the tip's
centre back toward the user (:data:`FINGER_LENGTH`). Where the eye sees a point is its projection from the eye
onto the imaginary screen, in projector pixels there (:data:`flexsheet.model.geometry.PIXEL_ON_SCREEN`): a
displacement along the line of sight costs nothing, one across it costs what the eye notices. Both eyes (V ∓
IPD/2 along y).
Frame: ``display``; units m, px."""

from __future__ import annotations

import numpy as np

from flexsheet.model import geometry
from flexsheet.model.projector import eye_positions

__all__ = ["FINGER_LENGTH", "IPD", "eyes", "finger_capsule", "seen", "screen_px"]

#: the finger's length behind the tip's centre, m: an adult index finger's distal and middle phalanges
#: (assumption; a longer finger hides no more, the capsule then ends beside the user's hand)
FINGER_LENGTH = 0.08
#: interpupillary distance, m (the renderer's default, flexsheet/rendering/stereo_renderer.py)
IPD = 0.064


def eyes(eye=geometry.EYE, ipd: float = IPD) -> np.ndarray:
    """(2, 3) m: the left and right eye (:func:`flexsheet.model.projector.eye_positions`)."""
    return np.stack(eye_positions(np.asarray(eye, float), ipd))


def finger_capsule(finger, length: float = FINGER_LENGTH) -> tuple[np.ndarray, np.ndarray, float]:
    """The finger as a capsule: (a, b, r), the segment from the tip's centre ``a`` (3,) m back along
    −``finger.direction`` by ``length`` m to ``b`` (3,) m, radius ``r`` m (``finger.radius``). ``finger``: any
    object with ``center`` (3,), unit ``direction`` (3,) (into the object) and ``radius``."""
    a = np.asarray(finger.center, float)
    d = np.asarray(finger.direction, float)
    return a, a - length * d / np.linalg.norm(d), float(finger.radius)


def _segments_distance(p0: np.ndarray, p1: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(k,) m: the least distance between each segment ``p0[i]``–``p1[i]`` ((k, 3) m) and the segment a–b."""
    d1 = p1 - p0                        # (k, 3)
    d2 = b - a                          # (3,)
    r = p0 - a
    aa = np.einsum("ij,ij->i", d1, d1)
    ee = float(d2 @ d2)
    f = r @ d2
    c = np.einsum("ij,ij->i", d1, r)
    bb = d1 @ d2
    den = aa * ee - bb * bb
    s = np.where(den > 1e-18, np.clip((bb * f - c * ee) / np.where(den > 1e-18, den, 1.0), 0.0, 1.0), 0.0)
    t = (bb * s + f) / ee
    t_c = np.clip(t, 0.0, 1.0)
    s = np.where(t != t_c, np.clip((bb * t_c - c) / np.maximum(aa, 1e-18), 0.0, 1.0), s)
    q1 = p0 + s[:, None] * d1
    q2 = a + t_c[:, None] * d2
    return np.linalg.norm(q1 - q2, axis=1)


def seen(points: np.ndarray, faces: np.ndarray, eye: np.ndarray, capsule=None, tol: float = 2e-4,
         targets: np.ndarray | None = None) -> np.ndarray:
    """(k,) bool: the vertices ``points`` (k, 3) m of the surface triangulated by ``faces`` (F, 3) int that
    ``eye`` (3,) m sees: no triangle of the surface crosses the segment eye → vertex more than ``tol`` m
    before the vertex, and (``capsule`` (a, b, r) of :func:`finger_capsule`) the segment keeps more than r
    from the capsule's axis. ``targets`` (m, 3) m: test these points on the surface instead of its vertices
    ((m,) bool). Raises ``ValueError`` for mismatched shapes or an index outside ``points``."""
    import trimesh

    pts = np.asarray(points, float)
    f = np.asarray(faces)
    if pts.ndim != 2 or pts.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3:
        raise ValueError(f"points must be (k, 3) and faces (F, 3), got {pts.shape} and {f.shape}")
    if len(f) and (f.min() < 0 or f.max() >= len(pts)):
        raise ValueError(f"faces index vertices 0..{len(pts) - 1}, got {f.min()}..{f.max()}")
    q = pts if targets is None else np.asarray(targets, float).reshape(-1, 3)
    e = np.asarray(eye, float)
    d = q - e
    dist = np.linalg.norm(d, axis=1)
    ok = np.ones(len(q), bool)
    if capsule is not None:
        a, b, r = capsule
        ok &= (_segments_distance(np.broadcast_to(e, q.shape), q, np.asarray(a, float), np.asarray(b, float))
               > r)
    mesh = trimesh.Trimesh(pts, f, process=False, validate=False)
    idx = np.flatnonzero(ok)
    if len(idx) and len(f):
        dirs = d[idx] / dist[idx, None]
        tri, ray, loc = mesh.ray.intersects_id(np.broadcast_to(e, (len(idx), 3)), dirs, multiple_hits=False,
                                               return_locations=True)
        if len(ray):
            first = np.linalg.norm(loc - e, axis=1)
            hidden = first < dist[idx[ray]] - tol
            ok[idx[ray[hidden]]] = False
    return ok


def screen_px(points: np.ndarray, eye: np.ndarray) -> np.ndarray:
    """(k, 2) px: where ``eye`` (3,) m sees ``points`` (k, 3) m on the imaginary screen (the plane through
    :data:`~flexsheet.model.geometry.SCREEN_POINT` normal to ``SCREEN_NORMAL``), as its (y, z) in projector
    pixels there. Raises ``ValueError`` for a point level with the eye (seen edge-on)."""
    e = np.asarray(eye, float)
    n = geometry.SCREEN_NORMAL
    rel = np.asarray(points, float) - e
    den = rel @ n
    if np.any(np.abs(den) < 1e-9):
        raise ValueError("a point lies in the plane through the eye parallel to the screen")
    s = e + ((geometry.SCREEN_POINT - e) @ n / den)[:, None] * rel
    return s[:, 1:] / geometry.PIXEL_ON_SCREEN
