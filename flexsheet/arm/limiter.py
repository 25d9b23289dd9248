"""Bridge-side streaming limiter: turn a (jumpy, 48 Hz) joint goal into a 7.1 ms command stream that never
asks for more than the position, velocity or acceleration limits (pure numpy).

Per joint, each period ``T`` the command ``c`` moves with velocity ``v`` chosen as the fastest that
(1) does not exceed ``qd_max``, (2) differs from the previous period's velocity by at most ``qdd_max·T``,
(3) can still stop at the goal with deceleration ``qdd_max`` (the exact discrete braking curve, see
``StreamLimiter._brake``), and (4) does not pass the goal in one period. The goal is first clipped into the
joint range shrunk by ``margin``. This is a per-joint time-optimal second-order rate limiter (bang-bang with
braking; see Kröger & Wahl, "Online trajectory generation", IEEE T-RO 26(1), 2010, type-II OTG, for the
general form).

The velocity toward each joint limit is also capped by the braking curve of the distance to that limit,
so the range is never left even when the goal jumps (the goal itself may be overshot when it jumps back
toward the arm faster than the deceleration allows; the stream then returns to it).

Velocity feed-forward: a moving goal (``goal_velocity`` w, rad/s) is tracked by moving with w plus the
braking-limited speed toward it, ``v = w + sign(e)·min(v_brake(|e|), |e|/T)``: once caught up, the command
moves with the goal one period ahead of it instead of braking to a stop at each new goal (a streamed
trajectory through the targets). With w = 0 this is the rate limiter above.

Guarantees (tested): ``|c_k − c_{k−1}| ≤ qd_max·T``, ``|v_k − v_{k−1}| ≤ qdd_max·T`` and ``c_k`` within the
shrunk range, for any goal and goal-velocity sequence.
"""

from __future__ import annotations

import numpy as np

__all__ = ["StreamLimiter"]


