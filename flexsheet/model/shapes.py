"""Virtual shapes the sheet presents: closest point, normal, centre-ray hit, arc (geodesic) length (pure).

Every shape lives in the ``display`` frame (m). Points are (3,) sequences of floats; results are plain
float tuples (see :mod:`flexsheet.model.vec`, chosen for speed on the ≤ 50 µs planner path).

Shapes: :class:`Cylinder` (the paper's cylinder, capped, §VI-A), :class:`Sphere`, :class:`RoundedBox`
(Minkowski sum of a box and a ball; radius 0 gives a sharp box), :class:`Plane` and :class:`MeshShape`
(any closed triangle mesh through trimesh: I/O, closest point, containment, ray casts).

Placement rule (paper §V-A, Fig. 7(a)): the contact point A is where the line from the fingertip to the
object's centre O meets the surface. For a cylinder the paper's "centre" is the axis (its Fig. 7 is a
cross-section), so the ray is radial. We generalise O to a *skeleton* inside the shape: a point (sphere),
the axis segment shortened by ``end_margin`` at each end (cylinder) or a shrunk box (rounded box). The
ray from the skeleton point nearest the fingertip through the fingertip is well defined everywhere except
on the skeleton itself, is continuous across end caps and box edges, and for the cylinder's side is
exactly the paper's radial construction. Non-convex meshes use the closest point.

Errors: constructors raise ``ValueError`` naming the bad field; :meth:`Shape.project` never raises for
finite points: it returns ``singular=True`` (and a held direction) where the ray is undefined.
"""

from __future__ import annotations

import math
from typing import Any

from flexsheet.model import geometry
from flexsheet.model.checks import check_positive
from flexsheet.model.shape_base import Shape, unit3, vec3
from flexsheet.model.vec import Vec, add, axpy, cross, dot, norm, perp_unit, scale, sub, unit

__all__ = ["Cylinder", "Sphere", "RoundedBox", "Plane", "MeshShape", "make_shape",
           "paper_cylinder"]


