"""Scripted user's finger for the stroking experiment and the world twin (pure, deterministic given a seed).

The paper's experiment (§V-B): a target mark moves on the cylinder from 0° to 60°; the user follows it
with the fingertip in a given moving time (10 s and 30 s in Table I). We script that finger:

* **Target mark**: angle φ*(t) around the cylinder axis, 0 = facing the user (+x), positive toward
  ``up`` (+z); ``profile`` "linear" (constant angular speed, 0.3 s smoothstep blends at both ends so the
  acceleration is bounded) or "minjerk" (Flash & Hogan, J. Neurosci. 5(7), 1985).
* **Tracking**: the finger follows the mark with a pure delay ``lag`` (visual pursuit of a predictable
  ramp lags by ~0.1 s) plus a slow wander (band 0.1–1 Hz, rms ``wander_deg`` in angle and
  ``wander_axial`` m along the axis) — a human does not trace the mark exactly.
* **Tremor**: physiological tremor, a band-limited 8–12 Hz oscillation on each axis with rms
  ``tremor_rms`` m (default 50 µm). Sources: R. J. Elble, "Physiologic and enhanced physiologic tremor",
  Handbook of Clinical Neurophysiology vol. 1, ch. 22 (2003) — the 8–12 Hz neurogenic component;
  C. N. Riviere et al., IEEE T-RA 19(5) 2003 — hand tremor amplitudes of tens of µm rms in each axis
  during precise tasks. An unsupported, fatigued finger can reach 0.1–0.5 mm; sweep ``tremor_rms``.
* **Depth**: the fingertip sits ``depth`` m inside the virtual surface while stroking (light contact);
  "push" presses to ``push_depth`` and back (raised cosine) at the start angle; "stroke_push" presses
  (half sine) while stroking.

Each noise is a fixed sum of sinusoids drawn from ``seed`` (numpy ``default_rng``), so :meth:`position`
is a smooth deterministic function of time and :meth:`positions` is its vectorised form.

Timeline: [0, approach_time) "approach" from ``approach_distance`` outside the start point; then
``hold_before`` s "idle" on the surface; ``moving_time`` s of "stroke" | "push" | "stroke_push"; then
"idle". Units m, rad, s; display frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from flexsheet.model import scene
from flexsheet.model.checks import check_point, check_positive, check_unit, check_vector

__all__ = ["FingerScript", "MODES"]

MODES = ("stroke", "push", "stroke_push")


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


@dataclass(frozen=True)
class FingerScript:
    """The scripted finger. Fields (SI): ``mode`` ("stroke" | "push" | "stroke_push"), ``moving_time`` s,
    ``start_angle``/``end_angle`` rad, ``profile`` ("linear" | "minjerk"), ``depth`` m (stroking contact
    depth), ``push_depth`` m, ``approach_time`` s, ``approach_distance`` m, ``hold_before``/``hold_after`` s,
    ``lag`` s, ``wander_deg`` deg rms, ``wander_axial`` m rms, ``tremor_rms`` m rms per axis, ``seed``,
    cylinder ``center`` (3,), ``axis`` (3,), ``radius`` m, ``up`` (3,) (direction of positive angles at
    90°). Frozen: the world node's script segments are these fields. Raises ``ValueError`` naming a bad
    field."""

    mode: str = "stroke"
    moving_time: float = 10.0
    start_angle: float = 0.0
    end_angle: float = math.radians(60.0)
    profile: str = "linear"
    depth: float = 0.0005
    push_depth: float = 0.005
    approach_time: float = 1.0
    approach_distance: float = 0.03
    hold_before: float = 1.0
    hold_after: float = 1.0
    lag: float = 0.1
    wander_deg: float = 0.3
    wander_axial: float = 0.0005
    tremor_rms: float = 5e-5
    seed: int = 0
    center: tuple[float, float, float] = tuple(float(x) for x in scene.CYLINDER_CENTER)  # type: ignore[assignment]
    axis: tuple[float, float, float] = tuple(float(x) for x in scene.CYLINDER_AXIS)      # type: ignore[assignment]
    radius: float = scene.CYLINDER_RADIUS
    up: tuple[float, float, float] = (0.0, 0.0, 1.0)

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {self.mode!r}")
        if self.profile not in ("linear", "minjerk"):
            raise ValueError(f"profile must be 'linear' or 'minjerk', got {self.profile!r}")
        for k in ("moving_time", "radius"):
            check_positive(k, getattr(self, k))
        for k in ("depth", "push_depth", "approach_time", "approach_distance", "hold_before", "hold_after", "lag",
                  "wander_deg", "wander_axial", "tremor_rms"):
            check_positive(k, getattr(self, k), allow_zero=True)
        for k in ("start_angle", "end_angle"):
            if not math.isfinite(getattr(self, k)):
                raise ValueError(f"{k} must be finite (rad), got {getattr(self, k)!r}")
        c = check_point("center", self.center)
        a = check_unit("axis", self.axis)
        up = check_vector("up", self.up)
        up = up - (up @ a) * a
        e2 = check_unit("up (orthogonal to axis)", up)
        e1 = np.cross(e2, a) if np.cross(e2, a) @ np.array([1.0, 0, 0]) >= 0 else -np.cross(e2, a)
        rng = np.random.default_rng(self.seed)
        K = 6
        tremor = [(rng.uniform(8.0, 12.0, K), rng.uniform(0, 2 * np.pi, K)) for _ in range(3)]
        wander = [(rng.uniform(0.1, 1.0, K), rng.uniform(0, 2 * np.pi, K)) for _ in range(2)]
        derived = {"_a": a, "_e1": e1, "_e2": e2, "_c": c, "_tremor": tremor, "_wander": wander,
                   "_kamp": math.sqrt(2.0 / K)}   # K sinusoids of amplitude A have rms A·sqrt(K/2)
        for k, v in derived.items():
            object.__setattr__(self, k, v)

    @property
    def t_move(self) -> float:
        """Time the mark starts moving, s (approach + hold before)."""
        return self.approach_time + self.hold_before

    @property
    def duration(self) -> float:
        """Length of the whole script, s."""
        return self.t_move + self.moving_time + self.hold_after

    # ---- script ------------------------------------------------------------------------------------
    def _s(self, t: np.ndarray) -> np.ndarray:
        """Normalised progress of the mark in [0, 1] at times t (s)."""
        x = np.clip((t - self.t_move) / self.moving_time, 0.0, 1.0)
        if self.profile == "minjerk":
            return x ** 3 * (10 - 15 * x + 6 * x * x)
        # linear with smoothstep blends of duration b at both ends (same total time and travel)
        b = min(0.3, 0.25 * self.moving_time) / self.moving_time
        v = 1.0 / (1.0 - b)                        # peak normalised speed
        tt = x
        s = np.where(tt < b, v * (tt ** 3 / b ** 2 - tt ** 4 / (2 * b ** 3)),
                     np.where(tt > 1 - b, 1 - v * ((1 - tt) ** 3 / b ** 2 - (1 - tt) ** 4 / (2 * b ** 3)),
                              v * (tt - b / 2)))
        return s

    def target_angle(self, t):
        """Angle of the target mark, rad (scalar or array like t)."""
        t = np.asarray(t, float)
        if self.mode == "push":
            return np.full_like(t, self.start_angle) if t.ndim else float(self.start_angle)
        a = self.start_angle + (self.end_angle - self.start_angle) * self._s(t)
        return a if t.ndim else float(a)

    def phase(self, t: float) -> str:
        """Script phase at t: "approach", "idle", or the mode while moving."""
        if t < self.approach_time:
            return "approach"
        if self.t_move <= t < self.t_move + self.moving_time:
            return self.mode
        return "idle"

    def _noise(self, t: np.ndarray, comps, rms: float) -> np.ndarray:
        f, ph = comps
        return rms * self._kamp * np.sin(2 * np.pi * f[None, :] * t[:, None] + ph[None, :]).sum(axis=1)

    def _depth(self, t: np.ndarray) -> np.ndarray:
        x = np.clip((t - self.t_move) / self.moving_time, 0.0, 1.0)
        if self.mode == "push":
            return self.depth + (self.push_depth - self.depth) * 0.5 * (1 - np.cos(2 * np.pi * x))
        if self.mode == "stroke_push":
            return self.depth + (self.push_depth - self.depth) * np.sin(np.pi * x)
        return np.full_like(t, self.depth)

    def positions(self, t) -> np.ndarray:
        """Fingertip marker positions (N, 3) m, display frame, at times t (N,) s."""
        t = np.atleast_1d(np.asarray(t, float))
        if not np.all(np.isfinite(t)):
            raise ValueError("t must be finite")
        phi = np.asarray(self.target_angle(t - self.lag), float) + np.radians(self._noise(t, self._wander[0], self.wander_deg))
        h = self._noise(t, self._wander[1], self.wander_axial)
        r = self.radius - self._depth(t)
        ap = np.clip(1.0 - t / self.approach_time, 0.0, 1.0) if self.approach_time > 0 else np.zeros_like(t)
        r = r + self.approach_distance * _smoothstep(ap) if self.approach_time > 0 else r
        radial = np.cos(phi)[:, None] * self._e1[None, :] + np.sin(phi)[:, None] * self._e2[None, :]
        p = self._c[None, :] + h[:, None] * self._a[None, :] + r[:, None] * radial
        trem = np.stack([self._noise(t, c, self.tremor_rms) for c in self._tremor], axis=1)
        return p + trem

    def position(self, t: float) -> np.ndarray:
        """Fingertip marker position (3,) m at time t s."""
        return self.positions(np.array([t]))[0]

    def velocity(self, t: float, h: float = 1e-4) -> np.ndarray:
        """Marker velocity (3,) m/s (central difference of :meth:`position`)."""
        p = self.positions(np.array([t - h, t + h]))
        return (p[1] - p[0]) / (2 * h)

    def angle_of(self, p) -> np.ndarray:
        """Angle(s) around the axis of point(s) p (3,) or (N, 3), rad, same convention as the target."""
        p = np.atleast_2d(np.asarray(p, float)) - self._c
        return np.arctan2(p @ self._e2, p @ self._e1)