class StreamLimiter:
    """Rate/acceleration/position limiter of a 6-joint command stream.

    Parameters
    ----------
    q0 : (6,) rad, the starting command (the measured joints), clipped into the range.
    period : s, stream period T (> 0).
    qd_max, qdd_max : (6,) rad/s and rad/s², > 0.
    q_lower, q_upper : (6,) rad joint limits; ``margin`` rad (≥ 0) is kept from both.

    Raises ``ValueError`` naming the argument on bad shapes, non-finite values or non-positive limits.
    """

    def __init__(self, q0, period: float, qd_max, qdd_max, q_lower, q_upper, margin: float = 0.0) -> None:
        if not (period > 0.0 and np.isfinite(period)):
            raise ValueError(f"period must be > 0 s, got {period!r}")
        arrs = {}
        for name, v in (("q0", q0), ("qd_max", qd_max), ("qdd_max", qdd_max), ("q_lower", q_lower),
                        ("q_upper", q_upper)):
            a = np.asarray(v, dtype=float)
            if a.shape != (6,) or not np.isfinite(a).all():
                raise ValueError(f"{name} must be a finite (6,) vector, got {v!r}")
            arrs[name] = a
        if (arrs["qd_max"] <= 0).any() or (arrs["qdd_max"] <= 0).any():
            raise ValueError("qd_max and qdd_max must be positive")
        if not margin >= 0.0:
            raise ValueError(f"margin must be >= 0 rad, got {margin!r}")
        self.T = float(period)
        self.qd_max = arrs["qd_max"]
        self.qdd_max = arrs["qdd_max"]
        self.lo = arrs["q_lower"] + margin
        self.hi = arrs["q_upper"] - margin
        if (self.lo >= self.hi).any():
            raise ValueError("margin leaves an empty joint range")
        self.c = np.clip(arrs["q0"], self.lo, self.hi)
        self.v = np.zeros(6)

    def reset(self, q) -> None:
        """Restart from joints ``q`` (6,) rad at rest (after a reconnect: q = measured). ``ValueError`` if
        bad."""
        a = np.asarray(q, dtype=float)
        if a.shape != (6,) or not np.isfinite(a).all():
            raise ValueError(f"q must be a finite (6,) vector, got {q!r}")
        self.c = np.clip(a, self.lo, self.hi)
        self.v = np.zeros(6)

    def snapshot(self) -> tuple[np.ndarray, np.ndarray]:
        """The limiter's state ``(c, v)``: copies of the command (6,) rad and its velocity (6,) rad/s."""
        return self.c.copy(), self.v.copy()

    def restore(self, snap: tuple[np.ndarray, np.ndarray]) -> None:
        """Return to a state taken by :meth:`snapshot` (e.g. to redo this period's step toward a newer goal).

        Raises ``ValueError`` if ``snap`` is not two finite (6,) vectors.
        """
        try:
            c, v = (np.array(x, dtype=float) for x in snap)
        except (TypeError, ValueError):
            raise ValueError(f"snapshot must be a (c, v) pair of (6,) vectors, got {snap!r}") from None
        if c.shape != (6,) or v.shape != (6,) or not (np.isfinite(c).all() and np.isfinite(v).all()):
            raise ValueError(f"snapshot must be a (c, v) pair of finite (6,) vectors, got {snap!r}")
        self.c, self.v = c, v

    def _brake(self, dist: np.ndarray) -> np.ndarray:
        """Largest speed from which steps of v, v − aT, v − 2aT, … stop within ``dist`` (exact, discrete).

        With D = dist/(a·T²) and v = (m + f)·a·T (m integer, 0 ≤ f < 1) the distance covered is
        a·T²·(m(m+1)/2 + (m+1)·f); inverting: m = ⌊(√(1+8D) − 1)/2⌋, f = (D − m(m+1)/2)/(m+1).
        One step later the same holds with m − 1, so staying under this curve is always feasible.
        """
        a, T = self.qdd_max, self.T
        D = np.maximum(dist, 0.0) / (a * T * T)
        m = np.floor((np.sqrt(1.0 + 8.0 * D) - 1.0) * 0.5)
        f = np.clip((D - 0.5 * m * (m + 1.0)) / (m + 1.0), 0.0, 1.0)
        return (m + f) * a * T

    def step(self, goal, goal_velocity=None) -> np.ndarray:
        """Advance one period toward ``goal`` (6,) rad moving at ``goal_velocity`` (6,) rad/s (None: at rest);
        returns the new command (6,) rad (a copy). A non-finite goal velocity is taken as 0."""
        lo, hi, qd, c = self.lo, self.hi, self.qd_max, self.c
        g = _clip(np.asarray(goal, dtype=float), lo, hi)
        T, aT = self.T, self.qdd_max * self.T
        if goal_velocity is None:
            w = np.zeros(6)
        else:
            w = np.asarray(goal_velocity, dtype=float)
            if not np.isfinite(w).all():
                w = np.where(np.isfinite(w), w, 0.0)
            w = _clip(w, -qd, qd)
        e = g - c
        ae = np.abs(e)
        # the braking speeds of the distance to the goal, to the lower and to the upper limit, in one pass
        b = self._brake(np.stack((ae, c - lo, hi - c)))
        v_des = _clip(w + np.sign(e) * np.minimum(b[0], ae / T), -qd, qd)
        v = _clip(v_des, self.v - aT, self.v + aT)
        # never faster toward a joint limit than the deceleration can stop before it (feasible by induction)
        v = _clip(_clip(v, -b[1], b[2]), -qd, qd)
        c_new = _clip(c + v * T, lo, hi)
        self.v = (c_new - c) / T
        self.c = c_new
        return c_new.copy()


def _clip(x: np.ndarray, lo, hi) -> np.ndarray:
    """``np.clip`` for the limiter's (6,) vectors (a third of its call's overhead; NaN passes as there)."""
    return np.minimum(np.maximum(x, lo), hi)
