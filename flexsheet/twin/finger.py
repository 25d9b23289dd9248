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
* **Any scene**: with ``scene`` (a :class:`flexsheet.model.scenes.Scene`) the mark moves along the
  scene's stroke path instead (:meth:`~flexsheet.model.scenes.Scene.stroke_at`): the profile runs over the
  path's arc-length fraction 0 → 1 and the fingertip goes to p − depth·n (p the path point, n its outward
  normal; the approach comes in along n). The angular wander becomes an along-path wander of
  ``radius``·``wander_deg`` (rad) and the axial wander runs along b = t × n (t the path's direction), so
  the paper's cylinder scene gives the same finger as the cylinder parameters (tested to 1e-9 m).
  ``start_angle``, ``end_angle``, ``center``, ``axis`` and ``up`` are not used then.

Each noise is a fixed sum of sinusoids drawn from ``seed`` (numpy ``default_rng``), so :meth:`position`
is a smooth deterministic function of time and :meth:`positions` is its vectorised form.

Timeline: [0, approach_time) "approach" from ``approach_distance`` outside the start point (after another
segment: from where that one ended, lifted off, :func:`after`); then
``hold_before`` s "idle" on the surface; ``moving_time`` s of "stroke" | "push" | "stroke_push"; then
"idle". Units m, rad, s; display frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from flexsheet.model import geometry
from flexsheet.model.checks import check_point, check_positive, check_unit, check_vector

__all__ = ["FingerScript", "MODES", "after"]

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
    90°); ``scene``: a :class:`flexsheet.model.scenes.Scene` whose stroke path the finger follows (module
    doc; ``None``: the cylinder parameters). Frozen: the world node's script segments are these fields (but
    ``scene``, a graph-wide setting). Raises ``ValueError`` naming a bad field."""

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
    center: tuple[float, float, float] = tuple(float(x) for x in geometry.CYLINDER_CENTER)  # type: ignore[assignment]
    axis: tuple[float, float, float] = tuple(float(x) for x in geometry.CYLINDER_AXIS)      # type: ignore[assignment]
    radius: float = geometry.CYLINDER_RADIUS
    up: tuple[float, float, float] = (0.0, 0.0, 1.0)
    scene: Any = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {self.mode!r}")
        if self.profile not in ("linear", "minjerk"):
            raise ValueError(f"profile must be 'linear' or 'minjerk', got {self.profile!r}")
        for k in ("moving_time", "radius"):
            check_positive(k, getattr(self, k))
        for k in ("depth", "push_depth", "approach_time", "approach_distance", "hold_before", "hold_after",
                  "lag",
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
                   "_kamp": math.sqrt(2.0 / K),   # K sinusoids of amplitude A have rms A·sqrt(K/2)
                   "_path": None if self.scene is None else _path_table(self.scene)}
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

    def target_fraction(self, t):
        """Fraction 0 → 1 of the mark's way (of the angle range, or of a scene's path length) at t (scalar or
        array like t); 0 throughout a push."""
        t = np.asarray(t, float)
        f = np.zeros_like(t) if self.mode == "push" else self._s(t)
        return f if t.ndim else float(f)

    def target_angle(self, t):
        """Angle of the target mark, rad (scalar or array like t). With a scene: the angle on an arc stroke
        (``start_deg`` … ``end_deg``), 0 on a polyline stroke (see :meth:`target_fraction`)."""
        t = np.asarray(t, float)
        f = self.target_fraction(t)
        if self._path is not None:
            a0, a1 = self._path["angles"]
            a = a0 + (a1 - a0) * f
        else:
            a = self.start_angle + (self.end_angle - self.start_angle) * f
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
        if self._path is not None:
            return self._scene_positions(t)
        phi = (np.asarray(self.target_angle(t - self.lag), float)
               + np.radians(self._noise(t, self._wander[0], self.wander_deg)))
        h = self._noise(t, self._wander[1], self.wander_axial)
        r = self.radius - self._depth(t)
        ap = np.clip(1.0 - t / self.approach_time, 0.0, 1.0) if self.approach_time > 0 else np.zeros_like(t)
        r = r + self.approach_distance * _smoothstep(ap) if self.approach_time > 0 else r
        radial = np.cos(phi)[:, None] * self._e1[None, :] + np.sin(phi)[:, None] * self._e2[None, :]
        p = self._c[None, :] + h[:, None] * self._a[None, :] + r[:, None] * radial
        trem = np.stack([self._noise(t, c, self.tremor_rms) for c in self._tremor], axis=1)
        return p + trem

    def _scene_positions(self, t: np.ndarray) -> np.ndarray:
        """:meth:`positions` along the scene's stroke path (module doc)."""
        tab = self._path
        L = tab["length"]
        arc = np.asarray(self.target_fraction(t - self.lag), float) * L \
            + self.radius * np.radians(self._noise(t, self._wander[0], self.wander_deg))
        q, n, tang = _path_at(tab, arc)
        b = np.cross(tang, n)
        b /= np.linalg.norm(b, axis=1, keepdims=True)
        h = self._noise(t, self._wander[1], self.wander_axial)
        off = -self._depth(t)
        if self.approach_time > 0:
            off = off + self.approach_distance * _smoothstep(np.clip(1.0 - t / self.approach_time, 0.0, 1.0))
        p = q + h[:, None] * b + off[:, None] * n
        trem = np.stack([self._noise(t, c, self.tremor_rms) for c in self._tremor], axis=1)
        return p + trem

    def surface_point(self, t) -> tuple[np.ndarray, np.ndarray]:
        """The mark's path point (N, 3) m and outward normal (N, 3) at times t (N,) s, without the finger's
        lag, wander, depth and tremor (a scene's path; the cylinder's circle otherwise)."""
        t = np.atleast_1d(np.asarray(t, float))
        if self._path is not None:
            q, n, _ = _path_at(self._path, np.asarray(self.target_fraction(t), float) * self._path["length"])
            return q, n
        phi = np.asarray(self.target_angle(t), float)
        n = np.cos(phi)[:, None] * self._e1[None, :] + np.sin(phi)[:, None] * self._e2[None, :]
        return self._c[None, :] + self.radius * n, n

    def position(self, t: float) -> np.ndarray:
        """Fingertip marker position (3,) m at time t s."""
        return self.positions(np.array([t]))[0]

    def velocity(self, t: float, h: float = 1e-4) -> np.ndarray:
        """Marker velocity (3,) m/s (central difference of :meth:`position`)."""
        p = self.positions(np.array([t - h, t + h]))
        return (p[1] - p[0]) / (2 * h)

    def state(self, t: float, h: float = 1e-4) -> tuple[np.ndarray, np.ndarray]:
        """(:meth:`position`, :meth:`velocity`) at t s from one evaluation of three samples: (3,) m, (3,)
        m/s."""
        p = self.positions(np.array([t - h, t, t + h]))
        return p[1], (p[2] - p[0]) / (2 * h)

    def angle_of(self, p) -> np.ndarray:
        """Angle(s) around the axis of point(s) p (3,) or (N, 3), rad, same convention as the target."""
        p = np.atleast_2d(np.asarray(p, float)) - self._c
        return np.arctan2(p @ self._e2, p @ self._e1)


