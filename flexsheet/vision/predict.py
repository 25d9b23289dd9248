"""Constant-velocity Kalman filter of the fingertip, for gating and for predicting ahead of loop delay.

State x = (p, v) (6,): position m and velocity m/s in one frame (the triangulator uses the display frame).
Model (Bar-Shalom, Li & Kirubarajan, *Estimation with Applications to Tracking and Navigation*, §6.2.2,
"continuous white-noise acceleration"): p' = p + v dt, v' = v, process noise spectral density ``q``
(m²/s³) per axis, giving Q = q [[dt³/3 I, dt²/2 I], [dt²/2 I, dt I]]. Measurement z = p + w, w ~ N(0, R)
with R the triangulation covariance (m²).
"""

from __future__ import annotations

import math

import numpy as np

from flexsheet.model.checks import check_point

__all__ = ["ConstantVelocityKF", "Predictor", "q_for_tracking_index"]


class ConstantVelocityKF:
    """3-D constant-velocity Kalman filter (module doc).

    ``q``: acceleration noise spectral density, m²/s³ (> 0; default 2.0 ≈ a finger's ±1.4 m/s² jerkiness
    over 1 s); ``v0_std``: prior velocity std, m/s, at (re)initialisation.
    Raises ``ValueError`` for non-positive parameters.
    """

    def __init__(self, q: float = 2.0, v0_std: float = 0.5):
        if not (q > 0 and np.isfinite(q)):
            raise ValueError(f"q must be positive and finite (m^2/s^3), got {q!r}")
        if not (v0_std > 0 and np.isfinite(v0_std)):
            raise ValueError(f"v0_std must be positive and finite (m/s), got {v0_std!r}")
        self.q = float(q)
        self.v0_std = float(v0_std)
        self.x = np.zeros(6)
        self.P = np.eye(6)
        self.t: float | None = None

    @property
    def initialised(self) -> bool:
        """True once a measurement has been taken since construction or :meth:`reset`."""
        return self.t is not None

    def reset(self) -> None:
        """Forget the track (the next :meth:`update` re-initialises)."""
        self.t = None

    def _FQ(self, dt: float, q: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        F = np.eye(6)
        F[:3, 3:] = dt * np.eye(3)
        q = self.q if q is None else q
        Q = np.zeros((6, 6))
        Q[:3, :3] = q * dt ** 3 / 3 * np.eye(3)
        Q[:3, 3:] = Q[3:, :3] = q * dt ** 2 / 2 * np.eye(3)
        Q[3:, 3:] = q * dt * np.eye(3)
        return F, Q

    def predicted(self, t: float, q: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Predicted state (6,) and covariance (6, 6) at time ``t`` (s) without changing the filter, with
        process noise ``q`` m²/s³ for this step (None: the filter's). Raises ``ValueError`` if not
        initialised."""
        if self.t is None:
            raise ValueError("filter not initialised: call update() first")
        dt = max(0.0, float(t) - self.t)
        F, Q = self._FQ(dt, q)
        return F @ self.x, F @ self.P @ F.T + Q

    def mahalanobis2(self, z: np.ndarray, R: np.ndarray, t: float, q: float | None = None) -> float:
        """Squared Mahalanobis distance of measurement z (3,) m with covariance R (3, 3) m² from the
        prediction at ``t`` (s) under process noise ``q`` m²/s³ (None: the filter's); χ²(3) distributed for
        consistent data. Raises ``ValueError`` if not initialised."""
        x, P = self.predicted(t, q)
        S = P[:3, :3] + R
        d = np.asarray(z, float) - x[:3]
        return float(d @ np.linalg.solve(S, d))

    def update(self, z: np.ndarray, R: np.ndarray, t: float, q: float | None = None) -> None:
        """Predict to ``t`` (s) with process noise ``q`` m²/s³ for this step (None: the filter's) and fuse
        measurement z (3,) m with covariance R (3, 3) m² (initialises on the first call). Raises
        ``ValueError`` on non-finite input."""
        z = check_point("z", z)
        R = np.asarray(R, float)
        if R.shape != (3, 3) or not np.all(np.isfinite(R)):
            raise ValueError(f"R must be a finite (3, 3) covariance, got {R!r}")
        if self.t is None:
            self.x = np.concatenate([z, np.zeros(3)])
            self.P = np.zeros((6, 6))
            self.P[:3, :3] = R
            self.P[3:, 3:] = self.v0_std ** 2 * np.eye(3)
            self.t = float(t)
            return
        x, P = self.predicted(t, q)
        S = P[:3, :3] + R
        K = np.linalg.solve(S, P[:3, :]).T          # P Hᵀ S⁻¹ (6, 3)
        self.x = x + K @ (z - x[:3])
        self.P = P - K @ P[:3, :]
        self.P = 0.5 * (self.P + self.P.T)
        self.t = max(self.t, float(t))

    def position_at(self, t: float) -> np.ndarray:
        """Predicted position (3,) m at time ``t`` (s) (e.g. the last update time + horizon)."""
        return self.predicted(t)[0][:3]

    @property
    def velocity(self) -> np.ndarray:
        """Current velocity estimate (3,) m/s."""
        return self.x[3:].copy()


def q_for_tracking_index(tracking_index: float, sigma_m: float, period: float) -> float:
    """Process noise q (m²/s³) of the continuous white-noise-acceleration model for tracking index
    λ = √(q T³)/σ_m, i.e. q = (λ σ_m)² / T³, from ``sigma_m`` (m) and ``period`` T (s). Its steady-state
    Kalman filter is the α-β filter of Kalata's index λ. Raises ``ValueError`` for non-positive inputs."""
    for name, v in (("tracking_index", tracking_index), ("sigma_m", sigma_m), ("period", period)):
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"{name} must be finite and > 0, got {v!r}")
    return (tracking_index * sigma_m) ** 2 / period ** 3


class Predictor:
    """The triangulator's fingertip prediction, in-process: :class:`ConstantVelocityKF` updated with each
    measurement z (3,) m and its covariance R (3, 3) m², predicting ``position_at(t + h)`` as
    :class:`flexsheet.vision.tracker.FingertipTracker` does. ``q`` m²/s³; ``v0_std`` m/s (the tracker's is
    ``TrackerConfig.v0_std``). Raises ``ValueError`` for a non-positive ``q`` or ``v0_std``."""

    def __init__(self, q: float, v0_std: float = 1.0):
        self.kf = ConstantVelocityKF(q=q, v0_std=v0_std)
        self.t = 0.0

    def update(self, t: float, z: np.ndarray, R: np.ndarray) -> None:
        """Fuse the measurement z (3,) m with covariance R (3, 3) m² taken at ``t`` s."""
        self.kf.update(z, R, t)
        self.t = t

    def predict(self, h: float) -> np.ndarray:
        """Position (3,) m ``h`` s after the last measurement."""
        return self.kf.position_at(self.t + h)
