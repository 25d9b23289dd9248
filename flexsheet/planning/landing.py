"""Where the finger will land, and the sheet waiting for it there (pure).

Away from the surface the planner places the sheet under the fingertip's own projection, which learns the
landing point only as the finger arrives: a finger that comes in obliquely has its projection 14° from where
it lands at 5 mm out and 6° at 2 mm (the scripted finger on the paper's cylinder). The application knows the
landing earlier: it shows the user a target mark (the start of a stroke, the mark moving along it) on
``/task/mark`` (:class:`messages.TaskMark`). From the finger's release until it next reaches the object's
surface, :meth:`Landing.place` moves the sheet's target to the landing the mark predicts:

* **Where**: the target normal is the blend n_b = unit((1 − w)·n_f + w·n_m) of the fingertip's projection
  (q_f, n_f) and the mark (q_m, n_m), and the contact the surface point whose normal is n_b near
  (1 − w)·q_f + w·q_m (:meth:`~flexsheet.model.shape_base.Shape.support`): the mark itself at w = 1, the
  fingertip's projection at w = 0. w = smoothstep(d / ``touch_distance``) of the fingertip's signed distance d
  from the surface: the mark until the finger is within ``touch_distance``, its own point where it arrives.
  A finger that lands elsewhere than the mark takes the sheet there only as it arrives.
* **Outside**: the sheet waits ``preposition_offset`` × smoothstep((d − ``touch_distance``) /
  ``preposition_blend``) outside the surface along the normal, so it stands clear of the object while the
  arms still trail the plan, and is on the surface by the time the finger is within ``touch_distance``.
* **Never through the object**: between the sheet's last planned pose and the target the normal turns at
  most ``limits.w_max`` × dt per update, and each intermediate target is the support plane of its normal
  (the surface point with that normal, plus the offset): the sheet rolls around the object, outside it,
  instead of cutting the chord through it. On a convex object a support plane does not cut it; on a
  non-convex one the support is the local one near the last contact.

``use_mark`` turns it on (default off: on the default script it brings the plan to the landing 0.35–0.42 s
earlier, but not the arms' sheet, docs/objects.md). Without it, without a fresh visible mark (older than
``mark_timeout`` s against the fingertip's stamp, or none yet), while the finger touches after its arrival,
or with it inside the object, :meth:`Landing.place` returns the fingertip's projection unchanged: the
planner then behaves as without this module. Units: m, s, rad; display frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from flexsheet.model.vec import Vec, axpy, dot, min_rotation, rodrigues, scale, unit

__all__ = ["Mark", "Landing", "clearance", "smoothstep"]


def smoothstep(x: float) -> float:
    """3x² − 2x³ on x clipped to [0, 1]."""
    x = min(1.0, max(0.0, x))
    return x * x * (3.0 - 2.0 * x)


@dataclass(frozen=True)
class Mark:
    """The application's target mark: ``t`` s (its stamp), ``point`` (3,) m on the object's surface,
    ``normal`` (3,) unit outward normal there; display frame."""

    t: float
    point: Vec
    normal: Vec


class Landing:
    """The sheet's target while the finger is away (module doc). ``shape``: the planner's shape;
    ``cfg``: its :class:`~flexsheet.planning.planner_config.PlannerConfig` (``touch_distance``,
    ``preposition_offset``, ``preposition_blend``, ``mark_timeout``, ``limits.w_max``)."""

    def __init__(self, shape, cfg) -> None:
        self.shape, self.cfg = shape, cfg
        self.mark: Mark | None = None
        #: between the finger's release and its next arrival at the surface (:meth:`place`)
        self.landing = True

    def set_mark(self, t: float, point, normal, visible: bool = True) -> None:
        """The mark shown at ``t`` s: ``point`` (3,) m, ``normal`` (3,) (normalised here); ``visible`` False
        (no mark shown) forgets it. Raises ``ValueError`` for a non-finite stamp, point or a zero normal."""
        if not visible:
            self.mark = None
            return
        p = tuple(float(x) for x in point)
        nv = tuple(float(x) for x in normal)
        if len(p) != 3 or len(nv) != 3 or not all(math.isfinite(x) for x in (t, *p, *nv)):
            raise ValueError(f"mark: stamp, point and normal must be finite (3,), got {t!r}, {p!r}, {nv!r}")
        nu = unit(nv, 1e-9)
        if nu is None:
            raise ValueError(f"mark: the normal must be non-zero, got {nv!r}")
        self.mark = Mark(float(t), p, nu)   # type: ignore[arg-type]

    def weight(self, dist: float) -> float:
        """The mark's weight at the fingertip's signed distance ``dist`` m from the surface: 0 on or in it, 1
        from ``touch_distance`` on."""
        return smoothstep(dist / self.cfg.touch_distance)

    def lift_share(self, dist: float) -> float:
        """The share of ``preposition_offset`` the sheet waits outside at ``dist`` m: 0 within
        ``touch_distance``, 1 from ``touch_distance + preposition_blend`` on."""
        c = self.cfg
        return smoothstep((dist - c.touch_distance) / c.preposition_blend)

    def fresh(self, t: float) -> Mark | None:
        """The mark, with ``use_mark``, one shown and its stamp within ``mark_timeout`` s of ``t`` s; else
        None."""
        m = self.mark
        if m is None or not self.cfg.use_mark or abs(t - m.t) > self.cfg.mark_timeout:
            return None
        return m

    def place(self, t: float, dt: float | None, dist: float, q: Vec, n: Vec, last: tuple[Vec, Vec] | None,
              touching: bool = False) -> tuple[Vec, Vec, float]:
        """(contact (3,) m, normal (3,), lift m along it) of the sheet's target for a fingertip at signed
        distance ``dist`` m whose projection is (``q``, ``n``), at ``t`` s, ``dt`` s after the last sample
        (None: the first; no turn limit); ``last``: the last plan's (contact, normal), or None; ``touching``:
        the planner's touch state after this sample. Between the finger's release (not ``touching``) and its
        arrival at the surface (``dist`` ≤ 0) the target is the mark's landing (module doc); otherwise, or
        without a fresh mark, (``q``, ``n``, 0) unchanged."""
        if not touching:
            self.landing = True
        elif dist <= 0.0:
            self.landing = False
        m = self.fresh(t) if self.landing else None
        w = self.weight(dist) if m is not None else 0.0
        if m is None or w <= 0.0:
            return q, n, 0.0
        nb = unit(axpy(w, m.normal, scale(n, 1.0 - w)), 1e-9) or m.normal
        near = axpy(w, m.point, scale(q, 1.0 - w))
        lift = self.cfg.preposition_offset * self.lift_share(dist)
        step = None if dt is None else self.cfg.limits.w_max * dt
        if last is not None and step is not None:
            q0, n0 = last
            r = min_rotation(n0, nb)
            if r is not None and r[1] > step:           # turn toward it around the object, not through it
                ni = unit(rodrigues(r[0], step, n0), 1e-9) or nb
                return self._support(ni, q0), ni, lift
        if w >= 1.0:
            return m.point, m.normal, lift
        return self._support(nb, near), nb, lift

    def _support(self, n: Vec, near: Vec) -> Vec:
        """The surface point whose outward normal is ``n`` near ``near`` (the shape's support point)."""
        return tuple(float(x) for x in self.shape.support(n, near))    # type: ignore[return-value]


def clearance(shape, origin: Vec, normal: Vec, near: Vec) -> float:
    """m: how far the plane through ``origin`` (3,) m with unit ``normal`` stands outside ``shape`` (negative:
    the object pierces it by that much), at its support point near ``near``."""
    s = shape.support(normal, near)
    return dot(normal, origin) - dot(normal, s)