#: samples of a scene's stroke path in the finger's table (linear interpolation: < 5 nm from the path on the
#: paper's 37 mm arc)
PATH_SAMPLES = 1025


def _path_table(scene) -> dict:
    """The scene's stroke path sampled for :meth:`FingerScript.positions`: arc length s (K,) m, points (K, 3),
    unit normals (K, 3), unit directions (K, 3), total ``length`` m, and the arc stroke's angle range, rad."""
    try:
        P, N = scene.stroke_at(np.linspace(0.0, 1.0, PATH_SAMPLES))
    except (AttributeError, TypeError) as exc:
        raise ValueError(f"scene must be a flexsheet.model.scenes.Scene, got {type(scene).__name__}: "
                         f"{exc}") from None
    seg = np.linalg.norm(np.diff(P, axis=0), axis=1)
    keep = np.concatenate([[True], seg > 1e-9])        # a projected polyline can repeat a surface point
    P, N = P[keep], N[keep]
    if len(P) < 3:
        raise ValueError(f"scene {getattr(scene, 'name', '?')!r}: the stroke path has no length")
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(P, axis=0), axis=1))])
    T = np.gradient(P, s, axis=0)
    T -= np.einsum("ij,ij->i", T, N)[:, None] * N
    T /= np.linalg.norm(T, axis=1, keepdims=True)
    dN = np.gradient(N, s, axis=0)
    kappa = np.einsum("ij,ij->i", dN, T)                  # normal curvature along the path, 1/m (convex > 0)
    st = scene.stroke
    angles = (math.radians(st.start_deg), math.radians(st.end_deg)) if st.kind == "arc" else (0.0, 0.0)
    return {"s": s, "P": P, "N": N, "T": T, "length": float(s[-1]), "angles": angles,
            "kappa_ends": (float(np.median(kappa[:8])), float(np.median(kappa[-8:])))}


