"""The FEM's judge: how far a served surface is from the reference's as the eyes see it, split into what the
eye notices and what it does not, in projector pixels (:mod:`flexsheet.fem.eye_view` finds what each eye
sees).

* **Shape** (:func:`judge`): each rendered vertex the eye sees, moved to the reference's deformed surface by
  the shortest way (the closest point on it, ``trimesh``), is its **shape** error; the rest, from that closest
  point to the reference's own vertex, is **sliding** along the surface. Uniform shading does not show sliding
  (a texture would), so shape is judged and sliding reported beside it. Each is the largest distance, over
  both eyes, between where the eye sees the two points on the imaginary screen.
* **Silhouette** (:func:`silhouette_px`): each eye's outline of the surface against the background, the zero
  set of n·(x − eye) interpolated over the triangles from area-weighted vertex normals (Hertzmann & Zorin,
  SIGGRAPH 2000: smooth where the per-face outline zigzags), the parts the eye sees with nothing behind them;
  the error is the symmetric Hausdorff distance between the served and the reference outline on the screen.
* **Contact** (:func:`contact_gap`): the drawn dent against the fingertip's sphere: the surface's least
  distance to the sphere's centre less its radius (> 0 a gap, < 0 the surface drawn inside the finger), as
  each eye sees
  it: the larger of the gap's shift on the screen and its change of stereo disparity.
* **Temporal** (:func:`frame_jumps`): each frame's change of the served surface less the change the frames
  around it make (a second difference: a smooth reference's change at frame rate is its neighbours' mean), so
  a table cell or a model switching shows as a jump.

Frame ``display``; units m in, px out (one projector pixel on the imaginary screen,
:data:`flexsheet.model.geometry.PIXEL_ON_SCREEN`).
"""

from __future__ import annotations

import numpy as np

from flexsheet.fem.eye_view import eyes, finger_capsule, screen_px, seen

__all__ = ["judge", "shape_px_by_depth", "silhouette_px", "contour_segments", "contact_gap", "frame_jumps",
           "SILHOUETTE_STEP_PX"]

#: the outline is sampled every this many px on the screen before the Hausdorff distance (its error ≤ half)
SILHOUETTE_STEP_PX = 0.1


def _check_pts(name: str, a: np.ndarray, like: np.ndarray | None = None) -> np.ndarray:
    a = np.asarray(a, float)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name} must be (k, 3) m, got shape {a.shape}")
    if like is not None and a.shape != like.shape:
        raise ValueError(f"{name} {a.shape} must match the reference's {like.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite")
    return a


