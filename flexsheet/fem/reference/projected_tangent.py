"""Projected Newton's tangent of the nonlinear reference (pure): the correction that turns
:class:`flexsheet.fem.reference.hyperelastic.HyperelasticModel`'s element stiffness into its positive
semi-definite projection, the material tangent A (9 × 9) clamped to its non-negative eigenvalues at every
quadrature point where it is indefinite (Teran, Sifakis, Irving & Fedkiw, SCA 2005; neo-Hookean or Gent)."""

from __future__ import annotations

import numpy as np

__all__ = ["projection_correction"]


def projection_correction(model, F: np.ndarray, Finv: np.ndarray, lnJ: np.ndarray,
                          gent: np.ndarray | None = None) -> np.ndarray:
    """Element-matrix correction Σ_q w Bᵀ(A₊ − A)B (E, 10, 3, 10, 3) of the tangent of ``model`` (a
    :class:`~flexsheet.fem.reference.hyperelastic.HyperelasticModel`: its Lamé parameters, Gent ``Jm``, shape
    gradients and quadrature weights; not imported here, as it imports this module) where A₊ clamps the
    material tangent A's negative eigenvalues to 0 (only quadrature points with a negative eigenvalue are
    touched), at deformation gradients ``F`` (E, Q, 3, 3) with their inverses ``Finv`` and ``lnJ`` (E, Q) =
    ln det F. ``gent`` (E, Q): the Gent factor g = 1/(1 − (I₁ − 3)/Jm) (None: neo-Hookean)."""
    E, Q = lnJ.shape
    S = np.einsum("eqJk,eqLi->eqiJkL", Finv, Finv).reshape(E, Q, 9, 9)
    f = np.swapaxes(Finv, 2, 3).reshape(E, Q, 9)
    A = (model.mu4 * np.eye(9) + (model.mu - model.lam * lnJ)[..., None, None] * S
         + model.lam4 * f[..., :, None] * f[..., None, :])
    if gent is not None:    # μ(g − 1) I + (2μg²/Jm) F ⊗ F on top of the neo-Hookean tangent
        fF = F.reshape(E, Q, 9)
        A = A + (model.mu4 * (gent - 1.0)[..., None, None]) * np.eye(9) \
            + ((2.0 / model.Jm) * model.mu * gent ** 2)[..., None, None] * fF[..., :, None] * fF[..., None, :]
    ev, V = np.linalg.eigh(A)
    out = np.zeros((E, 10, 3, 10, 3))
    bad = ev[..., 0] < 0
    if not np.any(bad):
        return out
    e_idx = np.flatnonzero(bad.any(axis=1))
    evb, Vb = ev[e_idx], V[e_idx]
    neg = np.minimum(evb, 0.0) * bad[e_idx][..., None]                      # A₊ − A = −V min(ev,0) Vᵀ
    ne = len(e_idx)
    D = -(Vb * neg[..., None, :]) @ np.swapaxes(Vb, -1, -2)                 # [e, q, (i, J), (k, L)]
    G = model.grad[e_idx]                                                    # [e, q, b, L]
    DG = (D.reshape(ne, Q, 27, 3) @ np.swapaxes(G, -1, -2)).reshape(ne, Q, 3, 3, 3, 10)  # [e, q, i, J, k, b]
    Gw = (G * model.w[e_idx][..., None, None]).transpose(0, 2, 1, 3).reshape(ne, 10, 3 * Q)  # [e, a, (q, J)]
    K = Gw @ DG.transpose(0, 1, 3, 2, 4, 5).reshape(ne, 3 * Q, 90)                         # [e, a, (i, k, b)]
    out[e_idx] = K.reshape(ne, 10, 3, 3, 10).transpose(0, 1, 2, 4, 3)
    return out
