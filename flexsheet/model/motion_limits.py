"""The bounds of the sheet's motion: :class:`MotionLimits` (pure).

One set of limits serves both owners of the sheet's motion: the planner's rate limiter
(:class:`flexsheet.planning.limits.RateLimiter`: speeds and accelerations) and the two arms' one motion
(:class:`flexsheet.arm.sheet_motion.SheetShaper`: those and the jerks that reach full acceleration in
:data:`RAMP_S`, full strain rate in :data:`STRETCH_RAMP_S`). Units: m, rad, s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from flexsheet.model.checks import check_positive

__all__ = ["MotionLimits", "RAMP_S", "STRETCH_RAMP_S"]

#: the time the sheet's centre and orientation take to reach full acceleration, s (sets their jerks)
RAMP_S = 0.005
#: the time the clamp strain takes to reach its full rate, and from there its full acceleration, s: a press's
#: tension must follow the finger (the joints' own limits slow it where they must,
#: :class:`flexsheet.arm.joint_rates.JointRates`)
STRETCH_RAMP_S = 0.01


@dataclass(frozen=True)
class MotionLimits:
    """Bounds on the sheet motion: ``v_max`` m/s, ``a_max`` m/s², ``w_max`` rad/s, ``alpha_max`` rad/s² (sheet
    centre and orientation), ``stretch_rate`` 1/s; the jerks and the strain's acceleration follow from them
    (:attr:`j_max`, :attr:`jw_max`, :attr:`stretch_acc`, :attr:`stretch_jerk`). Defaults are conservative for
    two RV-1A (rated composite speed 2.2 m/s) moving a 0.24 m sheet together; a human stroke is ≲ 0.1 m/s and
    ≲ 1 rad/s. Raises ``ValueError`` naming a bound that is not finite and positive."""

    v_max: float = 0.30
    a_max: float = 3.0
    w_max: float = 3.0
    alpha_max: float = 30.0
    stretch_rate: float = 1.0

    def __post_init__(self) -> None:
        for k in ("v_max", "a_max", "w_max", "alpha_max", "stretch_rate"):
            object.__setattr__(self, k, check_positive(k, getattr(self, k)))

    @property
    def j_max(self) -> float:
        """The centre's jerk, m/s³: full acceleration in :data:`RAMP_S`."""
        return self.a_max / RAMP_S

    @property
    def jw_max(self) -> float:
        """The orientation's jerk, rad/s³: full angular acceleration in :data:`RAMP_S`."""
        return self.alpha_max / RAMP_S

    @property
    def stretch_acc(self) -> float:
        """The strain's acceleration, 1/s²: full strain rate in :data:`STRETCH_RAMP_S`."""
        return self.stretch_rate / STRETCH_RAMP_S

    @property
    def stretch_jerk(self) -> float:
        """The strain's jerk, 1/s³: full strain acceleration in :data:`STRETCH_RAMP_S`."""
        return self.stretch_acc / STRETCH_RAMP_S

    def groups(self) -> np.ndarray:
        """(3, 3): rows velocity, acceleration, jerk; columns centre, orientation, strain."""
        return np.array([[self.v_max, self.w_max, self.stretch_rate],
                         [self.a_max, self.alpha_max, self.stretch_acc],
                         [self.j_max, self.jw_max, self.stretch_jerk]], dtype=float)
