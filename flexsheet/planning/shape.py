"""The planner's shape of a scene (pure): :meth:`flexsheet.model.scenes.Scene.shape`, with smooth normals on
meshes.

For the analytic kinds (cylinder, sphere, rounded box) this is ``scene.shape()`` itself. A mesh scene's
``scene.shape()`` is a :class:`flexsheet.model.shapes.MeshShape`, whose normals are the *face* normals: on the
organ's 5120-triangle mesh they jump by a few degrees from face to face, so the sheet would shake as the
finger strokes and the Table I metric would measure the facets. :class:`SmoothMeshShape` keeps the mesh's
closest point and inside test and replaces the normal by the scene's smoothed surface normal on every path
(closest point, support point, centre-ray exit)
(:meth:`flexsheet.model.scenes.Scene.surface_point`: corner normals averaged within 30° creases and
interpolated barycentrically — the normals the renderer and the world use), and finds the plane's support
point *locally* (a non-convex organ's global support can be on its other side).

Units m; display frame.
"""

from __future__ import annotations

import numpy as np

from flexsheet.model.shape_base import Shape
from flexsheet.model.shapes import MeshShape
from flexsheet.model.vec import Vec, dot, norm, sub

__all__ = ["planner_shape", "SmoothMeshShape", "principal_curvatures"]

#: id(scene) → (scene, its SmoothMeshShape): one trimesh query structure per mesh scene object
_CACHE: dict[int, tuple] = {}


class SmoothMeshShape(MeshShape):
    """A mesh scene's surface with the scene's smooth normals (module doc). ``scene``: a mesh
    :class:`flexsheet.model.scenes.Scene`. Queries cost ≈ 1 ms (trimesh's closest point)."""

    def __init__(self, scene) -> None:
        super().__init__(scene.trimesh())
        self.scene = scene

    def _ray_exit(self, s: Vec, w: Vec) -> tuple[Vec, Vec]:
        """Exit point (3,) m of the ray from ``s`` (inside) along unit ``w``, and the smooth normal (3,)
        there: one trimesh ray cast (the farthest hit), the corner normals interpolated barycentrically in the
        hit triangle (the centre ray of a convex mesh, :meth:`Shape.project`, sees no facets)."""
        loc, _, tri = self.mesh.ray.intersects_location(np.asarray([s]), np.asarray([w]), multiple_hits=True)
        if len(loc) == 0:
            return Shape._ray_exit(self, s, w)          # Newton on the smooth closest point
        k = int(np.argmax((loc - np.asarray(s)) @ np.asarray(w)))
        t = int(tri[k])
        n = _barycentric(self.mesh.triangles[t], loc[k]) @ self.scene.mesh_corner_normals()[t]
        n /= np.linalg.norm(n)
        return tuple(float(x) for x in loc[k]), tuple(float(x) for x in n)  # type: ignore[return-value]

    def closest(self, p: Vec) -> tuple[Vec, Vec, float]:
        """Closest point q (3,) m, smooth outward normal n (3,), signed distance m (< 0 inside; the side from
        the smooth normal where it is clear, else trimesh's containment test)."""
        x = np.asarray([p], dtype=float)
        qa, na = self.scene.surface_point(x)
        q = tuple(float(v) for v in qa[0])
        n = tuple(float(v) for v in na[0])
        d = norm(sub(p, q))
        side = dot(sub(p, q), n)
        if d <= 1e-12:
            return q, n, 0.0       # type: ignore[return-value]
        inside = side < 0.0 if abs(side) > 0.5 * d else bool(self.mesh.contains(x)[0])
        return q, n, (-d if inside else d)  # type: ignore[return-value]

    def closest_many(self, points) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`closest` for points (N, 3) m at once: (q (N, 3) m, n (N, 3), signed distance (N,) m), one
        batched closest-point query (and one containment test for the rows whose side is unclear)."""
        x = np.asarray(points, float).reshape(-1, 3)
        q, n = self.scene.surface_point(x)
        r = x - q
        d = np.linalg.norm(r, axis=1)
        side = np.einsum("ij,ij->i", r, n)
        inside = side < 0.0
        unclear = (d > 1e-12) & (np.abs(side) <= 0.5 * d)
        if unclear.any():
            inside[unclear] = self.mesh.contains(x[unclear])
        return q, n, np.where(d <= 1e-12, 0.0, np.where(inside, -d, d))

    def support(self, n: Vec, near: Vec, max_iter: int = 20) -> Vec:
        """The surface point near ``near`` (3,) m whose smooth normal is ``n`` (3,) unit: where a plane of
        normal ``n`` touches the surface there. Fixed-point iteration q ← closest(q + ρ (n − n_q)) with ρ the
        local radius of curvature (secant estimate, 5–100 mm); stops at |n − n_q| < 1e-7 or after ``max_iter``
        steps, returning the iterate whose normal is nearest ``n``."""
        nn = np.asarray(n, float) / np.linalg.norm(n)
        q, nq, _ = self.closest(near)
        qv, nv = np.asarray(q), np.asarray(nq)
        best, best_err = qv, float(np.linalg.norm(nn - nv))
        rho = 0.03
        for _ in range(max_iter):
            dn = nn - nv
            dn -= (dn @ nv) * nv
            if np.linalg.norm(dn) < 1e-7:
                break
            step = rho * dn
            ls = float(np.linalg.norm(step))
            if ls > 0.01:
                step *= 0.01 / ls
            q1, n1, _ = self.closest(tuple(qv + step))
            q1v, n1v = np.asarray(q1), np.asarray(n1)
            dq, dnn = float(np.linalg.norm(q1v - qv)), float(np.linalg.norm(n1v - nv))
            if dnn > 1e-12:
                rho = min(0.1, max(0.005, dq / dnn))
            qv, nv = q1v, n1v
            err = float(np.linalg.norm(nn - nv))
            if err < best_err:
                best, best_err = qv, err
        return tuple(float(v) for v in best)  # type: ignore[return-value]

    def support_many(self, normals, near, max_iter: int = 20) -> np.ndarray:
        """:meth:`support` for many planes at once: the points (N, 3) m for unit ``normals`` (N, 3) near
        ``near`` (N, 3) m. The same iteration row by row, each row stopping on its own, with one batched
        closest-point query per step (a report's thousands of samples: one trimesh query per step, not per
        sample and step)."""
        nn = np.asarray(normals, float).reshape(-1, 3)
        nn = nn / np.linalg.norm(nn, axis=1, keepdims=True)
        qv, nv = self.scene.surface_point(np.asarray(near, float).reshape(-1, 3))
        best, best_err = qv.copy(), np.linalg.norm(nn - nv, axis=1)
        rho = np.full(len(nn), 0.03)
        live = np.ones(len(nn), bool)
        for _ in range(max_iter):
            dn = nn - nv
            dn -= np.einsum("ij,ij->i", dn, nv)[:, None] * nv
            live &= np.linalg.norm(dn, axis=1) >= 1e-7
            if not live.any():
                break
            i = np.flatnonzero(live)
            step = rho[i, None] * dn[i]
            ls = np.linalg.norm(step, axis=1)
            big = ls > 0.01
            step[big] *= (0.01 / ls[big])[:, None]
            q1, n1 = self.scene.surface_point(qv[i] + step)
            dq, dnn = np.linalg.norm(q1 - qv[i], axis=1), np.linalg.norm(n1 - nv[i], axis=1)
            ok = dnn > 1e-12
            rho[i[ok]] = np.clip(dq[ok] / dnn[ok], 0.005, 0.1)
            qv[i], nv[i] = q1, n1
            err = np.linalg.norm(nn[i] - n1, axis=1)
            better = err < best_err[i]
            best[i[better]], best_err[i[better]] = q1[better], err[better]
        return best


def _barycentric(tri: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Barycentric weights (3,) of point ``q`` (3,) in triangle ``tri`` (3, 3) (its plane's projection)."""
    a, b, c = tri
    v0, v1, v2 = b - a, c - a, q - a
    d00, d01, d11, d20, d21 = v0 @ v0, v0 @ v1, v1 @ v1, v2 @ v0, v2 @ v1
    den = d00 * d11 - d01 * d01
    y = (d11 * d20 - d01 * d21) / den
    z = (d00 * d21 - d01 * d20) / den
    return np.array([1.0 - y - z, y, z])


