"""Batched 3 × 3 algebra of the nonlinear reference (pure): the inverse and determinant of a stack of
deformation gradients (:func:`inv_det3`) and Gram products over a summed axis (:func:`gram`), vectorised over
elements and quadrature points for :class:`flexsheet.fem.reference.hyperelastic.HyperelasticModel`."""

from __future__ import annotations

import numpy as np

__all__ = ["inv_det3", "gram"]


def inv_det3(F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse (..., 3, 3) and determinant (...) of a stack of 3 × 3 matrices ``F`` (..., 3, 3), by cofactors
    (Cramer's rule): a few times faster than ``np.linalg.inv``/``det``, which call LAPACK per matrix. The
    inverse of a singular matrix has inf/nan entries (no error); callers check the determinant."""
    a, b, c = F[..., 0, 0], F[..., 0, 1], F[..., 0, 2]
    d, e, f = F[..., 1, 0], F[..., 1, 1], F[..., 1, 2]
    g, h, i = F[..., 2, 0], F[..., 2, 1], F[..., 2, 2]
    c00, c01, c02 = e * i - f * h, f * g - d * i, d * h - e * g
    det = a * c00 + b * c01 + c * c02
    adj = np.stack([np.stack([c00, c * h - b * i, b * f - c * e], axis=-1),
                    np.stack([c01, a * i - c * g, c * d - a * f], axis=-1),
                    np.stack([c02, b * g - a * h, a * e - b * d], axis=-1)], axis=-2)
    with np.errstate(divide="ignore", invalid="ignore"):
        return adj / det[..., None, None], det


def gram(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Σ_k A[..., k, x] B[..., k, y]: (..., X, Y) from (..., K, X) and (..., K, Y), as a batched BLAS matmul
    (np.einsum without ``optimize`` loops in C and is ~10× slower on these element batches)."""
    return np.swapaxes(A, -1, -2) @ B