class Cylinder(Shape):
    """Capped circular cylinder: centre (3,) m on the axis, unit ``axis`` (3,), ``radius`` m, ``length`` m.

    The skeleton is the axis segment |h| ≤ length/2 − end_margin (``end_margin`` defaults to radius/2), so
    beyond the caps the centre ray wraps over the rim onto the cap continuously. Edges are sharp; outside
    the rim the closest-point normal is the rim-to-point direction (continuous).
    """

    kind = "cylinder"

    def __init__(self, center: Any, axis: Any, radius: float, length: float, end_margin: float | None = None):
        self.c = vec3("center", center)
        self.a = unit3("axis", axis)
        self.R = check_positive("radius", radius)
        self.L = check_positive("length", length)
        m = 0.5 * self.R if end_margin is None else check_positive("end_margin", end_margin, allow_zero=True)
        self.hs = max(0.0, 0.5 * self.L - min(m, 0.5 * self.L))
        self.e1 = perp_unit(self.a, (1.0, 0.0, 0.0))    # angle 0 direction (toward the user at home)
        self.e2 = cross(self.a, self.e1)

    @property
    def axis(self) -> Vec:
        """Unit axis direction (3,) (the Fig. 9 cross-section is normal to it)."""
        return self.a

    def _split(self, p: Vec) -> tuple[float, Vec, float]:
        d = sub(p, self.c)
        h = dot(d, self.a)
        r = axpy(-h, self.a, d)
        return h, r, norm(r)

    def angle_of(self, p: Vec) -> float:
        """Angle of p around the axis, rad, from ``e1`` (+x at home) toward ``a × e1``."""
        _, r, _ = self._split(p)
        return math.atan2(dot(r, self.e2), dot(r, self.e1))

    def point_at(self, angle: float, h: float = 0.0, radius: float | None = None) -> Vec:
        """Point at ``angle`` rad around the axis, axial offset ``h`` m, distance ``radius`` m (default R)."""
        rr = self.R if radius is None else radius
        ca, sa = math.cos(angle), math.sin(angle)
        rad = (self.e1[0] * ca + self.e2[0] * sa, self.e1[1] * ca + self.e2[1] * sa,
               self.e1[2] * ca + self.e2[2] * sa)
        return add(axpy(h, self.a, self.c), scale(rad, rr))

    def closest(self, p: Vec) -> tuple[Vec, Vec, float]:
        h, r, rho = self._split(p)
        hl = 0.5 * self.L
        rhat = unit(r) or self.e1
        ah = abs(h)
        sg = 1.0 if h >= 0.0 else -1.0
        if ah <= hl and rho <= self.R:            # inside: nearest of side and caps
            ds, dc = self.R - rho, hl - ah
            if ds <= dc:
                q = add(axpy(h, self.a, self.c), scale(rhat, self.R))
                return q, rhat, -ds
            q = add(axpy(sg * hl, self.a, self.c), r)
            return q, scale(self.a, sg), -dc
        hc = max(-hl, min(hl, h))
        rc = min(rho, self.R)
        q = add(axpy(hc, self.a, self.c), scale(rhat, rc))
        if ah <= hl:
            return q, rhat, rho - self.R
        if rho <= self.R:
            return q, scale(self.a, sg), ah - hl
        d = sub(p, q)
        dist = norm(d)
        return q, scale(d, 1.0 / dist), dist

    def skeleton_point(self, p: Vec) -> Vec:
        h = dot(sub(p, self.c), self.a)
        return axpy(max(-self.hs, min(self.hs, h)), self.a, self.c)

    def _ray_exit(self, s: Vec, w: Vec) -> tuple[Vec, Vec]:
        # s is on the axis: radial speed |w_r|, axial speed w_h.
        wh = dot(w, self.a)
        wr = axpy(-wh, self.a, w)
        rw = norm(wr)
        hs = dot(sub(s, self.c), self.a)
        t_side = self.R / rw if rw > 1e-15 else math.inf
        if abs(wh) > 1e-15:
            sg = 1.0 if wh > 0 else -1.0
            t_cap = (0.5 * self.L - sg * hs) / abs(wh)
        else:
            sg, t_cap = 1.0, math.inf
        q = axpy(min(t_side, t_cap), w, s)
        if math.isfinite(t_side) and abs(t_side - t_cap) <= 1e-12 * max(1.0, t_side):
            n = unit(add(scale(wr, 1.0 / rw), scale(self.a, sg)))
            return q, n  # type: ignore[return-value]
        if t_side < t_cap:
            return q, scale(wr, 1.0 / rw)
        return q, scale(self.a, sg)

    def default_direction(self, p: Vec) -> Vec:
        return self.e1

    def geodesic_step(self, q0: Vec, q1: Vec) -> Vec:
        """Exact on the side (unrolled cylinder: R·Δφ around, Δh along); chord rule on caps/rims."""
        h0, r0, p0 = self._split(q0)
        h1, r1, p1 = self._split(q1)
        hl = 0.5 * self.L + 1e-9
        tol = 1e-9 + 1e-7 * self.R
        if abs(p0 - self.R) < tol and abs(p1 - self.R) < tol and abs(h0) <= hl and abs(h1) <= hl:
            dphi = math.atan2(dot(cross(r0, r1), self.a), dot(r0, r1))
            tphi = cross(self.a, scale(r0, 1.0 / p0))
            return add(scale(tphi, self.R * dphi), scale(self.a, h1 - h0))
        return Shape.geodesic_step(self, q0, q1)

    def arc_length(self, q0: Vec, q1: Vec, steps: int = 64) -> float:
        """Exact on the side (helix on the unrolled cylinder: hypot(R·Δφ, Δh)), else the generic sum."""
        _, _, p0 = self._split(q0)
        _, _, p1 = self._split(q1)
        hl = 0.5 * self.L + 1e-9
        if abs(p0 - self.R) < 1e-9 and abs(p1 - self.R) < 1e-9 and abs(dot(sub(q0, self.c), self.a)) <= hl \
                and abs(dot(sub(q1, self.c), self.a)) <= hl:
            return norm(self.geodesic_step(q0, q1))
        return Shape.arc_length(self, q0, q1, steps)

    def support(self, n: Vec, near: Vec) -> Vec:
        na = dot(n, self.a)
        nr = unit(axpy(-na, self.a, n), 1e-9)
        hl = 0.5 * self.L
        hn, rn, rhon = self._split(near)
        if abs(na) < 1e-9:
            h = max(-hl, min(hl, hn))
        else:
            h = hl if na > 0 else -hl
        if nr is None:     # cap face: nearest point of the cap disc
            rr = scale(rn, min(1.0, self.R / rhon)) if rhon > 0 else (0.0, 0.0, 0.0)
            return add(axpy(h, self.a, self.c), rr)
        return add(axpy(h, self.a, self.c), scale(nr, self.R))


