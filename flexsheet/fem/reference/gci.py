"""The grid convergence index of a reference from three mesh levels (Roache 1994, "Perspective: a method for
uniform reporting of grid refinement studies", J. Fluids Eng. 116:405; the procedure of Celik et al. 2008, J.
Fluids Eng. 130:078001), applied to the visible difference between levels in projector pixels.

With levels h₁ < h₂ < h₃ (fine to coarse) at ratios r₂₁ = h₂/h₁ and r₃₂ = h₃/h₂, and the differences e₂₁ = |f₂
− f₁| and e₃₂ = |f₃ − f₂| (here: the largest visible shape difference, px), the apparent order solves p =
|ln(e₃₂/e₂₁) + ln((r₂₁ᵖ − s)/(r₃₂ᵖ − s))| / ln r₂₁ with s = 1 (monotone convergence), by fixed-point
iteration; it is capped at :data:`P_MAX` (the P2 elements' displacement order near a contact edge is lower,
and a cap keeps a lucky pair of levels from claiming more). The fine level's band is GCI = F_s·e₂₁/(r₂₁ᵖ − 1),
F_s = 1.25. Where the differences do not fall (e₃₂ ≤ e₂₁) the levels are not in the asymptotic range: GCI is
``inf``.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["gci", "gci_by_depth", "P_MAX", "SAFETY"]

P_MAX = 2.0          #: the largest apparent order credited
SAFETY = 1.25        #: F_s for three levels (Roache)


def gci(e21: float, e32: float, r21: float, r32: float) -> tuple[float, float]:
    """(GCI of the fine level, in the units of ``e21``; the apparent order p) from the differences ``e21``
    (fine–medium) and ``e32`` (medium–coarse), ≥ 0, and the refinement ratios ``r21``, ``r32`` (> 1). GCI is
    0.0 when both differences are 0, ``inf`` (p nan) when they do not fall. Raises ``ValueError`` for a
    negative or non-finite difference or a ratio ≤ 1."""
    for name, v in (("e21", e21), ("e32", e32)):
        if not (math.isfinite(v) and v >= 0):
            raise ValueError(f"{name} must be a finite difference >= 0, got {v!r}")
    for name, v in (("r21", r21), ("r32", r32)):
        if not (math.isfinite(v) and v > 1):
            raise ValueError(f"{name} must be a refinement ratio > 1, got {v!r}")
    if e21 == 0.0 and e32 == 0.0:
        return 0.0, float("nan")
    if e32 <= e21:
        return float("inf"), float("nan")
    p = math.log(e32 / e21) / math.log(r21)
    for _ in range(50):                              # Celik et al. eq. 3: the unequal-ratio correction
        q = math.log((r21 ** p - 1.0) / (r32 ** p - 1.0)) if p > 0 else 0.0
        p_new = abs(math.log(e32 / e21) + q) / math.log(r21)
        if abs(p_new - p) < 1e-10:
            break
        p = p_new
    p = min(p, P_MAX)
    return SAFETY * e21 / (r21 ** p - 1.0), p


def gci_by_depth(e21, e32, h: tuple[float, float, float]) -> dict:
    """:func:`gci` at each depth: ``e21``, ``e32`` (D,) px; ``h`` the three levels' sizes, coarse to fine (m).
    Returns {"gci_px" (D,), "order" (D,), "ratios" [r32, r21]}."""
    h3, h2, h1 = (float(x) for x in h)
    r21, r32 = h2 / h1, h3 / h2
    out = [gci(float(a), float(b), r21, r32) for a,
           b in zip(np.asarray(e21, float), np.asarray(e32, float), strict=True)]
    return {"gci_px": [g for g, _ in out], "order": [p for _, p in out], "ratios": [r32, r21]}
