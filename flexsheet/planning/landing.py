"""Where the finger will land on the object: its path against the surface (pure).

An encountered-type display must have the surface there before the finger arrives (docs/planner.md), so
before a touch the sheet is commanded to the tangent plane at the predicted landing point, not at the point
nearest the finger: on a curved or edged object the two differ by the finger's travel until contact.
"""

from __future__ import annotations

import math

from flexsheet.model.shape_base import Projection, Shape
from flexsheet.model.vec import Vec, axpy, dot, scale, sub

__all__ = ["FingerPath", "LANDING_STEPS"]

#: Newton steps of the time to contact along the path (3: within 0.1 mm on the scenes' curvatures)
LANDING_STEPS = 3


class FingerPath:
    """The finger's low-passed velocity from its samples, and the landing it predicts.

    ``v`` (3,) m/s in the display frame, or None before two samples (and after :meth:`observe` is given no
    step). Settings come from a :class:`flexsheet.planning.planner_config.PlannerConfig` at each call
    (``velocity_tau``, ``landing_horizon``, ``singular_eps``)."""

    def __init__(self) -> None:
        self.v: Vec | None = None
        self._p: Vec | None = None

    def observe(self, p: Vec, dt: float | None, tau: float = 0.05) -> None:
        """Fuse the sample ``p`` (3,) m taken ``dt`` s after the previous one (None: no usable step, e.g. a
        re-acquired marker: the velocity is forgotten), low-passed with time constant ``tau`` s."""
        prev, self._p = self._p, p
        if dt is None or prev is None or not dt > 0.0:
            self.v = None
            return
        vm = scale(sub(p, prev), 1.0 / dt)
        a = 1.0 - math.exp(-dt / tau)
        self.v = vm if self.v is None else axpy(a, sub(vm, self.v), self.v)

    def landing(self, shape: Shape, p: Vec, proj: Projection, cfg) -> Projection:
        """The landing of the finger at ``p`` (3,) m on ``shape``, ``proj`` its projection there: the projection of
        p + v·τ, τ its time to contact. τ is found by Newton steps along the path, each the distance d (m) to
        the surface over the closing speed c = −v·n (m/s, n the normal of the nearest point), regularised so that
        it stays finite and continuous as c falls to 0 and below: Δτ = d·c / (c² + (d/H)²) for c > 0, else 0
        (→ d/c when the surface is much nearer than H·c), H ``cfg.landing_horizon`` s, τ within [0, H]. Without
        a velocity, moving away or in contact it is ``proj`` itself."""
        v = self.v
        if v is None or proj.distance <= 0.0:
            return proj
        H, eps = cfg.landing_horizon, cfg.singular_eps
        tau, at = 0.0, proj
        for _ in range(LANDING_STEPS):
            c = -dot(v, at.normal)
            if c <= 0.0:
                break
            d = at.distance
            tau = min(H, max(0.0, tau + d * c / (c * c + (d / H) ** 2)))
            at = shape.project(axpy(tau, v, p), at.normal, eps)
        return at if tau > 0.0 else proj
