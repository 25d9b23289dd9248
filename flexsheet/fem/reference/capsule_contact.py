"""The geometrically nonlinear reference's finger (pure): a rigid capsule (the fingertip sphere swept back
along its shaft), the contact laws, and the smoothed penalty that keeps the surface out of it.

* **Finger**: rigid frictionless *capsule* (the fingertip sphere of radius r plus the finger's shaft behind
  it, along −p̂), non-penetration at the contact quadrature points of the outer surface of a
  :class:`~flexsheet.fem.reference.hyperelastic.HyperelasticModel` (order
  :data:`~flexsheet.fem.reference.hyperelastic.CONTACT_INTORDER`: 25 points per facet, because the facets
  around the tip stretch several times over and the fingertip slipped between the 6 points of the order-4
  rule), penalty E_c = Σ w φ(g_i) (gap g_i = distance to the capsule's axis segment − r; φ a C² penalty that
  starts ε = 20 µm before contact, :func:`smooth_penalty`); k = :data:`PENALTY_SCALE`·E/h, chosen by a penalty
  study (the visible surface within 0.03 mm of a 10× stiffer finger; the loaded points stand off by < ε or
  penetrate < 0.02 mm at 50 mm, reported). A real finger, not a bonded imposed displacement (the linear
  model's contact): material slides along it and wraps around it.
* **Sticking**: optionally (``contact="sticking"``,
  :func:`~flexsheet.fem.reference.path_solver.solve_path_capsule`) a fingertip that does not slip: points that
  touch it stick to it. It removes the frictionless snap-through under the tip but mesh-converges worse
  (docs/fem.md), so frictionless stays the default (:data:`DEFAULT_CONTACT`).

Units SI: m, N, Pa. Display frame (cylinder axis along +y through the mesh centre).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["PENALTY_SCALE", "CONTACT_LAWS", "DEFAULT_CONTACT", "Capsule", "capsule_at", "smooth_penalty"]

#: contact penalty κ = PENALTY_SCALE·E/h. Chosen by a penalty study (``flexsheet experiment fem``,
#: ``reference.penalty_study``): on the 6 mm mesh at 50 mm the old 10³ penetrated the finger
#: by 1.2 mm, made the force 10 % low and moved the visible surface by 2.2 mm against 10⁴; 10⁵
#: penetrates 0.004 mm and lies 0.03 mm from 10⁶ (docs/fem.md). Newton needs ~2.3× the CPU of
#: 10³ for it. Changing it needs a :data:`~flexsheet.fem.reference.versions.SOLVER_VERSION`
#: bump (the snapshot tables' cache key carries the solver tag, not the penalty).
PENALTY_SCALE = 1e5
#: finger contact laws (:func:`~flexsheet.fem.reference.path_solver.solve_path_capsule`)
CONTACT_LAWS = ("frictionless", "sticking")
DEFAULT_CONTACT = "frictionless"            #: the contact law the experiment and the snapshots use


@dataclass(frozen=True)
class Capsule:
    """Rigid finger: the sphere (centre ``center`` (3,) m, radius ``radius`` m) swept back along
    −``direction`` by ``shaft`` m (the finger's body). ``direction`` (3,) unit push direction p̂ (into the
    object). ``anchors`` (Fc, Qf, 3) m, sticking contact only: for each contact quadrature point of the
    :class:`HyperelasticModel` it is used with, the finger point it is stuck to, relative to ``center`` (NaN
    where not stuck); stuck points are held there by the penalty k/2 |x − (center + anchor)|² instead of the
    normal-only one (the finger only translates, so a point on it keeps its offset from ``center``)."""

    center: np.ndarray
    direction: np.ndarray
    radius: float
    shaft: float = 0.1
    anchors: np.ndarray | None = None

    def gap(self, x: np.ndarray, curvature: bool = False):
        """Signed gaps (N,) m (< 0: inside the finger) and unit outward normals (N, 3) at points ``x`` (N, 3);
        with ``curvature`` also ∂n/∂x (N, 3, 3) (1/m): (I − nnᵀ)/ρ on the sphere, (I − nnᵀ − p̂p̂ᵀ)/ρ on the
        shaft, ρ the distance from the finger's axis point."""
        rel = np.asarray(x, float) - self.center
        s_raw = -(rel @ self.direction)
        s = np.clip(s_raw, 0.0, self.shaft)                        # position along the shaft (backward)
        q = rel + s[:, None] * self.direction                      # from the closest axis point to x
        d = np.linalg.norm(q, axis=1)
        n = q / np.maximum(d, 1e-12)[:, None]
        if not curvature:
            return d - self.radius, n
        P = np.eye(3) - n[:, :, None] * n[:, None, :]
        shaft = (s_raw > 0) & (s_raw < self.shaft)
        P[shaft] -= np.outer(self.direction, self.direction)
        return d - self.radius, n, P / np.maximum(d, 1e-12)[:, None, None]


def capsule_at(angle: float, depth: float, radius: float, cyl_radius: float, cyl_center: np.ndarray,
               axial: float = 0.0) -> Capsule:
    """Finger pushed radially at azimuth ``angle`` (rad) to ``depth`` (m; the sphere's leading point is
    ``depth`` inside the undeformed surface, as :func:`flexsheet.fem.contact.finger_at`). Raises
    ``ValueError`` on NaN or negative depth."""
    for name, v in (("angle", angle), ("depth", depth), ("radius", radius), ("axial", axial)):
        if not math.isfinite(v):
            raise ValueError(f"{name} must be finite, got {v!r}")
    if depth < 0:
        raise ValueError(f"depth must be >= 0, got {depth!r}")
    if radius <= 0:
        raise ValueError(f"radius must be > 0, got {radius!r}")
    out = np.array([math.cos(angle), 0.0, math.sin(angle)])
    cp = np.asarray(cyl_center, float) + np.array([0.0, axial, 0.0]) + cyl_radius * out
    return Capsule(cp - depth * out + radius * out, -out, float(radius))


def smooth_penalty(g: np.ndarray, k: float, eps: float):
    """Smoothed contact penalty φ(g) J/m² and its derivatives φ' N/m², φ'' N/m³ for gaps ``g`` (m; any shape),
    stiffness ``k`` N/m³ and onset width ``eps`` m: k/(6ε)(ε − g)³ on [0, ε), the
    matching quadratic k/2 g² − kε/2 g + kε²/6 below 0 (C², so Newton sees no kink), 0 above ε."""
    g = np.asarray(g, float)
    inside = g < 0
    mid = (g >= 0) & (g < eps)
    phi = np.where(inside, 0.5 * k * g * g - 0.5 * k * eps * g + k * eps * eps / 6.0,
                   np.where(mid, k / (6 * eps) * (eps - g) ** 3, 0.0))
    d1 = np.where(inside, k * g - 0.5 * k * eps, np.where(mid, -k / (2 * eps) * (eps - g) ** 2, 0.0))
    d2 = np.where(inside, k, np.where(mid, k / eps * (eps - g), 0.0))
    return phi, d1, d2