def planner_shape(scene) -> Shape:
    """The :class:`flexsheet.model.shape_base.Shape` the planner, the world and the Table I metric use for
    ``scene`` (a :class:`flexsheet.model.scenes.Scene`): ``scene.shape()`` for analytic kinds, a
    :class:`SmoothMeshShape` for a mesh (one per scene object, cached)."""
    if scene.object.kind != "mesh":
        return scene.shape()
    hit = _CACHE.get(id(scene))
    if hit is None or hit[0] is not scene:
        hit = (scene, SmoothMeshShape(scene))
        _CACHE[id(scene)] = hit
    return hit[1]


def principal_curvatures(shape: Shape, q: Vec, n: Vec, h: float = 0.002) -> tuple[float, float]:
    """Principal curvatures (κ1 ≥ κ2) 1/m of ``shape`` at surface point ``q`` (3,) m with outward normal ``n``
    (3,): the symmetric part of the shape operator from central differences of the normal field at
    q ± h·e₁, q ± h·e₂ (``h`` m; e₁, e₂ a tangent basis), corrected for the offset points lying off the
    surface (exact on spheres and cylinders). Convex > 0. Averages over ±h (2 mm: the finger's contact
    scale), so a mesh's facets do not show."""
    nv = np.asarray(n, float)
    nv /= np.linalg.norm(nv)
    a = np.array([0.0, 1.0, 0.0]) if abs(nv[1]) < 0.9 else np.array([0.0, 0.0, 1.0])
    e1 = a - (a @ nv) * nv
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(nv, e1)
    qv = np.asarray(q, float)
    S = np.empty((2, 2))
    for j, e in enumerate((e1, e2)):
        n_p = np.asarray(shape.closest(tuple(qv + h * e))[1])
        n_m = np.asarray(shape.closest(tuple(qv - h * e))[1])
        dn = (n_p - n_m) / (2.0 * h)
        S[0, j], S[1, j] = dn @ e1, dn @ e2
    S = 0.5 * (S + S.T)
    k = np.linalg.eigvalsh(S)
    if not np.all(np.isfinite(k)):
        return 0.0, 0.0
    # a tangent offset h off a circle of curvature κ meets its normal at atan(hκ): the difference gives
    # κ/√(1 + h²κ²); undo that (exact on spheres and cylinders)
    hk = np.clip(h * k, -0.99, 0.99)
    k = k / np.sqrt(1.0 - hk * hk)
    return float(k[1]), float(k[0])
