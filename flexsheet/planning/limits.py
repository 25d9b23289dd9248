"""Motion limits the arms can follow, and a cheap reach check against the arm bases (pure).

* :class:`RateLimiter` — second-order (velocity + acceleration bounded) tracking of a pose: translation
  as a 3-vector, orientation on SO(3) through the rotation-vector error (Rodrigues), and the stretch as a
  scalar. Per update the commanded speed toward the target is min(v_max, √(2 a_max e), e/dt) (the
  time-optimal braking curve of a double integrator, e.g. Kröger & Wahl, IEEE T-RO 26(1), 2010, §II),
  then the change of velocity is bounded by a_max·dt. Within the limits it reaches the target in one
  step, so normal stroking passes through unchanged; a jump is ramped.
* :class:`ReachModel` — is a clamp position inside a spherical shell around each arm's shoulder (J2)? Bases
  come from :data:`flexsheet.model.geometry.LEFT_BASE`/``RIGHT_BASE``; J2 is ``shoulder_height`` above the
  base (0.165 + 0.135 m in ``flexsheet/arm/rv1a.urdf``). Default shell 0.32…0.53 m: upper arm 0.250 m
  + forearm 0.184 m + wrist/flange 0.102 m (same URDF) bounds the far side; the near side is where J3
  reaches its 155° limit (the bases in :mod:`flexsheet.model.geometry` were moved out for that reason). This
  is a workspace screen only — the arm bridge does the real IK and joint limits.

Units: m, rad, s. Vectors are float tuples (see :mod:`flexsheet.model.vec`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from flexsheet.model import geometry
from flexsheet.model.motion_limits import MotionLimits
from flexsheet.model.vec import (
    Mat,
    Vec,
    axpy,
    cols,
    cross,
    mat_mul_t,
    matvec,
    norm,
    perp_unit,
    rodrigues,
    rot_from_cols,
    rot_log,
    scale,
    sub,
    unit,
)

__all__ = ["RateLimiter", "LimiterState", "ReachModel", "limit_step"]


def limit_step(err: Vec, vel: Vec, vmax: float, amax: float, dt: float) -> tuple[Vec, Vec, bool]:
    """One limited step toward ``err`` (target − current) from velocity ``vel``; returns (step, new vel,
    limited).

    Desired speed min(vmax, √(2·amax·|err|), |err|/dt) along err, velocity change ≤ amax·dt. ``limited`` is
    True when the step does not land on the target.
    """
    e = norm(err)
    if e > 0.0:
        sp = min(vmax, math.sqrt(2.0 * amax * e), e / dt)
        vd = scale(err, sp / e)
    else:
        vd = (0.0, 0.0, 0.0)
    dv = sub(vd, vel)
    dvn = norm(dv)
    lim = amax * dt
    if dvn > lim:
        dv = scale(dv, lim / dvn)
    v = axpy(1.0, dv, vel)
    step = scale(v, dt)
    limited = norm(sub(step, err)) > 1e-9 + 1e-6 * e
    return step, v, limited


@dataclass(frozen=True, slots=True)
class LimiterState:
    """A :class:`RateLimiter`'s state: ``origin`` (3,) m or None (no pose yet), ``R`` rotation (rows) or None,
    ``stretch``, ``vel`` (3,) m/s, ``omega`` (3,) rad/s (display frame)."""

    origin: Vec | None
    R: Mat | None
    stretch: float
    vel: Vec
    omega: Vec


_ZERO: Vec = (0.0, 0.0, 0.0)


@dataclass
class RateLimiter:
    """Stateful limiter of the sheet pose (origin (3,) m, rotation with columns (normal, u, v)) and stretch.

    ``reset(origin, R, stretch)`` sets the state with zero velocity; ``step(origin, R, stretch, dt)``
    returns the limited (origin, R, stretch, limited); ``clear()`` forgets the pose (the next ``step``
    starts there). ``snapshot()``/``restore(state)`` save and put back the whole state (e.g. to undo a step
    whose result was unreachable). ``vel`` (m/s) and ``omega`` (rad/s, display frame) hold the current rates;
    callers read the state but never assign it.
    """

    limits: MotionLimits = field(default_factory=MotionLimits)
    origin: Vec | None = None
    R: Mat | None = None
    stretch: float = 0.0
    vel: Vec = _ZERO
    omega: Vec = _ZERO

    @property
    def initialised(self) -> bool:
        """True once a pose is set (by :meth:`reset` or a first :meth:`step`)."""
        return self.origin is not None and self.R is not None

    def reset(self, origin: Vec, R: Mat, stretch: float) -> None:
        """Set the state to this pose at rest."""
        self.origin, self.R, self.stretch = origin, R, stretch
        self.vel = _ZERO
        self.omega = _ZERO

    def clear(self) -> None:
        """Forget the pose and the rates (as constructed): the next :meth:`step` starts at its target."""
        self.origin, self.R, self.stretch = None, None, 0.0
        self.vel = _ZERO
        self.omega = _ZERO

    def snapshot(self) -> LimiterState:
        """The current state (immutable)."""
        return LimiterState(self.origin, self.R, self.stretch, self.vel, self.omega)

    def restore(self, state: LimiterState, at_rest: bool = False) -> None:
        """Put back a :meth:`snapshot`; with ``at_rest`` the rates are zeroed (the pose held, not moving)."""
        self.origin, self.R, self.stretch = state.origin, state.R, state.stretch
        self.vel, self.omega = (_ZERO, _ZERO) if at_rest else (state.vel, state.omega)

    def step(self, origin: Vec, R: Mat, stretch: float, dt: float) -> tuple[Vec, Mat, float, bool]:
        """Move toward (origin, R, stretch) within the limits over ``dt`` s (dt > 0)."""
        if not self.initialised:
            self.reset(origin, R, stretch)
            return origin, R, stretch, False
        L = self.limits
        st, self.vel, lim1 = limit_step(sub(origin, self.origin), self.vel, L.v_max, L.a_max, dt)
        o = axpy(1.0, st, self.origin)
        eb = rot_log(mat_mul_t(self.R, R))                 # body-frame error
        ew = matvec(self.R, eb)                            # world frame
        rs, self.omega, lim2 = limit_step(ew, self.omega, L.w_max, L.alpha_max, dt)
        ang = norm(rs)
        c0, c1, _ = cols(self.R)
        if ang > 0.0:
            ax = scale(rs, 1.0 / ang)
            c0 = rodrigues(ax, ang, c0)
            c1 = rodrigues(ax, ang, c1)
        n = unit(c0) or (1.0, 0.0, 0.0)
        u = perp_unit(n, c1)
        Rn = rot_from_cols(n, u, cross(n, u))
        ds = stretch - self.stretch
        mx = L.stretch_rate * dt
        lim3 = abs(ds) > mx + 1e-12
        s = self.stretch + max(-mx, min(mx, ds))
        self.origin, self.R, self.stretch = o, Rn, s
        return o, Rn, s, (lim1 or lim2 or lim3)


@dataclass(frozen=True)
class ReachModel:
    """Spherical-shell workspace of each arm around its shoulder (J2).

    ``left_base``/``right_base``: (x, y, z, yaw) in the display frame (defaults from
    :mod:`flexsheet.model.geometry`); ``shoulder_height`` m above the base; ``reach_min``/``reach_max`` m from
    J2 to the clamp point.
    """

    left_base: tuple[float, float, float, float] = geometry.LEFT_BASE
    right_base: tuple[float, float, float, float] = geometry.RIGHT_BASE
    shoulder_height: float = 0.30
    reach_min: float = 0.32
    reach_max: float = 0.53

    def shoulder(self, arm: str) -> Vec:
        """J2 position (3,) m of ``arm`` ("left" | "right"); raises ``ValueError`` otherwise."""
        if arm not in ("left", "right"):
            raise ValueError(f"arm must be 'left' or 'right', got {arm!r}")
        b = self.left_base if arm == "left" else self.right_base
        return (float(b[0]), float(b[1]), float(b[2]) + self.shoulder_height)

    def margin(self, arm: str, point: Vec) -> float:
        """Signed margin (m) of a clamp point inside the shell: > 0 reachable, < 0 outside by that much."""
        d = norm(sub(point, self.shoulder(arm)))
        return min(self.reach_max - d, d - self.reach_min)

    def reachable(self, left: Vec, right: Vec) -> tuple[bool, float]:
        """Whether both clamp points are inside their shells, and the smaller margin (m)."""
        m = min(self.margin("left", left), self.margin("right", right))
        return m >= 0.0, m
