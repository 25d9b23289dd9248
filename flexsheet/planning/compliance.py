"""The object's local normal stiffness at the contact, estimated from the scene (pure): what the sheet must
present when the FEM's dF/dd is not available ("compliance from the scene").

Model — a rigid spherical fingertip of radius r_f (``scene.finger.radius``) pressed ``d`` m into the object's
surface at contact point q:

1. **Hertz contact** (K. L. Johnson, *Contact Mechanics*, CUP 1985, §4.2 and §3.9): the object's principal
   curvatures κ₁, κ₂ at q (:func:`flexsheet.planning.shape.principal_curvatures`; > 0 convex) give the
   relative radii 1/R′ = 1/r_f + κ₁, 1/R″ = 1/r_f + κ₂ and the equivalent radius R_e = √(R′R″); the contact
   radius is a = √(R_e·d) and the incremental stiffness is k = dF/dd = 2E*·a with E* = E_eff/(1 − ν²) (rigid
   finger). This is also what the FEM's dF/dd is for a sphere (docs/fem.md). Concave curvatures are clipped at
   −1/(2r_f) (the finger still touches on a patch). Below ``min_depth`` (default 0.5 mm: the scripted
   finger's light stroking contact) the depth is taken as ``min_depth``, so a grazing finger asks for the
   stiffness of a light touch, not for zero.
2. **Inclusions** (the scene's stiffer spheres, a "tumour"): the effective modulus under the finger is the
   body's, raised by each inclusion in proportion to the share ``w`` of the indentation's strain energy that
   lies inside it. The energy density is that of Boussinesq's point load on an incompressible half-space — a
   purely radial stress σ_r = 3P·cosθ/(2πr²) (Johnson 1985, §3.2, ν = ½), so energy ∝ cos²θ/r⁴ — regularised
   over the contact, ρ ∝ cos²θ/(r² + a²)² (θ from the inward normal, r from q); its integral over the
   half-space is π²/(6a). ``w`` = ∫_inclusion ρ dV / ∫_half-space ρ dV by a fixed 1472-point midpoint grid in
   the ball (within 1 % of a 2·10⁶-point Monte Carlo for the organ's tumour). The modulus rises by Eshelby's
   dilute result for a spherical inclusion in an incompressible matrix (J. D. Eshelby, Proc. R. Soc. A 241,
   376 (1957); μ_eff = μ(1 + (5/2)·φ·(μ_i − μ)/(μ_i + 3μ/2))), with the energy share for the volume fraction
   φ: E_eff = E·(1 + Σ_i w_i·(5/2)(c_i − 1)/(c_i + 3/2)), c_i = E_i/E. For a small contrast this is the exact
   first-order perturbation (δk/k = w·δE/E); for a rigid inclusion it stays finite (factor 5/2).

Validity: small strain (Hertz holds for a ≲ r_f/2, i.e. d ≲ r_f/4 on a flat object; at the paper's 10–50 mm
pushes it is an order-of-magnitude estimate — the FEM's dF/dd replaces it wherever the FEM solves the scene);
the object is locally a half-space (its thickness ≫ a); the support is ignored. The planner then clamps the
stretch to what the arms can apply (:func:`flexsheet.model.tension.stretch_for_stiffness`:
``object_stiffer_than_sheet`` / ``object_softer_than_sheet``).

Units m, Pa, N/m; display frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from flexsheet.model.checks import check_positive
from flexsheet.model.shape_base import Shape
from flexsheet.planning.shape import planner_shape, principal_curvatures

__all__ = ["ContactStiffness", "SceneCompliance", "hertz_stiffness", "energy_share", "eshelby_factor"]


def hertz_stiffness(E_star: float, R_e: float, depth: float) -> tuple[float, float]:
    """Hertz incremental stiffness k = 2E*·a (N/m) and contact radius a = √(R_e·d) (m) of a sphere of
    equivalent radius ``R_e`` m pressed ``depth`` m into a half-space of contact modulus ``E_star`` Pa
    (Johnson 1985, eq. 4.22–4.23). Raises ``ValueError`` for a non-positive modulus or radius or a negative
    depth."""
    if not (E_star > 0.0 and R_e > 0.0 and depth >= 0.0 and math.isfinite(E_star * R_e * depth)):
        raise ValueError(f"hertz_stiffness needs E_star > 0, R_e > 0, depth >= 0; got {E_star!r}, {R_e!r}, "
                         f"{depth!r}")
    a = math.sqrt(R_e * depth)
    return 2.0 * E_star * a, a


def eshelby_factor(contrast: float) -> float:
    """(5/2)(c − 1)/(c + 3/2): the dilute stiffening per unit volume fraction of a spherical inclusion c times
    stiffer than an incompressible matrix (Eshelby 1957). 0 at c = 1, 5/2 for a rigid inclusion, negative for
    a softer one (≥ −5/3 for a void)."""
    return 2.5 * (contrast - 1.0) / (contrast + 1.5)


def _ball_quadrature(n_side: int = 14) -> np.ndarray:
    """Points (M, 3) of a regular grid inside the unit ball (cell centres), M = 1472 for ``n_side`` 14."""
    g = (np.arange(n_side) + 0.5) / n_side * 2.0 - 1.0
    X = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    return X[np.linalg.norm(X, axis=1) <= 1.0]


_BALL = _ball_quadrature()


def energy_share(q, n, a: float, center, radius: float) -> float:
    """Share w ∈ [0, 1] of the indentation's strain energy inside the ball (``center`` (3,) m, ``radius`` m)
    for a contact at ``q`` (3,) m with outward normal ``n`` (3,) and contact radius ``a`` m (module doc, item
    2). Points of the ball above the tangent plane do not count. Raises ``ValueError`` for a ≤ 0 or radius ≤
    0."""
    if not (a > 0.0 and radius > 0.0):
        raise ValueError(f"energy_share needs a > 0 and radius > 0, got a={a!r}, radius={radius!r}")
    qv = np.asarray(q, float)
    inward = -np.asarray(n, float) / np.linalg.norm(n)
    X = np.asarray(center, float) + radius * _BALL
    d = X - qv
    r2 = np.einsum("ij,ij->i", d, d)
    c = d @ inward
    below = c > 0.0
    cos2 = np.where(below, c * c / np.maximum(r2, 1e-30), 0.0)
    rho = cos2 / (r2 + a * a) ** 2
    vol = 4.0 / 3.0 * math.pi * radius ** 3
    w = float(rho.mean() * vol) / (math.pi ** 2 / (6.0 * a))
    return min(1.0, w)


@dataclass(frozen=True, slots=True)
class ContactStiffness:
    """One estimate: ``k`` N/m (dF/dd), ``depth`` m used (≥ ``min_depth``), ``a`` m contact radius, ``E_eff``
    Pa under the finger, ``E_body`` Pa, ``R_e`` m equivalent radius, ``kappa`` (κ₁, κ₂) 1/m, ``shares`` the
    energy share of each inclusion, ``k_body`` N/m the same contact without the inclusions."""

    k: float
    depth: float
    a: float
    E_eff: float
    E_body: float
    R_e: float
    kappa: tuple[float, float]
    shares: tuple[float, ...]
    k_body: float


class SceneCompliance:
    """The scene's local stiffness at a contact (module doc). ``scene``: a
    :class:`flexsheet.model.scenes.Scene`; ``shape``: the shape whose normals give the curvature (default
    :func:`flexsheet.planning.shape.planner_shape`); ``min_depth`` m; ``curvature_step`` m (the ±h of the
    curvature differences). Curvatures are cached per contact point (re-used within ``cache_distance`` m).
    Raises ``ValueError`` for a non-positive ``min_depth`` or ``curvature_step``."""

    def __init__(self, scene, shape: Shape | None = None, min_depth: float = 5e-4,
                 curvature_step: float = 2e-3,
                 cache_distance: float = 1e-3) -> None:
        for k, v in (("min_depth", min_depth), ("curvature_step", curvature_step)):
            check_positive(k, v)
        self.scene = scene
        self.shape = shape if shape is not None else planner_shape(scene)
        self.min_depth = float(min_depth)
        self.h = float(curvature_step)
        self.cache_distance = float(cache_distance)
        self.r_f = float(scene.finger.radius)
        self.E = float(scene.material.E)
        self.nu = float(scene.material.nu)
        self.inclusions = [(np.asarray(i.center, float), float(i.radius), float(i.E) / self.E)
                           for i in scene.inclusions]
        self._kcache: tuple[np.ndarray, tuple[float, float]] | None = None

    def curvatures(self, q, n) -> tuple[float, float]:
        """(κ₁, κ₂) 1/m at contact ``q`` with normal ``n`` (cached within ``cache_distance``)."""
        qv = np.asarray(q, float)
        c = self._kcache
        if c is not None and float(np.linalg.norm(c[0] - qv)) <= self.cache_distance:
            return c[1]
        k = principal_curvatures(self.shape, tuple(qv), tuple(np.asarray(n, float)), self.h)
        self._kcache = (qv, k)
        return k

    def estimate(self, q, n, depth: float) -> ContactStiffness:
        """The stiffness for a finger ``depth`` m (< ``min_depth``: ``min_depth``) into the surface at ``q``
        (3,) m with outward normal ``n`` (3,). Raises ``ValueError`` for non-finite input."""
        qv, nv = np.asarray(q, float), np.asarray(n, float)
        if qv.shape != (3,) or nv.shape != (3,) or not (np.all(np.isfinite(qv)) and np.all(np.isfinite(nv))
                                                         and math.isfinite(depth)):
            raise ValueError(f"estimate needs finite q (3,), n (3,) and depth, got {q!r}, {n!r}, {depth!r}")
        d = max(float(depth), self.min_depth)
        k1, k2 = self.curvatures(qv, nv)
        floor = -0.5 / self.r_f
        r1 = 1.0 / (1.0 / self.r_f + max(k1, floor))
        r2 = 1.0 / (1.0 / self.r_f + max(k2, floor))
        R_e = math.sqrt(r1 * r2)
        E_star = self.E / (1.0 - self.nu ** 2)
        k_body, a = hertz_stiffness(E_star, R_e, d)
        shares = tuple(energy_share(qv, nv, a, c, r) for c, r, _ in self.inclusions)
        factor = (1.0
                  + sum(w * eshelby_factor(cr) for w,
                        (_, _, cr) in zip(shares, self.inclusions, strict=True)))
        factor = max(factor, 0.05)
        return ContactStiffness(k_body * factor, d, a, self.E * factor, self.E, R_e, (k1, k2), shares, k_body)

    def __call__(self, q, n, depth: float) -> float:
        """k N/m (:meth:`estimate`)."""
        return self.estimate(q, n, depth).k