class Sphere(Shape):
    """Sphere: ``center`` (3,) m, ``radius`` m. Skeleton = the centre (singular there)."""

    kind = "sphere"

    def __init__(self, center: Any, radius: float):
        self.c = vec3("center", center)
        self.R = check_positive("radius", radius)

    def closest(self, p: Vec) -> tuple[Vec, Vec, float]:
        d = sub(p, self.c)
        r = norm(d)
        n = scale(d, 1.0 / r) if r > 1e-15 else (1.0, 0.0, 0.0)
        return axpy(self.R, n, self.c), n, r - self.R

    def skeleton_point(self, p: Vec) -> Vec:
        return self.c

    def _ray_exit(self, s: Vec, w: Vec) -> tuple[Vec, Vec]:
        return axpy(self.R, w, self.c), w

    def geodesic_step(self, q0: Vec, q1: Vec) -> Vec:
        """Exact great-circle step: R·ψ along the great circle's start direction."""
        n0 = scale(sub(q0, self.c), 1.0 / self.R)
        n1 = scale(sub(q1, self.c), 1.0 / self.R)
        t = axpy(-dot(n1, n0), n0, n1)
        tl = norm(t)
        if tl < 1e-15:
            return (0.0, 0.0, 0.0)
        psi = math.atan2(tl, dot(n0, n1))
        return scale(t, self.R * psi / tl)

    def support(self, n: Vec, near: Vec) -> Vec:
        return axpy(self.R, n, self.c)


class Plane(Shape):
    """Infinite plane through ``point`` (3,) m with outward unit ``normal`` (3,): the half-space behind it is
    "inside". The centre ray is the orthogonal projection (never singular)."""

    kind = "plane"

    def __init__(self, point: Any, normal: Any):
        self.p0 = vec3("point", point)
        self.n = unit3("normal", normal)

    def closest(self, p: Vec) -> tuple[Vec, Vec, float]:
        d = dot(sub(p, self.p0), self.n)
        return axpy(-d, self.n, p), self.n, d

    def skeleton_point(self, p: Vec) -> Vec:
        return axpy(-(dot(sub(p, self.p0), self.n) + 1.0), self.n, p)   # 1 m behind, under p

    def centre_ray(self, p: Vec, eps: float = 1e-5) -> tuple[Vec, Vec] | None:
        q, n, _ = self.closest(p)
        return q, n

    def geodesic_step(self, q0: Vec, q1: Vec) -> Vec:
        return sub(q1, q0)

    def support(self, n: Vec, near: Vec) -> Vec:
        return self.closest(near)[0]


def _rpy(rpy: Any) -> tuple[Vec, Vec, Vec]:
    r, p, y = vec3("rpy", rpy)
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    # R = Rz(y) Ry(p) Rx(r); return its columns (local x, y, z axes in the display frame)
    return ((cy * cp, sy * cp, -sp), (cy * sp * sr - sy * cr, sy * sp * sr + cy * cr, cp * sr),
            (cy * sp * cr + sy * sr, sy * sp * cr - cy * sr, cp * cr))


