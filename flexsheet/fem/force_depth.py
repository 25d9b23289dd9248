"""The object's force–depth table (:class:`flexsheet.model.force_depth.ForceDepth`) from the real-time FEM
model the node serves (:func:`flexsheet.fem.served.served_model`): at ``n_points`` points evenly along the
scene's stroke the finger is pushed along the inward normal, 0 → the scene's ``use.max_depth`` in ``step`` m
steps, the model reset before each point, and its contact force recorded. What deforms the image is what the
finger is asked to feel.

:func:`hertz_check` compares the table with Hertz's closed form (K. L. Johnson, *Contact Mechanics*, CUP 1985,
§4.2: F = (4/3)·E*·√R_e·d^{3/2}, rigid spherical finger, E* = E/(1 − ν²), R_e from the relative curvatures) at
the scene's reference point, where it applies: a smooth convex body without inclusions (cylinder, sphere) and
small depth (contact radius a = √(R_e·d) ≤ r_f/2).

**Small depth.** The served tables solve a push from :data:`SOLVED_FROM` on and interpolate linearly below it,
which overstates a contact's force (+69 % at 1 mm on the cylinder against Hertz). There each curve follows the
contact law's c·d^{3/2}, c fitted to the model's force over [:data:`SOLVED_FROM`, 2·:data:`SOLVED_FROM`]
(:func:`contact_fit`). The linear scene model's mesh jitter (about ±10 % between 0.5 mm steps on the rounded
box) is kept: it is the model's.

Units m, N; display frame. Errors: ``ValueError`` naming the field.
"""

from __future__ import annotations

import contextlib
import math

import numpy as np

from flexsheet.fem.served import served_model
from flexsheet.model.force_depth import ForceDepth

__all__ = ["N_POINTS", "STEP", "SOLVED_FROM", "build_force_depth", "contact_fit", "hertz_check"]

N_POINTS = 25       #: points along the stroke (the first is the scene's ``reference``)
STEP = 0.0005       #: depth step, m
#: the served models solve a push from this depth (m) on: the snapshot and path tables' first depth; shallower
#: they interpolate linearly from 0, which overstates a contact's force (+69 % at 1 mm on the cylinder)
SOLVED_FROM = 0.0025


def build_force_depth(scene, model=None, n_points: int = N_POINTS, step: float = STEP,
                      depth_max: float | None = None, lock=None) -> ForceDepth:
    """Push ``model`` (default: the served model of ``scene``) at ``n_points`` stroke points (module doc), 0 →
    ``depth_max`` (default ``scene.use.max_depth``) in ``step`` m. A push the model rejects or solves invalid
    ends that point's curve; its later depths extrapolate with the last slope. ``lock``: a context manager
    held around each point's push (a node serving the same model between points). Raises ``ValueError`` for
    fewer than 2 points, a non-positive step or depth."""
    if n_points < 2:
        raise ValueError(f"n_points must be >= 2, got {n_points!r}")
    d_max = float(scene.use.max_depth if depth_max is None else depth_max)
    if not (math.isfinite(step) and step > 0.0 and math.isfinite(d_max) and d_max >= 2 * step):
        raise ValueError(f"step and depth_max must be > 0 m with depth_max >= 2 steps, got {step!r}, "
                         f"{d_max!r}")
    if model is None:
        model, _ = served_model(scene)
    depths = np.arange(0.0, d_max + 0.5 * step, step)
    P, N = scene.stroke_at(np.linspace(0.0, 1.0, n_points))
    F = np.zeros((n_points, len(depths)))
    hold = lock if lock is not None else contextlib.nullcontext()
    for i, (p, n) in enumerate(zip(P, N, strict=True)):
        last = 0
        with hold:
            model.reset()
            for j, d in enumerate(depths[1:], start=1):
                try:
                    u = model.update(p - n * d)
                except ValueError:
                    break
                if not (u.valid and math.isfinite(u.force)):
                    break
                F[i, j] = max(0.0, float(u.force))
                last = j
            model.reset()
        if last < len(depths) - 1:      # extrapolate with the last slope (≥ 0)
            slope = max(0.0, (F[i, last] - F[i, last - 1]) / step) if last >= 1 else 0.0
            F[i, last + 1:] = F[i, last] + slope * (depths[last + 1:] - depths[last])
        F[i] = contact_fit(depths, F[i])[0]
    names = ["reference"] + [f"stroke_{100 * f:.0f}" for f in np.linspace(0.0, 1.0, n_points)[1:]]
    return ForceDepth(P, N, tuple(names), depths, F, scene.key())


def contact_fit(depths: np.ndarray, force: np.ndarray) -> tuple[np.ndarray, float]:
    """(force (D,) N at ``depths`` (D,) m with the shallow part replaced, the fitted c N/m^{3/2}) as the
    module doc says: c·d^{3/2} fitted by least squares over [:data:`SOLVED_FROM`, 2·:data:`SOLVED_FROM`], used
    below :data:`SOLVED_FROM`; deeper, the model's force, made non-decreasing. Raises ``ValueError`` without a
    solved depth in the fit range."""
    d = np.asarray(depths, float)
    f = np.asarray(force, float).copy()
    use = (d >= SOLVED_FROM - 1e-9) & (d <= 2.0 * SOLVED_FROM + 1e-9)
    if not use.any():
        raise ValueError(f"contact_fit needs a depth in [{SOLVED_FROM}, {2 * SOLVED_FROM}] m")
    x = d[use] ** 1.5
    c = float(x @ f[use] / (x @ x))
    low = d < SOLVED_FROM - 1e-9
    f[low] = c * d[low] ** 1.5
    return np.maximum.accumulate(np.maximum(f, 0.0)), c


def hertz_check(scene, table: ForceDepth, depths=(0.001, 0.002, 0.003)) -> dict | None:
    """The table's force at the ``reference`` point against Hertz (module doc) at ``depths`` m; None where
    Hertz does not apply (inclusions, or a body that is not a cylinder or sphere). Returns
    ``{"depth_m", "hertz_n", "table_n", "ratio", "contact_radius_m", "source"}``."""
    kind = scene.object.kind
    if scene.inclusions or kind not in ("cylinder", "sphere"):
        return None
    r_f = float(scene.finger.radius)
    R = float(scene.object.radius)
    r1 = 1.0 / (1.0 / r_f + 1.0 / R)
    r2 = r1 if kind == "sphere" else r_f
    R_e = math.sqrt(r1 * r2)
    E_star = float(scene.material.E) / (1.0 - float(scene.material.nu) ** 2)
    i = table.names.index("reference")
    q = table.points[i]
    hz = [4.0 / 3.0 * E_star * math.sqrt(R_e) * d ** 1.5 for d in depths]
    tb = [table.force_at(q, d) for d in depths]
    return {"depth_m": list(depths), "hertz_n": hz, "table_n": tb,
            "ratio": [t / h for t, h in zip(tb, hz, strict=True)],
            "contact_radius_m": [math.sqrt(R_e * d) for d in depths], "equivalent_radius_m": R_e,
            "source": "Hertz, rigid sphere on a half-space of the scene's E*, Johnson 1985 §4.2"}
