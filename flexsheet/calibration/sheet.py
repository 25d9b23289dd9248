"""The sheet's force under a fingertip, identified from pushes as a lab measures it (pure: numpy + scipy).

A probe the size of a fingertip (an 8 mm-radius sphere) on a load cell, on a stage moving along the sheet's
normal, is pressed into the tensioned sheet at several points and clamp strains; each press records the force
at a few depths. The planner's sheet model (:mod:`flexsheet.model.tension`),

    F = h(u, v)·(g(u)·[T(ε + ε₀)·(w·d + w₂·d²) + b·d + a·d²] + c·d³),   g = 1/a + 1/b,
    h = 1 + p_u·(2u/L₀)² + p_v·(2v/L₀)²,

is fitted to them: T is the nominal neo-Hookean tension (its modulus error goes into w), ε₀ the sheet's own
strain offset (pre-strain less grip slip), w the band width, w₂ its growth with depth, b and a the sheet's own
stiffness that does not scale with the pull, c the membrane's stretching, p_u and p_v where the finger presses
(the presses at the centre, toward a clamp and toward a free edge set them). For given (ε₀, p_u, p_v) the
model is linear in (w, w₂, b, a, c) ≥ 0, so they come from a non-negative weighted least squares
(``scipy.optimize.nnls``) in relative error, floored at the load cell's noise: weights 1/(σ₀ + F), σ₀ =
:data:`NOISE_N` — what a finger tells apart is a ratio (the Weber fraction), and weighting by the noise alone
(1/(σ₀ + 0.5 %·F)) let the deep presses set the fit and left the 2 mm presses 14 % light (median; 4 % with
relative weights; docs/figures/calibration/sheet); ε₀ is the bounded scalar minimum of that fit's residual
(``scipy.optimize.minimize_scalar``), then (ε₀, p_u, p_v) together from there (Nelder–Mead; p_u needs presses
at two distances along the clamp line, p_v two across, else it stays 0). The residual reported is the median
and RMS relative error of the model against the presses.

Units: m, N, N/m; strain dimensionless. Frames: the sheet's (u along the clamp line from the centre, v
across).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from flexsheet.model.tension import SheetMaterial, contact_geometry, position_factor, press_force, tension

__all__ = ["Press", "PRESS_STRETCHES", "PRESS_POINTS", "PRESS_DEPTHS", "plan_presses", "SheetFit", "TERMS",
           "OPTIONAL_TERMS",
           "with_terms", "fit_sheet", "model_error", "relative_errors"]

#: clamp strains pressed at: dense over the strains the display works at
#: (0.005–0.05), and 0.08 for the stiff end (the bridges' span band is 0.01–0.10)
PRESS_STRETCHES = (0.005, 0.01, 0.015, 0.02, 0.025, 0.03, 0.04, 0.05, 0.08)
#: contact points (u, v), m from the sheet centre: the centre, toward a clamp and toward a free edge
PRESS_POINTS = ((0.0, 0.0), (0.036, 0.0), (0.072, 0.0), (0.0, 0.036), (0.036, 0.036))
#: probe depths per press, m
PRESS_DEPTHS = (0.002, 0.004, 0.007, 0.010, 0.015, 0.020)
#: load-cell noise (N, and relative) the fit weights by: a 10 N cell, 5 mN + 0.5 % of the reading
NOISE_N, NOISE_REL = 0.005, 0.005


@dataclass(frozen=True)
class Press:
    """One reading: clamp strain ``stretch``, contact ``offset_u``/``offset_v`` (m), probe ``depth`` (m) along
    the sheet's normal from the flat sheet, ``force`` (N) on the load cell."""

    stretch: float
    offset_u: float
    offset_v: float
    depth: float
    force: float


def plan_presses(stretches=PRESS_STRETCHES, points=PRESS_POINTS, depths=PRESS_DEPTHS
                 ) -> list[tuple[float, float, float, tuple[float, ...]]]:
    """The presses to make: (stretch, u, v, depths) for every stretch and point. Raises ``ValueError`` on an
    empty list, a negative stretch or a non-increasing depth list."""
    if not stretches or not points or not depths:
        raise ValueError("stretches, points and depths must be non-empty")
    if any(not (math.isfinite(s) and s >= 0.0) for s in stretches):
        raise ValueError(f"stretches must be finite and >= 0, got {stretches!r}")
    if any(not d > 0.0 for d in depths) or np.any(np.diff(depths) <= 0):
        raise ValueError(f"depths must be > 0 and increasing, got {depths!r}")
    return [(float(s), float(u), float(v), tuple(float(d) for d in depths)) for s in stretches for u,
            v in points]


@dataclass(frozen=True)
class SheetFit:
    """The identified model: ``contact_width`` w (m), ``contact_growth`` w₂, ``own_stiffness`` b (N),
    ``own_growth`` a (N/m), ``stretching`` c (N/m³), ``strain_offset`` ε₀, ``position_u`` p_u, ``position_v``
    p_v; ``median_pct``/``rms_pct``: the model's relative error against the presses, %; ``n``: presses
    used."""

    contact_width: float
    contact_growth: float
    own_stiffness: float
    own_growth: float
    stretching: float
    strain_offset: float
    position_u: float
    position_v: float
    median_pct: float
    rms_pct: float
    n: int

    def material(self, base: SheetMaterial | None = None) -> SheetMaterial:
        """``base`` (default the nominal :class:`SheetMaterial`) with the identified terms."""
        return with_terms(self, base)


