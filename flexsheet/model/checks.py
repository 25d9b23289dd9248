"""Input validators shared by every model, node and experiment: points, vectors, unit vectors, rotations and
rigid transforms.

Each takes the argument's ``name`` so the error names the field and the offending value, returns the value as
float64 numpy, and raises ``ValueError`` (nodes turn that into ``InputRejected``). Tolerances are absolute.
Model: pytransform3d's ``check_transform`` / ``check_matrix`` (Fabisch 2019), which validate the same
properties (shape, finiteness, orthonormal rotation with det +1, last row (0, 0, 0, 1)).
"""

from __future__ import annotations

import numpy as np

from flexsheet.model.vec import vnorm

__all__ = ["check_point", "check_vector", "check_unit", "check_positive", "check_rotation", "check_pose"]

_I3 = np.eye(3)


def _short(a) -> str:
    try:
        return repr(np.round(np.asarray(a, dtype=float), 6).tolist())
    except (TypeError, ValueError):
        return repr(a)


def check_point(name: str, p, dim: int = 3) -> np.ndarray:
    """A finite point (``dim``,) in m; returns float64. Raises ``ValueError`` naming ``name``."""
    try:
        a = np.asarray(p, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a finite ({dim},) point in m, got {p!r}") from None
    if a.shape != (dim,) or not np.isfinite(a).all():
        raise ValueError(f"{name} must be a finite ({dim},) point in m, got {_short(p)}")
    return a


def check_vector(name: str, v, dim: int = 3, nonzero: bool = False) -> np.ndarray:
    """A finite vector (``dim``,); with ``nonzero`` its norm must exceed 1e-12. Raises ``ValueError``."""
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a finite ({dim},) vector, got {v!r}") from None
    if a.shape != (dim,) or not np.isfinite(a).all():
        raise ValueError(f"{name} must be a finite ({dim},) vector, got {_short(v)}")
    if nonzero and vnorm(a) <= 1e-12:
        raise ValueError(f"{name} must be non-zero, got {_short(v)}")
    return a


def check_unit(name: str, v, tol: float | None = None) -> np.ndarray:
    """A direction (3,). With ``tol=None`` it is normalised (must be non-zero); otherwise its norm must be
    1 within ``tol``. Returns the unit vector. Raises ``ValueError`` naming ``name``."""
    a = check_vector(name, v, 3, nonzero=True)
    n = vnorm(a)
    if tol is not None and abs(n - 1.0) > tol:
        raise ValueError(f"{name} must be a unit vector (|v| = 1 ± {tol:g}), got |v| = {n:.6g}")
    return a / n


def check_positive(name: str, x, allow_zero: bool = False) -> float:
    """A finite scalar > 0 (or ≥ 0 with ``allow_zero``); returns float. Raises ``ValueError``."""
    try:
        f = float(x)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a finite number, got {x!r}") from None
    if not np.isfinite(f) or f < 0.0 or (f == 0.0 and not allow_zero):
        raise ValueError(f"{name} must be {'>= 0' if allow_zero else '> 0'} and finite, got {x!r}")
    return f


def check_rotation(name: str, R, tol: float = 1e-6) -> np.ndarray:
    """A (3, 3) proper rotation (RᵀR = I within ``tol``, det > 0); returns float64. Raises ``ValueError``."""
    try:
        A = np.asarray(R, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a finite (3, 3) rotation, got {R!r}") from None
    if A.shape != (3, 3) or not np.isfinite(A).all():
        raise ValueError(f"{name} must be a finite (3, 3) rotation, got shape {A.shape}")
    err = float(np.abs(A.T @ A - _I3).max())
    if err > tol or np.linalg.det(A) <= 0.0:
        raise ValueError(f"{name} is not a proper rotation (|RᵀR − I| = {err:.2g}, det = "
                         f"{np.linalg.det(A):.4g}): {_short(A)}")
    return A


def check_pose(name: str, T, tol: float = 1e-6) -> np.ndarray:
    """A (4, 4) rigid transform: finite, last row (0, 0, 0, 1), proper rotation block within ``tol``.

    Returns float64. Raises ``ValueError`` naming ``name`` and what is wrong.
    """
    try:
        A = np.asarray(T, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a finite (4, 4) transform, got {T!r}") from None
    if A.shape != (4, 4) or not np.isfinite(A).all():
        raise ValueError(f"{name} must be a finite (4, 4) transform, got shape {A.shape}")
    if np.abs(A[3] - (0.0, 0.0, 0.0, 1.0)).max() > tol:
        raise ValueError(f"{name} last row must be (0, 0, 0, 1), got {_short(A[3])}")
    check_rotation(f"{name} rotation block", A[:3, :3], tol)
    return A
