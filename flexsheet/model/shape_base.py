"""The interface every virtual shape implements (:class:`Shape`) and the result of placing the sheet on it
(:class:`Projection`); the shapes themselves are in :mod:`flexsheet.model.shapes`, whose docstring states the
placement rule. Frame ``display``, m (pure)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from flexsheet.model.checks import check_point, check_unit
from flexsheet.model.vec import Vec, axpy, dot, norm, scale, sub, unit

__all__ = ["Projection", "Shape", "vec3", "unit3"]


@dataclass(frozen=True, slots=True)
class Projection:
    """Result of projecting a fingertip onto a shape.

    ``point`` (3,) m: surface point; ``normal`` (3,): unit outward normal there; ``distance`` m: signed
    distance of the fingertip from the surface along the projection (< 0 inside, i.e. pushing);
    ``singular``: the projection direction was undefined (fingertip on the skeleton) and ``hint`` was used.
    """

    point: Vec
    normal: Vec
    distance: float
    singular: bool = False


def vec3(name: str, v: Any) -> Vec:
    """:func:`flexsheet.model.checks.check_point` as a float tuple (the shapes' vector type)."""
    return tuple(check_point(name, v).tolist())  # type: ignore[return-value]


def unit3(name: str, v: Any) -> Vec:
    """:func:`flexsheet.model.checks.check_unit` (normalised, non-zero) as a float tuple."""
    return tuple(check_unit(name, v).tolist())  # type: ignore[return-value]


class Shape:
    """Base class: a closed surface in the display frame. Subclasses implement the geometry.

    ``convex``: whether the centre-ray rule applies (else the closest point is used).
    """

    kind = "shape"
    convex = True

    # ---- geometry every shape provides -------------------------------------------------------------
    def closest(self, p: Vec) -> tuple[Vec, Vec, float]:
        """Closest surface point q (3,) m, outward unit normal n (3,), signed distance (m, < 0 inside)."""
        raise NotImplementedError

    def signed_distance(self, p: Vec) -> float:
        """Signed distance of p (3,) m to the surface, m (negative inside)."""
        return self.closest(p)[2]

    def skeleton_point(self, p: Vec) -> Vec:
        """Point of the shape's centre skeleton nearest p (the generalised centre O of §V-A)."""
        raise NotImplementedError

    def centre_ray(self, p: Vec, eps: float = 1e-5) -> tuple[Vec, Vec] | None:
        """Surface point and normal where the ray from the skeleton point O(p) through p leaves the shape.

        Paper §V-A, Fig. 7(a). Returns ``None`` when |p − O(p)| < ``eps`` m (direction undefined).
        """
        s = self.skeleton_point(p)
        w = unit(sub(p, s), eps)
        if w is None:
            return None
        return self._ray_exit(s, w)

    def _ray_exit(self, s: Vec, w: Vec) -> tuple[Vec, Vec]:
        """Exit point of the ray s + t·w (s inside, w unit) by safeguarded Newton on the signed distance."""
        lo, hi = 0.0, 1e-3
        while self.signed_distance(axpy(hi, w, s)) < 0.0:
            lo, hi = hi, hi * 2.0
            if hi > 1e3:
                raise ValueError(f"ray from {s!r} along {w!r} never leaves the shape")
        t = hi
        for _ in range(40):
            q, n, d = self.closest(axpy(t, w, s))
            if abs(d) < 1e-10:
                break
            if d < 0.0:
                lo = t
            else:
                hi = t
            g = dot(n, w)
            tn = t - d / g if g > 0.1 else 0.5 * (lo + hi)
            t = tn if lo < tn < hi else 0.5 * (lo + hi)
            if hi - lo < 1e-10:
                break
        q, n, _ = self.closest(axpy(t, w, s))
        return q, n

    def project(self, p: Vec, hint: Vec | None = None, eps: float = 1e-4) -> Projection:
        """Contact point for fingertip p (3,) m: centre ray for convex shapes, else closest point.

        ``hint`` (3,) unit: direction to use where the ray is undefined (fingertip within ``eps`` m of the
        skeleton): the last good normal. Then the result has ``singular=True``. Distance is signed
        (negative when the fingertip is inside, i.e. pushing).
        """
        if not self.convex:
            q, n, d = self.closest(p)
            return Projection(q, n, d)
        r = self.centre_ray(p, eps)
        if r is None:
            s = self.skeleton_point(p)
            h = hint if hint is not None else self.default_direction(p)
            q, n = self._ray_exit(s, h)
            return Projection(q, n, dot(sub(p, q), n), True)
        q, n = r
        return Projection(q, n, dot(sub(p, q), n))

    def default_direction(self, p: Vec) -> Vec:
        """Direction used at a singular point with no hint: toward the user (+x display)."""
        return (1.0, 0.0, 0.0)

    def normal_at(self, q: Vec) -> Vec:
        """Outward unit normal at (or near) surface point q."""
        return self.closest(q)[1]

    def geodesic_step(self, q0: Vec, q1: Vec) -> Vec:
        """Tangent vector at q0 (3,) whose length is the arc (geodesic) length q0→q1 and direction its start.

        Default: the chord projected onto the tangent plane at q0, rescaled to the chord length (exact to
        second order in the step; the planner calls it with steps of ≲ 1 mm).
        """
        n = self.normal_at(q0)
        c = sub(q1, q0)
        t = axpy(-dot(c, n), n, c)
        tl = norm(t)
        if tl < 1e-15:
            return (0.0, 0.0, 0.0)
        return scale(t, norm(c) / tl)

    def arc_length(self, q0: Vec, q1: Vec, steps: int = 64) -> float:
        """Surface (geodesic) length between surface points q0 and q1, m: exact for sphere/cylinder
        side/plane, else the length of the straight chord's projection onto the surface in ``steps``
        pieces."""
        total = 0.0
        prev = q0
        for i in range(1, steps + 1):
            t = i / steps
            x = axpy(t, sub(q1, q0), q0)
            q = self.closest(x)[0]
            total += norm(self.geodesic_step(prev, q))
            prev = q
        return total

    def support(self, n: Vec, near: Vec) -> Vec:
        """Surface point where a plane with outward normal n touches the shape (support point); ties
        (flat faces) are broken by the point nearest ``near``. Used to find the contact the sheet presents."""
        raise NotImplementedError
