"""The pose path's fingertip filter: a low-pass with a velocity lead, so the finger's tremor does not turn the
sheet while the slow stroke is not delayed (pure).

The planner forms the sheet's orientation and contact point from the fingertip; the finger's physiological
tremor (8–12 Hz, tens of µm) reaches the sheet there, and behind the loop's delay the sheet moves against it.
:class:`PoseFilter` gives the pose path ``y = LP₂(p) + L·V₃(p)``:

* ``LP₂``: two cascaded first-order low-passes at ``cutoff`` Hz (critically damped, −40 dB/decade);
* ``V₃``: the sample-to-sample velocity (p_k − p_{k−1})/dt through three first-order low-passes at
  ``velocity_cutoff`` Hz (the velocity the lead needs, with the tremor's derivative filtered out);
* ``L``: the exact steady-state ramp lag of ``LP₂`` at this step's dt, 2·dt·e^(−dt/τ)/(1 − e^(−dt/τ))
  (τ = 1/(2π·``cutoff``)), so a stroke at constant velocity comes out with no lag and no static offset (a
  constant input, too). What remains is a transient while the velocity changes (the acceleration through
  ``V₃``'s lag).

At 48 Hz, ``cutoff`` 3 Hz, ``velocity_cutoff`` 3 Hz, ``tests/unit/planning/test_pose_filter.py`` bounds
the 10 Hz gain below 0.3 and the error on a 0.5 Hz motion below 7 %. The stretch path (the push depth) does
not pass through it: the planner takes the depth from the raw sample along the filtered normal, and uses the
filter only while the finger touches (``surface_planner``).

Units: m, s, Hz; vectors are float tuples (3,).
"""

from __future__ import annotations

import math

from flexsheet.model.vec import Vec

__all__ = ["POSE_STAGES", "VELOCITY_STAGES", "PoseFilter"]

#: first-order stages of the position low-pass
POSE_STAGES = 2
#: first-order stages of the velocity's low-pass
VELOCITY_STAGES = 3


class PoseFilter:
    """Low-pass with a velocity lead for the fingertip of the pose path (module doc). ``cutoff`` Hz: the
    position's corner (0: off, :meth:`step` returns its input); ``velocity_cutoff`` Hz: the velocity's corner
    (> 0 when ``cutoff`` is). Raises ``ValueError`` for a negative, non-finite or missing corner."""

    def __init__(self, cutoff: float, velocity_cutoff: float):
        if not (math.isfinite(cutoff) and cutoff >= 0.0):
            raise ValueError(f"cutoff must be finite and >= 0 Hz, got {cutoff!r}")
        if cutoff > 0.0 and not (math.isfinite(velocity_cutoff) and velocity_cutoff > 0.0):
            raise ValueError(f"velocity_cutoff must be finite and > 0 Hz, got {velocity_cutoff!r}")
        self.cutoff = float(cutoff)
        self.velocity_cutoff = float(velocity_cutoff)
        self.reset()

    @property
    def enabled(self) -> bool:
        """Whether the filter acts (``cutoff`` > 0)."""
        return self.cutoff > 0.0

    def reset(self) -> None:
        """Forget the state: the next :meth:`step` starts at its sample, at rest."""
        self._x: list[Vec] = []
        self._v: list[Vec] = []
        self._prev: Vec | None = None

    def step(self, p: Vec, dt: float | None) -> Vec:
        """The filtered position (3,) m for sample ``p`` (3,) m taken ``dt`` s after the last one (None or
        ≤ 0: start again at ``p``)."""
        if not self.enabled:
            return p
        if dt is None or not dt > 0.0 or self._prev is None:
            self._x = [p] * POSE_STAGES
            self._v = [(0.0, 0.0, 0.0)] * VELOCITY_STAGES
            self._prev = p
            return p
        e = math.exp(-2.0 * math.pi * self.cutoff * dt)
        a = 1.0 - e
        u = p
        for i in range(POSE_STAGES):
            x = self._x[i]
            u = (x[0] + a * (u[0] - x[0]), x[1] + a * (u[1] - x[1]), x[2] + a * (u[2] - x[2]))
            self._x[i] = u
        b = 1.0 - math.exp(-2.0 * math.pi * self.velocity_cutoff * dt)
        q = self._prev
        w = ((p[0] - q[0]) / dt, (p[1] - q[1]) / dt, (p[2] - q[2]) / dt)
        for i in range(VELOCITY_STAGES):
            v = self._v[i]
            w = (v[0] + b * (w[0] - v[0]), v[1] + b * (w[1] - v[1]), v[2] + b * (w[2] - v[2]))
            self._v[i] = w
        self._prev = p
        lag = POSE_STAGES * dt * e / a
        return (u[0] + lag * w[0], u[1] + lag * w[1], u[2] + lag * w[2])