def _path_at(tab: dict, arc: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Point, normal and direction (each (N, 3)) at arc lengths ``arc`` (N,) m along the table; beyond the
    ends the path goes on along the osculating circle of its end (the end's normal curvature; straight where
    it is flat), so a wander past the start of an arc stays on the arc's circle."""
    s, P, N, T = tab["s"], tab["P"], tab["N"], tab["T"]
    L = s[-1]
    a = np.clip(arc, 0.0, L)
    q = np.column_stack([np.interp(a, s, P[:, k]) for k in range(3)])
    n = np.column_stack([np.interp(a, s, N[:, k]) for k in range(3)])
    d = np.column_stack([np.interp(a, s, T[:, k]) for k in range(3)])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    over = arc - a
    for end, sel in ((0, over < 0.0), (1, over > 0.0)):
        if not np.any(sel):
            continue
        k = tab["kappa_ends"][end]
        sg = over[sel]
        th = sg * k
        if abs(k) > 1e-9:
            f_t, f_n = np.sin(th) / k, (np.cos(th) - 1.0) / k
        else:
            f_t, f_n = sg, np.zeros_like(sg)
        N0, T0 = n[sel], d[sel]
        q[sel] = q[sel] + f_t[:, None] * T0 + f_n[:, None] * N0
        n[sel] = np.cos(th)[:, None] * N0 + np.sin(th)[:, None] * T0
        d[sel] = np.cos(th)[:, None] * T0 - np.sin(th)[:, None] * N0
    return q, n, d


def after(prev: FingerScript, script: FingerScript, t: float, h: float = 1e-4) -> tuple[np.ndarray,
                                                                                        np.ndarray]:
    """(position (3,) m, velocity (3,) m/s) at time ``t`` s of segment ``script`` played after ``prev``:
    during ``script``'s approach the finger leaves where ``prev`` ended, lifts off along ``prev``'s last
    normal by ``approach_distance`` (in the first third of the approach) and blends (smoothstep) into
    ``script``'s own approach. A real finger moves through free space between two strokes; jumping to the next
    start put it behind the sheet still posed at the last stroke's end (a contact 3–4 mm deep that no finger
    makes). After the approach: ``script.state(t)``."""
    if not (0.0 <= t < script.approach_time):
        return script.state(t)
    p_end = prev.position(prev.duration)
    n_end = prev.surface_point(prev.duration)[1][0]

    def pos(x: float) -> np.ndarray:
        x = min(max(x, 0.0), script.approach_time)
        f = x / script.approach_time
        w = float(_smoothstep(np.array(f)))
        lift = script.approach_distance * float(_smoothstep(np.array(3.0 * f)))
        return (1.0 - w) * (p_end + lift * n_end) + w * script.position(x)

    return pos(t), (pos(t + h) - pos(t - h)) / (2.0 * h)