class RoundedBox(Shape):
    """Box with rounded edges: ``center`` (3,) m, outer ``half_extents`` (3,) m, edge ``radius`` m
    (0 = sharp), orientation ``rpy`` (roll, pitch, yaw) rad (R = Rz Ry Rx). It is the Minkowski sum of the
    inner box (half_extents − radius) and a ball of ``radius``: closest points are exact and normals are
    continuous outside. The skeleton is the inner box shrunk by ``margin`` (default half the smallest inner
    half-extent) so the centre ray is defined for inside points too."""

    kind = "box"

    def __init__(self, center: Any, half_extents: Any, radius: float = 0.0, rpy: Any = (0.0, 0.0, 0.0),
                 margin: float | None = None):
        self.c = vec3("center", center)
        e = vec3("half_extents", half_extents)
        if min(e) <= 0.0:
            raise ValueError(f"half_extents must be > 0, got {half_extents!r}")
        self.r = check_positive("radius", radius, allow_zero=True)
        if self.r > min(e):
            raise ValueError(f"radius must be <= the smallest half extent {min(e)}, got {radius!r}")
        self.e = e
        self.ei = tuple(x - self.r for x in e)
        self.ax = _rpy(rpy)
        m = 0.5 * min(self.ei) if margin is None else check_positive("margin", margin, allow_zero=True)
        self.es = tuple(max(0.0, x - m) for x in self.ei)

    def _to_local(self, p: Vec) -> Vec:
        d = sub(p, self.c)
        return (dot(d, self.ax[0]), dot(d, self.ax[1]), dot(d, self.ax[2]))

    def _to_world(self, lp: Vec) -> Vec:
        a = self.ax
        return (self.c[0] + a[0][0] * lp[0] + a[1][0] * lp[1] + a[2][0] * lp[2],
                self.c[1] + a[0][1] * lp[0] + a[1][1] * lp[1] + a[2][1] * lp[2],
                self.c[2] + a[0][2] * lp[0] + a[1][2] * lp[1] + a[2][2] * lp[2])

    def _dir_world(self, lp: Vec) -> Vec:
        a = self.ax
        return (a[0][0] * lp[0] + a[1][0] * lp[1] + a[2][0] * lp[2],
                a[0][1] * lp[0] + a[1][1] * lp[1] + a[2][1] * lp[2],
                a[0][2] * lp[0] + a[1][2] * lp[1] + a[2][2] * lp[2])

    def closest(self, p: Vec) -> tuple[Vec, Vec, float]:
        lp = self._to_local(p)
        ei = self.ei
        ci = (max(-ei[0], min(ei[0], lp[0])), max(-ei[1], min(ei[1], lp[1])), max(-ei[2], min(ei[2], lp[2])))
        d = sub(lp, ci)
        dl = norm(d)
        if dl > 1e-12:
            nl = scale(d, 1.0 / dl)
            return self._to_world(axpy(self.r, nl, ci)), self._dir_world(nl), dl - self.r
        # inside the inner box: nearest face of the outer box
        best, i = min((self.e[k] - abs(lp[k]), k) for k in range(3))
        sg = 1.0 if lp[i] >= 0.0 else -1.0
        ql = list(lp)
        ql[i] = sg * self.e[i]
        nl = [0.0, 0.0, 0.0]
        nl[i] = sg
        return self._to_world(tuple(ql)), self._dir_world(tuple(nl)), -best  # type: ignore[arg-type]

    def skeleton_point(self, p: Vec) -> Vec:
        lp = self._to_local(p)
        es = self.es
        return self._to_world((max(-es[0], min(es[0], lp[0])), max(-es[1], min(es[1], lp[1])),
                               max(-es[2], min(es[2], lp[2]))))

    def _ray_exit(self, s: Vec, w: Vec) -> tuple[Vec, Vec]:
        """Exit through the outer slabs, then (edge/corner regions) Newton on the distance to the inner box,
        which is convex along the ray, so the iteration from the slab hit converges monotonically."""
        sl = self._to_local(s)
        wl = (dot(w, self.ax[0]), dot(w, self.ax[1]), dot(w, self.ax[2]))
        t = math.inf
        face = 0
        for k in range(3):
            if abs(wl[k]) > 1e-15:
                tk = ((self.e[k] if wl[k] > 0 else -self.e[k]) - sl[k]) / wl[k]
                if tk < t:
                    t, face = tk, k
        ei = self.ei
        for _ in range(50):
            x = axpy(t, wl, sl)
            ci = (max(-ei[0], min(ei[0], x[0])), max(-ei[1], min(ei[1], x[1])), max(-ei[2], min(ei[2], x[2])))
            dv = sub(x, ci)
            dl = norm(dv)
            if dl <= self.r + 1e-13 or self.r == 0.0:
                break
            nl = scale(dv, 1.0 / dl)
            g = dot(nl, wl)
            if g <= 1e-12:
                break
            t -= (dl - self.r) / g
        x = axpy(t, wl, sl)
        ci = (max(-ei[0], min(ei[0], x[0])), max(-ei[1], min(ei[1], x[1])), max(-ei[2], min(ei[2], x[2])))
        dv = sub(x, ci)
        dl = norm(dv)
        if dl > 1e-12 and self.r > 0.0:
            nl = scale(dv, 1.0 / dl)
        else:   # sharp box (or a face hit): the face normal; an exact edge hit averages the faces
            nl_l = [0.0, 0.0, 0.0]
            for k in range(3):
                if abs(abs(x[k]) - self.e[k]) <= 1e-12 * max(1.0, self.e[k]):
                    nl_l[k] = 1.0 if x[k] > 0 else -1.0
            if not any(nl_l):
                nl_l[face] = 1.0 if wl[face] > 0 else -1.0
            nl = unit(tuple(nl_l))  # type: ignore[arg-type, assignment]
        return self._to_world(x), self._dir_world(nl)

    def support(self, n: Vec, near: Vec) -> Vec:
        nl = (dot(n, self.ax[0]), dot(n, self.ax[1]), dot(n, self.ax[2]))
        ln = self._to_local(near)
        ci = tuple((self.ei[k] if nl[k] > 1e-9 else -self.ei[k]) if abs(nl[k]) > 1e-9
                   else max(-self.ei[k], min(self.ei[k], ln[k])) for k in range(3))
        return self._to_world(axpy(self.r, nl, ci))  # type: ignore[arg-type]


