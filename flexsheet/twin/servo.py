"""Joint servo model of the controller twin: a position-controlled industrial arm (pure numpy).

Model (per joint, discrete time, period ``dt``): the drive asks for the velocity of a first-order lag
toward the active target, ``v_des = (q_target − q) / tau``, clipped to ±``qd_max``; the velocity may change by
at most ``qdd_max · dt`` per period; then ``q += v · dt``. This is the usual "P position loop with
rate and acceleration saturation" reduction of a stiff industrial servo (Siciliano et al., *Robotics*,
§8.3; Spong, Hutchinson & Vidyasagar, *Robot Modeling and Control*, §6.3). It tracks a ramp with a lag of
``tau · v`` and a step with at most ``qd_max`` speed.

Parameters (all ASSUMED for the RV-1A; stated so they can be tuned to a measured arm):
``tau`` = 0.015 s (position-loop time constant), ``qd_max`` = the URDF speed limits, ``qdd_max`` = 4 × those
per second (reach full speed in 0.25 s).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from flexsheet.arm.kinematics import Q_LOWER, Q_UPPER, QD_MAX

__all__ = ["ServoParams", "JointServo"]


@dataclass(frozen=True)
class ServoParams:
    """Servo parameters. ``tau`` s (> 0); ``qd_max`` (6,) rad/s; ``qdd_max`` (6,) rad/s²;
    ``q_lower``/``q_upper`` (6,) rad, hard stops the model never passes."""

    tau: float = 0.015
    qd_max: np.ndarray = field(default_factory=lambda: QD_MAX.copy())
    qdd_max: np.ndarray = field(default_factory=lambda: 4.0 * QD_MAX)
    q_lower: np.ndarray = field(default_factory=lambda: Q_LOWER.copy())
    q_upper: np.ndarray = field(default_factory=lambda: Q_UPPER.copy())

    def __post_init__(self) -> None:
        if not (self.tau > 0.0 and np.isfinite(self.tau)):
            raise ValueError(f"tau must be a positive time constant in s, got {self.tau!r}")
        for name in ("qd_max", "qdd_max", "q_lower", "q_upper"):
            a = np.asarray(getattr(self, name), dtype=float)
            if a.shape != (6,) or not np.all(np.isfinite(a)):
                raise ValueError(f"{name} must be a finite (6,) vector, got {a!r}")
            object.__setattr__(self, name, a)
        if np.any(self.qd_max <= 0) or np.any(self.qdd_max <= 0):
            raise ValueError("qd_max and qdd_max must be positive")


class JointServo:
    """State (q, v) of six joints driven by :class:`ServoParams`; :meth:`step` advances one period.

    ``q0``: (6,) rad initial joints (clipped to the limits). Raises ``ValueError`` on a bad ``q0``.
    """

    def __init__(self, q0, params: ServoParams | None = None) -> None:
        self.p = params or ServoParams()
        q = np.asarray(q0, dtype=float)
        if q.shape != (6,) or not np.all(np.isfinite(q)):
            raise ValueError(f"q0 must be a finite (6,) vector in rad, got {q0!r}")
        self.q = np.clip(q, self.p.q_lower, self.p.q_upper)
        self.v = np.zeros(6)

    def step(self, q_target: np.ndarray, dt: float) -> None:
        """Advance by ``dt`` s toward ``q_target`` (6,) rad (clipped to the limits). Updates ``q``, ``v``."""
        p = self.p
        goal = np.clip(q_target, p.q_lower, p.q_upper)
        v_des = np.clip((goal - self.q) / p.tau, -p.qd_max, p.qd_max)
        # brake in time: never faster than what the acceleration limit can stop before the goal
        v_stop = np.sqrt(2.0 * p.qdd_max * np.abs(goal - self.q))
        v_des = np.clip(v_des, -v_stop, v_stop)
        dv = np.clip(v_des - self.v, -p.qdd_max * dt, p.qdd_max * dt)
        self.v = self.v + dv
        q_new = self.q + self.v * dt
        hit = (q_new < p.q_lower) | (q_new > p.q_upper)
        self.q = np.clip(q_new, p.q_lower, p.q_upper)
        self.v[hit] = 0.0