#: the identified terms of :class:`~flexsheet.model.tension.SheetMaterial`,
#: as the fit and ``display.yaml`` name them
TERMS = ("contact_width", "contact_growth", "own_stiffness", "own_growth", "stretching", "strain_offset",
         "position_u", "position_v")
#: the :data:`TERMS` an older sheet entry may lack: read as 0 (the string band's, no position term)
OPTIONAL_TERMS = ("position_u", "position_v")


def with_terms(src, base: SheetMaterial | None = None) -> SheetMaterial:
    """``base`` (default the nominal :class:`SheetMaterial`) with the :data:`TERMS` of ``src`` (a
    :class:`SheetFit` or a ``display.yaml`` sheet entry). Raises ``ValueError`` as :class:`SheetMaterial` does
    for a term out of its range."""
    return replace(base or SheetMaterial(), **{k: float(getattr(src, k)) for k in TERMS})


def _columns(presses: list[Press], mat: SheetMaterial) -> np.ndarray:
    """(n, 5) regressors of (w, w₂, b, a, c) at ``mat``'s strain offset and position terms."""
    rows = []
    for p in presses:
        h = position_factor(mat, p.offset_u, p.offset_v)
        g = contact_geometry(p.stretch, mat, p.offset_u) * h
        tg, d = tension(p.stretch, mat) * g, p.depth
        rows.append((tg * d, tg * d * d, g * d, g * d * d, h * d ** 3))
    return np.array(rows)


def fit_sheet(presses: list[Press], base: SheetMaterial | None = None,
              offset_bound: float = 0.03) -> SheetFit:
    """Fit the model (module doc) to ``presses`` on top of ``base`` (nominal E, thickness, size). Raises
    ``ValueError`` with fewer than 4 presses, a non-finite or negative reading, or presses at one strain only
    (ε₀ and w cannot be told apart)."""
    from scipy.optimize import minimize, minimize_scalar, nnls

    base = base or SheetMaterial()
    if len(presses) < 4:
        raise ValueError(f"need at least 4 presses, got {len(presses)}")
    for i, p in enumerate(presses):
        vals = (p.stretch, p.offset_u, p.offset_v, p.depth, p.force)
        if not all(math.isfinite(x) for x in vals) or p.depth <= 0.0 or p.force < 0.0 or p.stretch < 0.0:
            raise ValueError(f"press {i}: stretch, depth and force must be finite, depth > 0 and force >= 0, "
                             f"got {p}")
    if len({round(p.stretch, 6) for p in presses}) < 2:
        raise ValueError("presses at two clamp strains at least are needed to separate the strain offset")
    F = np.array([p.force for p in presses])
    wgt = 1.0 / (NOISE_N + F)           # relative error above the noise floor (module doc)

    def solve(eps0: float, pu: float = 0.0, pv: float = 0.0):
        mat = replace(base, strain_offset=float(eps0), position_u=float(pu), position_v=float(pv))
        A = _columns(presses, mat)
        x, _ = nnls(A * wgt[:, None], F * wgt)
        r = (A @ x - F) * wgt
        return float(r @ r), x

    lo = max(-offset_bound, -min(p.stretch for p in presses) + 1e-4)
    best = minimize_scalar(lambda e: solve(e)[0], bounds=(lo, offset_bound), method="bounded",
                           options={"xatol": 1e-5})
    eps0, pu, pv = float(best.x), 0.0, 0.0
    free = [len({round(abs(getattr(p, k)), 4) for p in presses}) >= 2 for k in ("offset_u", "offset_v")]
    if any(free):
        def cost(z):
            e, u_, v_ = z[0], (z[1] if free[0] else 0.0), (z[-1] if free[1] else 0.0)
            if not (lo <= e <= offset_bound and -0.9 <= u_ <= 5.0 and -0.9 <= v_ <= 5.0):
                return math.inf
            return solve(e, u_, v_)[0]
        z = minimize(cost, [eps0] + [0.0] * sum(free), method="Nelder-Mead",
                     options={"xatol": 1e-6, "fatol": 1e-14, "maxiter": 4000}).x
        eps0, pu, pv = float(z[0]), (float(z[1]) if free[0] else 0.0), (float(z[-1]) if free[1] else 0.0)
    _, (w, w2, b, a, c) = solve(eps0, pu, pv)
    fit = SheetFit(float(w), float(w2), float(b), float(a), float(c), eps0, pu, pv, 0.0, 0.0, len(presses))
    med, rms = model_error(fit.material(base), presses)
    return replace(fit, median_pct=med, rms_pct=rms)


def relative_errors(mat: SheetMaterial, presses: list[Press], min_force: float = 0.02) -> np.ndarray:
    """|model − force| / force (n,), %, of :func:`flexsheet.model.tension.press_force` with ``mat`` against
    the presses' forces (those ≥ ``min_force`` N: a few mN divide into meaningless ratios). Raises
    ``ValueError`` when no press is that strong."""
    pairs = [(press_force(p.stretch, mat, p.offset_u, p.depth, p.offset_v), p.force) for p in presses
             if p.force >= min_force]
    if not pairs:
        raise ValueError(f"no press of at least {min_force} N to judge the model by")
    m, f = np.array(pairs).T
    return np.abs(m - f) / f * 100.0


def model_error(mat: SheetMaterial, presses: list[Press], min_force: float = 0.02) -> tuple[float, float]:
    """(median, RMS) of :func:`relative_errors`, %. Raises ``ValueError`` as it does."""
    rel = relative_errors(mat, presses, min_force)
    return float(np.median(rel)), float(np.sqrt(np.mean(rel ** 2)))