class MeshShape(Shape):
    """Any closed (watertight) triangle mesh, through trimesh (I/O, closest point, containment, rays).

    Build with :meth:`from_file` (STL/OBJ/PLY…, via ``trimesh.load``) or from a ``trimesh.Trimesh``.
    ``translation`` (3,) m and ``scale`` are applied to the vertices. Raises ``ValueError`` if the mesh is
    not watertight (signed distance undefined). Convex meshes use the centre ray to the centroid; others
    use the closest point. Queries cost ~0.1–1 ms (trimesh), far above the analytic shapes.
    """

    kind = "mesh"

    def __init__(self, mesh: Any, translation: Any = (0.0, 0.0, 0.0), scale_: float = 1.0):
        import numpy as np
        import trimesh

        if not isinstance(mesh, trimesh.Trimesh):
            raise ValueError(f"mesh must be a trimesh.Trimesh, got {type(mesh).__name__}")
        if not mesh.is_watertight:
            raise ValueError("mesh must be watertight (closed) for a signed distance")
        m = mesh.copy()
        m.apply_scale(check_positive("scale", scale_))
        m.apply_translation(np.asarray(vec3("translation", translation)))
        self.mesh = m
        self.convex = bool(m.is_convex)
        self.centroid: Vec = tuple(float(x) for x in m.centroid)  # type: ignore[assignment]
        self._pq = trimesh.proximity.ProximityQuery(m)
        self._np = np

    @classmethod
    def from_file(cls, path: str, translation: Any = (0.0, 0.0, 0.0), scale_: float = 1.0) -> MeshShape:
        """Load a mesh file with ``trimesh.load(path, force="mesh")``; raises ``ValueError`` if unreadable."""
        import trimesh

        try:
            mesh = trimesh.load(path, force="mesh")
        except Exception as e:  # trimesh raises assorted errors for bad files
            raise ValueError(f"path: cannot load mesh {path!r}: {e}") from None
        return cls(mesh, translation, scale_)

    def closest(self, p: Vec) -> tuple[Vec, Vec, float]:
        np = self._np
        pts, dist, tri = self._pq.on_surface(np.asarray([p], dtype=float))
        q = tuple(float(x) for x in pts[0])
        d = float(dist[0])
        fn = tuple(float(x) for x in self.mesh.face_normals[int(tri[0])])
        side = dot(sub(p, q), fn)  # type: ignore[arg-type]
        if abs(side) > 0.999 * d and d > 1e-12:     # closest point inside a face: the face normal decides
            inside = side < 0.0
        else:                                       # edge/vertex: ask trimesh (ray parity)
            inside = bool(self.mesh.contains(np.asarray([p], dtype=float))[0])
        if not inside and d > 1e-9:
            n = scale(sub(p, q), 1.0 / d)
        else:
            n = fn
        return q, n, (-d if inside else d)  # type: ignore[return-value]

    def skeleton_point(self, p: Vec) -> Vec:
        return self.centroid

    def _ray_exit(self, s: Vec, w: Vec) -> tuple[Vec, Vec]:
        """One trimesh ray cast from the (interior) centroid; the farthest hit is the exit."""
        np = self._np
        loc, _, tri = self.mesh.ray.intersects_location(np.asarray([s]), np.asarray([w]), multiple_hits=True)
        if len(loc) == 0:
            return super()._ray_exit(s, w)
        k = int(np.argmax((loc - np.asarray(s)) @ np.asarray(w)))
        return (tuple(float(x) for x in loc[k]),  # type: ignore[return-value]
                tuple(float(x) for x in self.mesh.face_normals[int(tri[k])]))

    def support(self, n: Vec, near: Vec) -> Vec:
        v = self.mesh.vertices
        return tuple(float(x) for x in v[int(self._np.argmax(v @ self._np.asarray(n)))])  # type: ignore[return-value]