def vertex_normals(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(k, 3) unit area-weighted vertex normals of the triangulated surface (faces (F, 3), counter-clockwise
    seen from outside)."""
    p = points[faces]
    fn = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])           # |fn| = 2 × area
    vn = np.zeros_like(points)
    for c in range(3):
        np.add.at(vn, faces[:, c], fn)
    return vn / np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-30)


def contour_segments(points: np.ndarray, faces: np.ndarray, eye: np.ndarray) -> np.ndarray:
    """(S, 2, 3) m: the interpolated outline of the surface seen from ``eye`` (3,) m: per triangle where
    g = n_v·(v − eye) changes sign, the segment between the zero crossings on its edges."""
    e = np.asarray(eye, float)
    g = np.einsum("ij,ij->i", vertex_normals(points, faces), points - e)
    gf = g[faces]
    segs = []
    for a, b, c in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        # the lone vertex a on one side: crossings on edges a-b and a-c
        lone = (np.sign(gf[:, a]) != np.sign(gf[:, b])) & (np.sign(gf[:, a]) != np.sign(gf[:, c])) \
            & (gf[:, a] != 0)
        if not lone.any():
            continue
        f, ga, gb, gc = faces[lone], gf[lone, a], gf[lone, b], gf[lone, c]
        pa, pb, pc = points[f[:, a]], points[f[:, b]], points[f[:, c]]
        tb = (ga / (ga - gb))[:, None]
        tc = (ga / (ga - gc))[:, None]
        segs.append(np.stack([pa + tb * (pb - pa), pa + tc * (pc - pa)], axis=1))
    return np.concatenate(segs) if segs else np.zeros((0, 2, 3))


def _outline_px(points, faces, eye, capsule, tol) -> np.ndarray:
    """(n, 2) px: the seen outline against the background on the screen, sampled every
    :data:`SILHOUETTE_STEP_PX` (each sample tested on its own, so an occluder clips the outline where it
    ends)."""
    seg = contour_segments(points, faces, eye)
    if not len(seg):
        return np.zeros((0, 2))
    a, b = screen_px(seg[:, 0], eye), screen_px(seg[:, 1], eye)
    n = np.maximum(1, np.ceil(np.linalg.norm(b - a, axis=1) / SILHOUETTE_STEP_PX).astype(int))
    t = np.concatenate([(np.arange(k) + 0.5) / k for k in n])
    rep = np.repeat(np.arange(len(n)), n)
    q = seg[rep, 0] + t[:, None] * (seg[rep, 1] - seg[rep, 0])
    ok = seen(points, faces, eye, capsule, tol, targets=q) & _against_background(q, points, faces, eye, tol)
    return screen_px(q[ok], eye)


def _against_background(q, points, faces, eye, skip: float) -> np.ndarray:
    """(m,) bool: outline points ``q`` (m, 3) m with nothing of the surface behind them on the eye's ray (from
    ``skip`` m past the point on): the object's outline against the background, not a fold or a crater's wall
    inside it, whose outline appears and vanishes as the surface turns by a hair at grazing."""
    import trimesh

    if not len(q):
        return np.zeros(0, bool)
    d = q - np.asarray(eye, float)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    mesh = trimesh.Trimesh(points, faces, process=False, validate=False)
    return ~mesh.ray.intersects_any(q + skip * d, d)


def _edge_length(points: np.ndarray, faces: np.ndarray) -> float:
    """The median edge length of the triangles, m."""
    p = points[faces]
    return float(np.median(np.linalg.norm(p - np.roll(p, 1, axis=1), axis=2)))


def _outlines(points, faces, pair, capsule, tol) -> list[np.ndarray]:
    """Per eye of ``pair``: :func:`_outline_px` of the surface ``points`` on ``faces``."""
    return [_outline_px(points, faces, e, capsule, tol) for e in pair]


def _hausdorff_px(model_outlines: list[np.ndarray], ref_outlines: list[np.ndarray]) -> float:
    """The largest, over the eyes, symmetric Hausdorff distance (px) between two sets of :func:`_outlines`:
    0.0 where neither is seen, ``inf`` where one is seen and the other not."""
    from scipy.spatial import cKDTree

    worst = 0.0
    for a, b in zip(model_outlines, ref_outlines, strict=True):
        if not len(a) and not len(b):
            continue
        if not len(a) or not len(b):
            return float("inf")
        worst = max(worst, float(cKDTree(b).query(a)[0].max()), float(cKDTree(a).query(b)[0].max()))
    return worst


def silhouette_px(model_pts: np.ndarray, ref_pts: np.ndarray, faces: np.ndarray, finger=None,
                  eye_pair: np.ndarray | None = None, tol: float | None = None) -> float:
    """The largest, over both eyes, symmetric Hausdorff distance (px) between the seen outline of the served
    surface ``model_pts`` (k, 3) m and the reference's ``ref_pts`` (k, 3) m on the same ``faces`` (F, 3); the
    ``finger`` (center, direction, radius; or None) occludes. An outline point is seen when no surface lies
    more than ``tol`` m before it on the eye's ray (default twice the median edge: a grazing ray crosses the
    polygon's own chords that far before the smooth outline). 0.0 when neither outline is seen; ``inf``
    when one is seen and the other not. Raises ``ValueError`` for bad shapes."""
    r = _check_pts("ref_pts", ref_pts)
    m = _check_pts("model_pts", model_pts, r)
    f = np.asarray(faces)
    cap = finger_capsule(finger) if finger is not None else None
    tol = 2.0 * _edge_length(r, f) if tol is None else tol
    pair = eyes() if eye_pair is None else np.asarray(eye_pair, float)
    return _hausdorff_px(_outlines(m, f, pair, cap, tol), _outlines(r, f, pair, cap, tol))


def judge(models: list[np.ndarray], ref_pts: np.ndarray, faces: np.ndarray, finger=None,
          eye_pair: np.ndarray | None = None, silhouette: bool = True) -> tuple[list[dict], int]:
    """Each of ``models`` (each (k, 3) m, the rendered vertices deformed by a model) against ``ref_pts`` (k,
    3) m (deformed by the reference) as the eyes see it (module doc): per model {"shape_px", "sliding_px",
    "total_px" (the old vertex-to-vertex figure), "silhouette_px" (None unless ``silhouette``)}, the largest
    over the vertices either eye sees on the reference's surface (``faces`` (F, 3)) past the ``finger``; and
    how many vertices either eye sees. Raises ``ValueError`` for mismatched or non-finite input."""
    import trimesh

    r = _check_pts("ref_pts", ref_pts)
    ms = [_check_pts(f"models[{i}]", m, r) for i, m in enumerate(models)]
    f = np.asarray(faces)
    cap = finger_capsule(finger) if finger is not None else None
    ref_mesh = trimesh.Trimesh(r, f, process=False, validate=False)
    closest = [trimesh.proximity.closest_point(ref_mesh, m)[0] for m in ms]
    out = [{"shape_px": 0.0, "sliding_px": 0.0, "total_px": 0.0, "silhouette_px": None} for _ in ms]
    pair = eyes() if eye_pair is None else np.asarray(eye_pair, float)
    seen_any = np.zeros(len(r), bool)
    for e in pair:
        vis = seen(r, f, e, cap)
        seen_any |= vis
        if not vis.any():
            continue
        s_ref = screen_px(r[vis], e)
        for o, m, c in zip(out, ms, closest, strict=True):
            s_m, s_c = screen_px(m[vis], e), screen_px(c[vis], e)
            o["shape_px"] = max(o["shape_px"], float(np.linalg.norm(s_m - s_c, axis=1).max()))
            o["sliding_px"] = max(o["sliding_px"], float(np.linalg.norm(s_c - s_ref, axis=1).max()))
            o["total_px"] = max(o["total_px"], float(np.linalg.norm(s_m - s_ref, axis=1).max()))
    if silhouette:                       # the reference's outlines once, for every model
        tol = 2.0 * _edge_length(r, f)
        ref_out = _outlines(r, f, pair, cap, tol)
        for o, m in zip(out, ms, strict=True):
            o["silhouette_px"] = _hausdorff_px(_outlines(m, f, pair, cap, tol), ref_out)
    return out, int(seen_any.sum())


def _disparity(p: np.ndarray, pair: np.ndarray) -> np.ndarray:
    """(k, 2) px: where the left eye sees ``p`` (k, 3) less where the right one does."""
    return screen_px(p, pair[0]) - screen_px(p, pair[1])


def contact_gap(points: np.ndarray, faces: np.ndarray, finger, eye_pair: np.ndarray | None = None) -> dict:
    """The drawn dent against the fingertip (module doc): the served surface ``points`` (k, 3) m on ``faces``,
    the ``finger`` (``center`` (3,) m, ``radius`` m). Returns {"gap_m" (signed: > 0 a gap, < 0 penetration),
    "gap_px" (≥ 0: the larger of the gap's shift on the screen, either eye, and its change of disparity)}.
    Raises ``ValueError`` for bad shapes or a finger centre inside the surface's far side (no contact
    geometry)."""
    import trimesh

    p = _check_pts("points", points)
    c = np.asarray(finger.center, float)
    rad = float(finger.radius)
    mesh = trimesh.Trimesh(p, np.asarray(faces), process=False, validate=False)
    q, dist, _ = trimesh.proximity.closest_point(mesh, c[None])
    q, d = q[0], float(dist[0])
    if d < 1e-12:
        raise ValueError("finger.center lies on the surface: no gap direction")
    u = (q - c) / d
    on_sphere = c + rad * u                       # the finger's point facing the surface
    gap = d - rad
    pair = eyes() if eye_pair is None else np.asarray(eye_pair, float)
    shift = max(float(np.linalg.norm(screen_px(q[None], e) - screen_px(on_sphere[None], e))) for e in pair)
    disp = float(np.linalg.norm(_disparity(q[None], pair) - _disparity(on_sphere[None], pair))) \
        if len(pair) == 2 else 0.0
    return {"gap_m": gap, "gap_px": max(shift, disp)}


def frame_jumps(frames: list[np.ndarray], faces: np.ndarray, fingers: list | None = None,
                eye_pair: np.ndarray | None = None) -> np.ndarray:
    """(N − 3,) px: for consecutive served surfaces ``frames`` (N ≥ 4, each (k, 3) m) the jump of each
    frame-to-frame change k → k+1 (module doc) — the largest, over the vertices each eye sees on frame k
    (``fingers[k]`` occluding) and both eyes, of |Δs_k − (Δs_{k−1} + Δs_{k+1})/2| with s the screen position,
    px. Raises ``ValueError`` for fewer than 4 frames or mismatched shapes."""
    fr = [_check_pts(f"frames[{i}]", x, np.asarray(frames[0], float)) for i, x in enumerate(frames)]
    if len(fr) < 4:
        raise ValueError(f"frames: need at least 4, got {len(fr)}")
    if fingers is not None and len(fingers) != len(fr):
        raise ValueError(f"fingers: {len(fingers)} for {len(fr)} frames")
    f = np.asarray(faces)
    pair = eyes() if eye_pair is None else np.asarray(eye_pair, float)
    out = np.zeros(len(fr) - 3)
    for e in pair:
        s = np.stack([screen_px(x, e) for x in fr])              # (N, k, 2)
        d = np.diff(s, axis=0)                                   # (N-1, k, 2)
        j = d[1:-1] - 0.5 * (d[:-2] + d[2:])                     # change k→k+1, k = 1..N-3
        for i in range(len(out)):
            cap = (finger_capsule(fingers[i + 1]) if fingers is not None and fingers[i + 1] is not None
                   else None)
            vis = seen(fr[i + 1], f, e, cap)
            if vis.any():
                out[i] = max(out[i], float(np.linalg.norm(j[i][vis], axis=1).max()))
    return out


def shape_px_by_depth(model_u, ref_u, verts, faces, fingers) -> list[float]:
    """The largest visible shape error (px; the larger of the seen vertices' distance to the reference's
    surface and the outlines', :func:`judge`) per depth of ``model_u`` against ``ref_u`` ((D, S, 3) m
    displacements of the rendered vertices ``verts`` (S, 3) m on ``faces`` (F, 3)), ``fingers[j]`` (D,)
    occluding: the metric of every table check."""
    out = []
    for j, fg in enumerate(fingers):
        (o,), _ = judge([verts + np.asarray(model_u[j], float)], verts + np.asarray(ref_u[j], float), faces,
                        fg)
        out.append(max(o["shape_px"], o["silhouette_px"]))
    return out
