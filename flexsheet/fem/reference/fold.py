"""Does a deformed reference state fold its own surface? Self-contact and crease checks (pure).

The neo-Hookean reference (:mod:`flexsheet.fem.reference.hyperelastic`) keeps the finger out of the object but
has no *self*-contact: nothing stops one part of the object's surface from passing through another. Pushed
deep, the material dragged into the crater beside the finger is compressed along the crater's circumference (a
ring at rest radius r pulled in to the finger's radius has hoop stretch ≈ r_f / r), and a neo-Hookean surface
under compression past a critical stretch forms *creases*: sharp self-contacting folds (Biot 1963; the crease
onset of a neo-Hookean half-space in plane strain is at a compressive stretch ≈ 0.65, Hohlfeld & Mahadevan,
PRL 106, 105702, 2011). A crease has no length scale of its own, so a finite-element model without
self-contact puts its fold at the mesh scale and lets the surface cross itself: such a solution cannot
converge under mesh refinement there. These checks say whether, where and how much.

* :func:`outer_surface` — the outer boundary of a
  :class:`~flexsheet.fem.reference.hyperelastic.HyperelasticModel` as flat triangles (each P2 boundary facet
  split into 4 through its edge midpoints), oriented outward, and closed by mirroring across the model's
  symmetry planes.
* :func:`winding_numbers` — the generalised winding number w(p) = Σ Ω_t(p) / 4π of that closed surface at
  points p (Van Oosterom & Strackee, IEEE TBME 30(2), 1983, the solid angle of a triangle; Jacobson, Kavan &
  Sorkine-Hornung, SIGGRAPH 2013, for the winding number). At a point *on* a smooth part of the surface
  w = 0.5 (the material fills half of the directions around it), at the bottom of a fold closed to an interior
  angle α it is α / 2π, and w > 1 means the point is also inside another part of the body: the surface has
  passed through itself there.
* :func:`fold_report` — per state: the largest w over the surface points off the finger, how many points
  have w > 1 (penetrating), how deep the deepest lies inside (m), where, and the smallest in-plane stretch of
  the surface triangles (the crease criterion).

Units SI (m); display frame. Source of the physics: the references above; the code is ours.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["Surface", "outer_surface", "winding_numbers", "fold_report", "surface_stretch_ratios",
           "lateral_distance",
           "CREASE_STRETCH_RATIO"]

VERTEX_TOL = 1e-9       #: m: a point this close to a triangle's vertex is that vertex (its solid angle is 0)
#: compressive stretch at which a neo-Hookean surface creases (Hohlfeld & Mahadevan 2011)
CREASE_STRETCH_RATIO = 0.65


@dataclass
class Surface:
    """The closed outer surface of a model. ``tris`` (T, 3) int indices into ``model.points`` (DOF points) of
    the triangles of the modelled part, outward; ``mirrors`` list of (3,) sign vectors (±1 per axis, about
    ``center``) that copy the part onto the whole body (the identity first); ``center`` (3,) m the mirror
    point; ``points`` (S,) int the DOF points on the outer surface."""

    tris: np.ndarray
    mirrors: list
    center: np.ndarray
    points: np.ndarray

    def closed(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(V, 3) m vertices and (T·M, 3) int triangles of the whole closed surface, with the DOF points at
        positions ``x`` (P, 3) m: the part and its mirror images (orientation flipped where a mirror is
        odd)."""
        P = len(x)
        verts, tris = [], []
        for k, s in enumerate(self.mirrors):
            verts.append(self.center + (x - self.center) * s)
            t = self.tris + k * P
            tris.append(t if np.prod(s) > 0 else t[:, ::-1])
        return np.concatenate(verts), np.concatenate(tris)