def paper_cylinder() -> Cylinder:
    """The paper's cylinder (§VI-A) in the display frame: Ø 50√2 mm × 120 mm, axis +y through (−R, 0, 0)."""
    return Cylinder(tuple(geometry.CYLINDER_CENTER), tuple(geometry.CYLINDER_AXIS), geometry.CYLINDER_RADIUS,
                    geometry.CYLINDER_LENGTH)


def make_shape(kind: str, spec: dict[str, Any] | None = None) -> Shape:
    """Build a shape from a launch-file spec. ``kind``: "cylinder" | "sphere" | "box" | "plane" | "mesh".

    Keys (SI units, display frame) — cylinder: center, axis, radius, length, end_margin (defaults: the
    paper's cylinder); sphere: center, radius (default: radius R touching the sheet at the origin);
    box: center, half_extents, radius, rpy, margin (default 60×60×60 mm, radius 5 mm, touching the origin);
    plane: point, normal (default: the home sheet plane x = 0); mesh: path, translation, scale.
    Raises ``ValueError`` naming an unknown kind or key, or a bad value.
    """
    spec = dict(spec or {})
    R = geometry.CYLINDER_RADIUS
    try:
        if kind == "cylinder":
            d = {"center": tuple(geometry.CYLINDER_CENTER), "axis": tuple(geometry.CYLINDER_AXIS),
                 "radius": R,
                 "length": geometry.CYLINDER_LENGTH, "end_margin": None}
            d.update(spec)
            return Cylinder(**d)
        if kind == "sphere":
            d = {"center": (-R, 0.0, 0.0), "radius": R}
            d.update(spec)
            return Sphere(**d)
        if kind == "box":
            d = {"center": (-0.03, 0.0, 0.0), "half_extents": (0.03, 0.03, 0.03), "radius": 0.005,
                 "rpy": (0.0, 0.0, 0.0), "margin": None}
            d.update(spec)
            return RoundedBox(**d)
        if kind == "plane":
            d = {"point": (0.0, 0.0, 0.0), "normal": (1.0, 0.0, 0.0)}
            d.update(spec)
            return Plane(**d)
        if kind == "mesh":
            if "path" not in spec:
                raise ValueError("shape_params.path is required for a mesh shape")
            return MeshShape.from_file(spec["path"], spec.get("translation", (0.0, 0.0, 0.0)),
                                       spec.get("scale", 1.0))
    except TypeError as e:
        raise ValueError(f"shape_params for {kind!r}: {e}") from None
    raise ValueError(f"shape must be one of cylinder, sphere, box, plane, mesh; got {kind!r}")