def outer_surface(model) -> Surface:
    """:class:`Surface` of a :class:`~flexsheet.fem.reference.hyperelastic.HyperelasticModel`: its outer
    boundary facets (the boundary without the symmetry planes ``model.sym_y`` / ``model.sym_z``), each P2
    facet as 4 flat triangles through its corner nodes and edge midpoints (DOF points), oriented away from the
    facet's tetrahedron. Raises ``ValueError`` if an edge midpoint is missing from the DOF points (not a P2
    model)."""
    sk = model.skmesh
    c = np.asarray(model.mesh.center, float)
    tol = 1e-9
    facets = sk.boundary_facets()
    fp = sk.p[:, sk.facets[:, facets]]                                       # (3, 3, nf)
    on_y = np.all(np.abs(fp[1] - c[1]) < tol, axis=0) if model.sym_y else np.zeros(len(facets), bool)
    on_z = np.all(np.abs(fp[2] - c[2]) < tol, axis=0) if model.sym_z else np.zeros(len(facets), bool)
    outer = facets[~(on_y | on_z)]
    F = sk.facets[:, outer].T                                                # (nf, 3) node = DOF point index
    # orient each facet away from its tetrahedron's fourth node
    tet = sk.t[:, sk.f2t[0, outer]].T                                        # (nf, 4)
    X = model.points
    fourth = np.array([np.setdiff1d(t, f)[0] for t, f in zip(tet, F, strict=True)])
    a, b, cc = X[F[:, 0]], X[F[:, 1]], X[F[:, 2]]
    n = np.cross(b - a, cc - a)
    flip = np.einsum("ij,ij->i", n, X[fourth] - a) > 0
    F[flip] = F[flip][:, [0, 2, 1]]
    # the edge midpoints (P2 DOF points) of each facet's three edges
    tree = cKDTree(X)
    mids = []
    for i, j in ((0, 1), (1, 2), (2, 0)):
        d, idx = tree.query(0.5 * (X[F[:, i]] + X[F[:, j]]))
        if np.max(d, initial=0.0) > 1e-9:
            raise ValueError(f"outer_surface: an edge midpoint is not a DOF point (distance {np.max(d):.3g} "
                             "m); a P2 model is needed")
        mids.append(idx)
    m01, m12, m20 = mids
    tris = np.concatenate([np.stack([F[:, 0], m01, m20], 1), np.stack([m01, F[:, 1], m12], 1),
                           np.stack([m20, m12, F[:, 2]], 1), np.stack([m01, m12, m20], 1)])
    mirrors = [np.ones(3)]
    if model.sym_y:
        mirrors.append(np.array([1.0, -1.0, 1.0]))
    if model.sym_z:
        mirrors += [s * np.array([1.0, 1.0, -1.0]) for s in list(mirrors)]
    return Surface(tris.astype(np.int64), mirrors, c, np.unique(tris))


def winding_numbers(q: np.ndarray, verts: np.ndarray, tris: np.ndarray, chunk: int = 4_000_000) -> np.ndarray:
    """Generalised winding number (Q,) of the closed triangle surface (``verts`` (V, 3) m, ``tris`` (T, 3)
    int, outward) at points ``q`` (Q, 3) m: Σ_t Ω_t(q) / 4π, Ω_t the signed solid angle of triangle t (Van
    Oosterom & Strackee 1983). 1 inside, 0 outside, ½ on a smooth part of the surface (a triangle with q as a
    vertex, within :data:`VERTEX_TOL`, contributes 0; a point inside another triangle's edge or face lies on
    the jump of that triangle's solid angle and reads either side). ``chunk`` bounds the point × triangle
    pairs held at once (~180 bytes each: the default holds ~0.7 GB)."""
    q = np.asarray(q, float)
    A, B, C = verts[tris[:, 0]], verts[tris[:, 1]], verts[tris[:, 2]]
    out = np.empty(len(q))
    step = max(1, chunk // max(1, len(tris)))
    for s in range(0, len(q), step):
        p = q[s:s + step, None, :]
        a, b, c = A[None] - p, B[None] - p, C[None] - p
        la, lb, lc = (np.linalg.norm(v, axis=2) for v in (a, b, c))
        num = np.einsum("qtk,qtk->qt", a, np.cross(b, c))
        den = la * lb * lc + np.einsum("qtk,qtk->qt", a, b) * lc + np.einsum("qtk,qtk->qt", b, c) * la \
            + np.einsum("qtk,qtk->qt", c, a) * lb
        om = 2.0 * np.arctan2(num, den)
        om[np.minimum(np.minimum(la, lb), lc) < VERTEX_TOL] = 0.0      # q is a vertex of t: no solid angle
        out[s:s + step] = om.sum(axis=1) / (4.0 * np.pi)
    return out


def surface_stretch_ratios(surf: Surface, x0: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(T, 2) principal in-plane stretches (smallest first) of the part's surface triangles between rest
    ``x0`` (P, 3) m and deformed ``x`` (P, 3) m DOF positions: the singular values of the map between the
    triangles' edge vectors. Raises ``numpy.linalg.LinAlgError`` on a degenerate rest triangle."""
    t = surf.tris
    E0 = np.stack([x0[t[:, 1]] - x0[t[:, 0]], x0[t[:, 2]] - x0[t[:, 0]]], axis=2)   # (T, 3, 2)
    E1 = np.stack([x[t[:, 1]] - x[t[:, 0]], x[t[:, 2]] - x[t[:, 0]]], axis=2)
    # orthonormal frame of the rest triangle: E0 = Q R; the 3x2 map is E1 R⁻¹
    Q, R = np.linalg.qr(E0)
    M = E1 @ np.linalg.inv(R)
    return np.linalg.svd(M, compute_uv=False)[:, ::-1]


def lateral_distance(x: np.ndarray, capsule) -> np.ndarray:
    """(N,) m distance of points ``x`` (N, 3) m from the finger's push axis (the line through
    ``capsule.center`` along ``capsule.direction``)."""
    rel = np.asarray(x, float) - capsule.center
    d = capsule.direction
    return np.linalg.norm(rel - np.outer(rel @ d, d), axis=1)


def fold_report(model, surf: Surface, u: np.ndarray, capsule, region: float, margin: float = 0.002) -> dict:
    """Fold and self-contact check of one state: ``u`` (P, 3) m displacements of ``model``'s DOF points,
    ``capsule`` the finger (:class:`~flexsheet.fem.reference.capsule_contact.Capsule`), ``region`` m: only
    surface points within this lateral distance of the push axis (rest position) are checked (the crater; the
    rest stays smooth). Points whose deformed position lies inside the finger's footprint (lateral distance ≤
    radius + ``margin``, as the visible-surface metric) are left out, and so are triangles whose deformed
    centroid does.

    Returns {"max_winding": largest w (0.5 smooth; α/2π at a fold of interior angle α; > 1 penetrating),
    "n_penetrating": points with w > 1, "max_penetration_m": the deepest of them from the nearest surface
    triangle that is not within 3 rest edge lengths of it (m; 0 if none), "worst_rest_m" (3,) rest position of
    the largest-w point, "worst_lateral_m" / "worst_drop_m": its rest distance from the push axis and how far
    it moved along the push (m), "min_stretch_ratio": smallest in-plane stretch of the surface triangles off
    the footprint (the crease criterion: < :data:`CREASE_STRETCH_RATIO`), "n_creased_tris": how many are below
    it, "max_stretch_ratio" the largest in-plane stretch ratio λ there and "max_stretch_ratio_lateral_m" its
    triangle's rest distance from the push axis}. w is sampled at the surface's own points (DOF points): a
    facet that crosses another between them is not seen. "max_winding" is NaN when no point is checked;
    ``margin`` = -inf checks the footprint too."""
    X0 = model.points
    x = X0 + u
    verts, tris = surf.closed(x)
    d = capsule.direction
    lat0 = lateral_distance(X0[surf.points], capsule)
    lat = lateral_distance(x[surf.points], capsule)
    sel = (lat0 < region) & (lat > capsule.radius + margin) & ~model.support[surf.points]
    pts = surf.points[sel]
    w = winding_numbers(x[pts], verts, tris) if len(pts) else np.zeros(0)
    out = {"max_winding": float(w.max()) if len(w) else float("nan"),
           "n_penetrating": int(np.count_nonzero(w > 1.0)),
           "max_penetration_m": 0.0, "worst_rest_m": None, "worst_lateral_m": None, "worst_drop_m": None}
    if len(pts):
        k = int(np.argmax(w))
        out["worst_rest_m"] = X0[pts[k]].tolist()
        out["worst_lateral_m"] = float(lat0[sel][k])
        out["worst_drop_m"] = float(u[pts[k]] @ d)
    pen = pts[w > 1.0]
    if len(pen):
        from trimesh.triangles import closest_point

        t_rest = surf.closed(X0)[0][tris].mean(axis=1)        # rest centroids, mirror images mirrored too
        edge = np.median(np.linalg.norm(X0[surf.tris[:, 1]] - X0[surf.tris[:, 0]], axis=1))
        tree = cKDTree(verts[tris].mean(axis=1))
        depth = []
        for p in pen:
            _, cand = tree.query(x[p], k=min(256, len(tris)))
            cand = cand[np.linalg.norm(t_rest[cand] - X0[p], axis=1) > 3 * edge]
            if not len(cand):       # every near triangle is its own neighbourhood: take them all
                cand = np.flatnonzero(np.linalg.norm(t_rest - X0[p], axis=1) > 3 * edge)
            if len(cand):
                cp = closest_point(verts[tris[cand]], np.repeat(x[p][None], len(cand), axis=0))
                depth.append(float(np.min(np.linalg.norm(cp - x[p], axis=1))))
        out["max_penetration_m"] = max(depth, default=0.0)
    st = surface_stretch_ratios(surf, X0, x)
    tlat = lateral_distance(x[surf.tris].mean(axis=1), capsule)
    tlat0 = lateral_distance(X0[surf.tris].mean(axis=1), capsule)
    off = (tlat > capsule.radius + margin) & (tlat0 < region) & ~np.all(model.support[surf.tris], axis=1)
    out["min_stretch_ratio"] = float(st[off, 0].min(initial=1.0))
    out["n_creased_tris"] = int(np.count_nonzero(st[off, 0] < CREASE_STRETCH_RATIO))
    out["max_stretch_ratio"] = float(st[off, 1].max(initial=1.0))
    out["max_stretch_ratio_lateral_m"] = float(tlat0[off][np.argmax(st[off, 1])]) if off.any() else None
    return out
